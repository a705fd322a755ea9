"""The constant placements of every joint, from the robot's parameters (model layer).

``T_parent_child(q) = B_j @ Motion(axis_j, value_j) @ A_j`` (see :mod:`jaxkin.model`): this module
computes ``B_j`` and ``A_j`` for the robot's parameterisation, with numpy (concrete parameters,
float64: constant folding, URDF export) or ``jax.numpy`` (traced parameters).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from .model import Robot

__all__ = ["JointPlacements", "joint_placements"]


class JointPlacements(NamedTuple):
    """Constant parts of every joint's transform, computed once per call from the leaves.

    ``B`` (before the motion) and ``A`` (after it) are ``(R, p)`` pairs of shape (n, 3, 3) and
    (n, 3), or None when the parameterisation makes them the identity.
    """

    B: tuple[Any, Any] | None
    A: tuple[Any, Any] | None


def _dh_standard(params, xp):
    a, alpha, d, theta = (params[k] for k in ("a", "alpha", "d", "theta"))
    ct, st, ca, sa = xp.cos(theta), xp.sin(theta), xp.cos(alpha), xp.sin(alpha)
    z = xp.zeros_like(a)
    # Rz(theta) Tz(d) Tx(a) Rx(alpha)
    R = xp.stack(
        [
            xp.stack([ct, -st * ca, st * sa], -1),
            xp.stack([st, ct * ca, -ct * sa], -1),
            xp.stack([z, sa, ca], -1),
        ],
        -2,
    )
    p = xp.stack([a * ct, a * st, d], -1)
    return R, p


def _dh_modified(params, xp):
    a, alpha, d, theta = (params[k] for k in ("a", "alpha", "d", "theta"))
    ct, st, ca, sa = xp.cos(theta), xp.sin(theta), xp.cos(alpha), xp.sin(alpha)
    z = xp.zeros_like(a)
    # Rx(alpha) Tx(a) Rz(theta) Tz(d)
    R = xp.stack(
        [
            xp.stack([ct, -st, z], -1),
            xp.stack([ca * st, ca * ct, -sa], -1),
            xp.stack([sa * st, sa * ct, ca], -1),
        ],
        -2,
    )
    p = xp.stack([a, -sa * d, ca * d], -1)
    return R, p


def _rpy(rpy, xp):
    r, p, y = rpy[..., 0], rpy[..., 1], rpy[..., 2]
    cr, sr, cp, sp, cy, sy = xp.cos(r), xp.sin(r), xp.cos(p), xp.sin(p), xp.cos(y), xp.sin(y)
    # Rz(yaw) Ry(pitch) Rx(roll)
    return xp.stack(
        [
            xp.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
            xp.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
            xp.stack([-sp, cp * sr, cp * cr], -1),
        ],
        -2,
    )


def joint_placements(robot: Robot, dtype=None, xp=jnp) -> JointPlacements:
    """The constant placements ``B_j`` and ``A_j`` of every joint (see :mod:`jaxkin.model`).

    ``xp`` is ``jax.numpy`` (traced leaves) or ``numpy`` (concrete leaves, in float64).
    """
    if xp is jnp:
        dtype = dtype or robot.dtype
        params = {k: v.astype(dtype) for k, v in robot.params.items()}
    else:
        params = {k: np.asarray(v, dtype=np.float64) for k, v in robot.params.items()}
    kind = robot.parameterisation
    if kind == "dh_standard":
        return JointPlacements(B=None, A=_dh_standard(params, xp))
    if kind == "dh_modified":
        return JointPlacements(B=_dh_modified(params, xp), A=None)
    return JointPlacements(B=(_rpy(params["rpy"], xp), params["xyz"]), A=None)
