"""Minimal orientation representations, their rate maps B(phi), and singularity margins.

For a representation ``phi`` of ``R``, the angular velocity in world axes is
``omega = B(phi) @ phi_dot`` (so the analytical and geometric Jacobians relate by
``J_a = blkdiag(I, B(phi)^-1) @ J_g``):

* ``"rpy"``: ``R = Rz(yaw) Ry(pitch) Rx(roll)``, ``phi = (roll, pitch, yaw)``;
  ``B = [Rz(y) Ry(p) e_x, Rz(y) e_y, e_z]``, ``det B = cos(pitch)``: singular at pitch = +-pi/2.
* ``"zyz"``: ``R = Rz(phi) Ry(theta) Rz(psi)``; ``B = [e_z, Rz(phi) e_y, Rz(phi) Ry(theta) e_z]``,
  ``det B = -sin(theta)``: singular at theta = 0 and pi.
* ``"rotvec"``: ``R = exp(skew(w))``; ``B`` is the left Jacobian of SO(3),
  ``I + (1 - cos t)/t^2 skew(w) + (t - sin t)/t^3 skew(w)^2`` (t = ``|w|``), singular only at
  t = 2 pi k, k >= 1, which the principal branch (t <= pi) never reaches.

:func:`representation_margin` measures the distance to the singularity (``|cos(pitch)|``,
``|sin(theta)|``, ``1 - t / (2 pi)``): 1 far from it, 0 on it.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import spatial
from ._checks import error_if, is_traced
from .errors import JaxkinError, RepresentationSingularityError, ShapeError

__all__ = [
    "REPRESENTATIONS",
    "analytical_from_geometric",
    "check_representation",
    "from_matrix",
    "guard_singular",
    "rate_matrix",
    "rate_matrix_autodiff",
    "representation_margin",
    "to_matrix",
]

REPRESENTATIONS = ("rpy", "zyz", "rotvec")

_TO = {"rpy": spatial.rpy_to_matrix, "zyz": spatial.zyz_to_matrix, "rotvec": spatial.exp_so3}
_FROM = {"rpy": spatial.matrix_to_rpy, "zyz": spatial.matrix_to_zyz, "rotvec": spatial.log_so3}


def check_representation(representation: str) -> str:
    if representation not in REPRESENTATIONS:
        raise JaxkinError(
            f"representation must be one of {REPRESENTATIONS}, got {representation!r}."
        )
    return representation


_SINGULAR_AT = {"rpy": "pitch = +-pi/2", "zyz": "theta = 0 or pi", "rotvec": "|w| = 2 pi"}


def guard_singular(
    value: Any,
    margin: jax.Array,
    representation: str,
    singular_tol: float | None,
    what: str,
    instead: str,
    *trees: Any,
) -> Any:
    """The analytical-Jacobian singularity policy, written once.

    With ``tol = singular_tol`` (default: sqrt of the dtype's machine epsilon), ``margin < tol``
    raises :class:`~jaxkin.RepresentationSingularityError` eagerly (``what`` is unbounded; the
    message suggests ``instead``); when ``margin`` or ``trees`` are traced the ``value`` becomes
    all NaN there instead.
    """
    dtype = np.dtype(getattr(margin, "dtype", np.float64))
    tol = float(np.sqrt(np.finfo(dtype).eps)) if singular_tol is None else float(singular_tol)
    # eagerly in numpy: one transfer instead of two more dispatches
    bad = margin < tol if is_traced(margin, *trees) else np.asarray(margin) < tol

    def error() -> Exception:
        return RepresentationSingularityError(
            f"the {representation!r} representation is singular here "
            f"({_SINGULAR_AT[representation]}; margin {float(margin):.3g} < {tol:.3g}): {what} "
            f"is unbounded. Use {instead}, another representation, or return_margin=True to get "
            "the raw values with their margin."
        )

    return error_if(bad, error, value, margin, *trees)


def _check_phi(phi) -> jax.Array:
    phi = jnp.asarray(phi)
    if phi.shape != (3,):
        raise ShapeError(f"phi must have shape (3,), got {phi.shape}; batch with jax.vmap.")
    if not jnp.issubdtype(phi.dtype, jnp.floating):
        phi = phi.astype(jnp.result_type(float))
    return phi


def to_matrix(phi, representation: str = "rpy") -> jax.Array:
    """Rotation matrix (3, 3) of ``phi`` (3,) in ``representation``."""
    return _TO[check_representation(representation)](_check_phi(phi))


def from_matrix(R, representation: str = "rpy") -> jax.Array:
    """``phi`` (3,) of rotation matrix ``R`` (3, 3) in ``representation`` (principal branch)."""
    R = jnp.asarray(R)
    if R.shape != (3, 3):
        raise ShapeError(f"R must have shape (3, 3), got {R.shape}; batch with jax.vmap.")
    return _FROM[check_representation(representation)](R)


def rate_matrix(phi, representation: str = "rpy") -> jax.Array:
    """``B(phi)`` (3, 3) with ``omega = B(phi) @ phi_dot``, omega in world axes (closed form).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> B = jk.rate_matrix(jnp.zeros(3))  # rpy at zero: omega = (roll_dot, pitch_dot, yaw_dot)
    >>> bool(jnp.allclose(B, jnp.eye(3)))
    True
    >>> round(float(jnp.linalg.det(jk.rate_matrix(jnp.array([0.0, 1.5, 0.0])))), 6)  # cos(pitch)
    0.070737
    """
    check_representation(representation)
    phi = _check_phi(phi)
    if representation == "rpy":
        _, p, y = phi
        cp, sp, cy, sy = jnp.cos(p), jnp.sin(p), jnp.cos(y), jnp.sin(y)
        zero, one = jnp.zeros_like(p), jnp.ones_like(p)
        return jnp.stack(
            [
                jnp.stack([cy * cp, -sy, zero]),
                jnp.stack([sy * cp, cy, zero]),
                jnp.stack([-sp, zero, one]),
            ]
        )
    if representation == "zyz":
        f, t, _ = phi
        cf, sf, ct, st = jnp.cos(f), jnp.sin(f), jnp.cos(t), jnp.sin(t)
        zero, one = jnp.zeros_like(f), jnp.ones_like(f)
        return jnp.stack(
            [
                jnp.stack([zero, -sf, cf * st]),
                jnp.stack([zero, cf, sf * st]),
                jnp.stack([one, zero, ct]),
            ]
        )
    return spatial.left_jacobian_so3(phi)  # rotvec


def rate_matrix_autodiff(phi, representation: str = "rpy") -> jax.Array:
    """``B(phi)`` by automatic differentiation: column k is ``vee(dR/dphi_k R^T)``.

    Independent of :func:`rate_matrix`'s closed forms (used to check them).
    """
    check_representation(representation)
    phi = _check_phi(phi)
    fn = _TO[representation]
    R = fn(phi)
    dR = jax.jacfwd(fn)(phi)  # (3, 3, 3)
    return jnp.stack([spatial.vee(dR[:, :, k] @ R.T) for k in range(3)], axis=1)


def representation_margin(phi, representation: str = "rpy") -> jax.Array:
    """Distance of ``phi`` from its representation singularity: 1 far away, 0 on it.

    ``|cos(pitch)|`` for rpy, ``|sin(theta)|`` for zyz, ``1 - |w| / (2 pi)`` for rotvec (which is
    never singular on its principal branch). The rate matrix's inverse grows like 1 / margin.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> float(jk.representation_margin(jnp.zeros(3)))  # rpy, level
    1.0
    >>> float(jk.representation_margin(jnp.array([0.0, jnp.pi / 2, 0.0])).round(6))  # gimbal lock
    0.0
    """
    check_representation(representation)
    phi = _check_phi(phi)
    if representation == "rpy":
        return jnp.abs(jnp.cos(phi[1]))
    if representation == "zyz":
        return jnp.abs(jnp.sin(phi[1]))
    return 1.0 - spatial.safe_norm(phi) / (2 * jnp.pi)


def analytical_from_geometric(J_geometric, phi, representation: str = "rpy") -> jax.Array:
    """``J_a = blkdiag(I, B(phi)^-1) @ J_g`` for a (6, dof) world-aligned geometric Jacobian.

    Undefined where ``B(phi)`` is singular; check :func:`representation_margin` first.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q = jnp.array([0.0, jnp.pi / 2])
    >>> phi = jk.spatial.matrix_to_rpy(jk.fk(robot, q)[:3, :3])
    >>> Ja = jk.analytical_from_geometric(jk.geometric_jacobian(robot, q), phi)
    >>> bool(jnp.allclose(Ja, jk.analytical_jacobian(robot, q, "rpy")))
    True
    """
    J = jnp.asarray(J_geometric)
    if J.ndim != 2 or J.shape[0] != 6:
        raise ShapeError(f"J_geometric must have shape (6, dof), got {J.shape}.")
    B = rate_matrix(phi, representation).astype(J.dtype)
    return jnp.concatenate([J[:3], jnp.linalg.solve(B, J[3:])], axis=0)
