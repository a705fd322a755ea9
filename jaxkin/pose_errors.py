"""Pose errors: how far a pose ``T`` is from a desired pose ``T_desired``, both ``T_world_frame``.

Errors are in world axes, rows ``[position; orientation]``: ``p_d - p`` and the rotation vector of
``R_d R^T`` (the twist, times 1 s, that moves ``T`` onto ``T_desired``).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from . import spatial
from .spatial import safe_norm

__all__ = ["pose_error", "pose_error_norms", "pose_residual"]


def pose_error(T: Any, T_desired: Any) -> jax.Array:
    """Pose error ``[p_d - p; log(R_d R^T)]`` (6,), world axes: the twist (times 1 s) that moves
    pose ``T`` to ``T_desired`` along a screw-free path (position straight, orientation about a
    fixed world axis). NaN-free, also at zero error (``log_so3``'s Taylor branch).

    >>> import jax, jax.numpy as jnp, jaxkin as jk
    >>> T = jnp.eye(4)
    >>> T_desired = T.at[:3, :3].set(jk.spatial.rot_z(0.1)).at[0, 3].set(0.2)
    >>> e = jax.jit(jk.pose_error)(T, T_desired)  # jitted: one compile, not one per operation
    >>> [round(x, 6) for x in e.tolist()]  # [dp; rotation vector]
    [0.2, 0.0, 0.0, 0.0, 0.0, 0.1]
    """
    T = jnp.asarray(T)
    Td = jnp.asarray(T_desired)
    dp = Td[:3, 3] - T[:3, 3]
    dw = spatial.log_so3(Td[:3, :3] @ T[:3, :3].T)
    return jnp.concatenate([dp, dw])


def pose_residual(T: jax.Array, T_target: jax.Array) -> jax.Array:
    """``[p_t - p; w]`` (6,) with ``exp(skew(w)) = R_t R^T``: the residual the solvers iterate on.

    The same as :func:`jaxkin.inverse_velocity.pose_error` except exactly at an orientation error
    of pi, where the rotation axis is not recovered (``w = 0`` there): a cheaper logarithm without
    ``log_so3``'s near-pi branch, which compiles several times faster inside the solver loop.
    Final results are re-checked with the exact angle (:func:`pose_error_norms`).
    """
    dp = T_target[:3, 3] - T[:3, 3]
    M = T_target[:3, :3] @ T[:3, :3].T
    a = spatial.vee(M)  # sin(theta) * axis
    s2 = jnp.sum(a * a)
    c = 0.5 * (M[0, 0] + M[1, 1] + M[2, 2] - 1.0)
    pos = s2 > jnp.finfo(T.dtype).tiny
    s = spatial.safe_sqrt(s2, pos)
    theta = jnp.arctan2(s, c)
    # 1e-3 in every dtype, not spatial.get_epsilon (3e-2 in float32): theta / s and the series of
    # theta / sin(theta) agree on SO(3) only; their derivatives off it differ by O(theta).
    small = theta < 1e-3
    t2 = theta * theta
    factor = jnp.where(
        small, 1.0 + t2 / 6.0 + 7.0 * t2 * t2 / 360.0, theta / jnp.where(pos, s, 1.0)
    )
    factor = jnp.where(pos | small, factor, 0.0)
    return jnp.concatenate([dp, factor * a])


def pose_error_norms(T: jax.Array, T_target: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Position error (m) and orientation error (rad, the angle of ``R_t R^T`` in [0, pi])."""
    dp = T_target[:3, 3] - T[:3, 3]
    M = T_target[:3, :3] @ T[:3, :3].T
    s = safe_norm(spatial.vee(M))  # sin(angle)
    c = 0.5 * (M[0, 0] + M[1, 1] + M[2, 2] - 1.0)  # cos(angle)
    return safe_norm(dp), jnp.arctan2(s, c)
