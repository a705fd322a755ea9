"""Spatial algebra: skew matrices, rotations, homogeneous transforms, angular velocity.

Conventions (see the project README):

* ``T_a_b`` is the pose of frame b in frame a, so ``p_a = T_a_b @ p_b``.
* Twists are ordered ``[v; omega]`` (linear first).
* ``rpy`` is roll-pitch-yaw, ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``, the vector ordered
  ``(roll, pitch, yaw)``; ``zyz`` is ``R = Rz(phi) @ Ry(theta) @ Rz(psi)``, ordered
  ``(phi, theta, psi)``; a rotation vector ``w`` is ``R = exp(skew(w))``.

Every function here works on one element (a single vector, rotation or transform); batch with
``jax.vmap``. All functions are pure, jittable and differentiable. The exponential and logarithm
maps are NaN-free in value and gradient at angle 0 and angle pi.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

Array = jax.Array

__all__ = [
    "adjoint",
    "angular_velocity",
    "body_angular_velocity",
    "compose_angular_velocities",
    "exp_so3",
    "log_so3",
    "make_transform",
    "matrix_to_rpy",
    "matrix_to_zyz",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotation_about_axis",
    "rpy_to_matrix",
    "skew",
    "transform_inverse",
    "transform_point",
    "vee",
    "zyz_to_matrix",
]


def skew(w: Array) -> Array:
    """Skew-symmetric matrix ``S(w)`` with ``S(w) @ p == cross(w, p)``; (3,) -> (3, 3)."""
    w = jnp.asarray(w)
    z = jnp.zeros_like(w[0])
    return jnp.stack(
        [
            jnp.stack([z, -w[2], w[1]]),
            jnp.stack([w[2], z, -w[0]]),
            jnp.stack([-w[1], w[0], z]),
        ]
    )


def vee(S: Array) -> Array:
    """Inverse of :func:`skew`: the vector of the skew-symmetric part of ``S``; (3, 3) -> (3,).

    Uses the antisymmetric part ``(S - S^T) / 2``, so it is exact for skew matrices and a
    least-squares projection for matrices that are only nearly skew (e.g. ``Rdot R^T`` in
    floating point).
    """
    S = jnp.asarray(S)
    return 0.5 * jnp.stack([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


def _rot(c: Array, s: Array, axis: int) -> Array:
    o = jnp.ones_like(c)
    z = jnp.zeros_like(c)
    if axis == 0:
        rows = [[o, z, z], [z, c, -s], [z, s, c]]
    elif axis == 1:
        rows = [[c, z, s], [z, o, z], [-s, z, c]]
    else:
        rows = [[c, -s, z], [s, c, z], [z, z, o]]
    return jnp.stack([jnp.stack(r) for r in rows])


def rot_x(angle: Array) -> Array:
    """Rotation by ``angle`` (rad) about x; scalar -> (3, 3)."""
    angle = jnp.asarray(angle)
    return _rot(jnp.cos(angle), jnp.sin(angle), 0)


def rot_y(angle: Array) -> Array:
    """Rotation by ``angle`` (rad) about y; scalar -> (3, 3)."""
    angle = jnp.asarray(angle)
    return _rot(jnp.cos(angle), jnp.sin(angle), 1)


def rot_z(angle: Array) -> Array:
    """Rotation by ``angle`` (rad) about z; scalar -> (3, 3)."""
    angle = jnp.asarray(angle)
    return _rot(jnp.cos(angle), jnp.sin(angle), 2)


def rotation_about_axis(axis: Array, angle: Array) -> Array:
    """Rodrigues' formula: rotation by ``angle`` about the unit vector ``axis``; -> (3, 3)."""
    axis = jnp.asarray(axis)
    angle = jnp.asarray(angle)
    K = skew(axis)
    eye = jnp.eye(3, dtype=K.dtype)
    return eye + jnp.sin(angle) * K + (1.0 - jnp.cos(angle)) * (K @ K)


def rpy_to_matrix(rpy: Array) -> Array:
    """``R = Rz(yaw) Ry(pitch) Rx(roll)`` from ``rpy = (roll, pitch, yaw)``; (3,) -> (3, 3)."""
    rpy = jnp.asarray(rpy)
    return rot_z(rpy[2]) @ rot_y(rpy[1]) @ rot_x(rpy[0])


def _euler_outer(a: Array, b: Array) -> tuple[Array, Array, Array]:
    """Shared by :func:`matrix_to_rpy` and :func:`matrix_to_zyz`.

    ``(a, b) = n * (cos, sin)(outer)`` are two entries of the matrix, with ``n >= 0`` cos(pitch)
    resp. sin(theta) and ``outer`` yaw resp. phi. Returns ``(n, outer, near)``: ``sqrt(a^2 + b^2)``
    and ``arctan2(b, a)``, bit for bit, except at exact gimbal lock (``a^2 + b^2`` below the
    smallest normal number), where both are 0 (the convention) and a double ``where`` keeps their
    gradients finite; ``near`` flags ``n < 1e-2`` (``1e-1`` in float32), where the caller takes the
    inner angle from the matrix de-rotated by ``outer``.
    """
    n_sq = a**2 + b**2
    locked = n_sq < jnp.finfo(n_sq.dtype).tiny
    near = n_sq < (1e-4 if jnp.finfo(n_sq.dtype).bits == 64 else 1e-2)
    zero, one = jnp.zeros_like(n_sq), jnp.ones_like(n_sq)
    n = jnp.where(locked, zero, jnp.sqrt(jnp.where(locked, one, n_sq)))
    safe_b, safe_a = jnp.where(locked, zero, b), jnp.where(locked, one, a)
    outer = jnp.where(locked, zero, jnp.arctan2(safe_b, safe_a))
    return n, outer, near


def _safe_arctan2(near: Array, y: Array, x: Array) -> Array:
    # arctan2(y, x) for the "far" branch; (0, 1) where it is not used (y = x = 0 at the lock).
    return jnp.arctan2(jnp.where(near, jnp.zeros_like(y), y), jnp.where(near, jnp.ones_like(x), x))


def matrix_to_rpy(R: Array) -> Array:
    """``(roll, pitch, yaw)`` of ``R = Rz(yaw) Ry(pitch) Rx(roll)``, pitch in [-pi/2, pi/2].

    ``rpy_to_matrix(matrix_to_rpy(R))`` rebuilds ``R`` to rounding everywhere, gimbal lock
    included. At pitch = +-pi/2 exactly (``R[0, 0] == R[1, 0] == 0``) only roll - yaw (pitch
    +pi/2) resp. roll + yaw (pitch -pi/2) is determined; the convention there is **yaw = 0**
    (as Pinocchio's ``matrixToRpy``), so ``roll = atan2(-R[1, 2], R[1, 1])``. Near the lock
    (``cos(pitch) < 1e-2``, ``1e-1`` in float32) roll is taken from ``Rz(yaw)^T R`` so that it
    stays consistent with yaw, which rounding errors of ``R`` then perturb; elsewhere the result
    is the plain ``atan2`` formulas' (yaw from column 0, roll from row 2).

    Values and gradients are finite everywhere, but roll and yaw and their derivatives are
    unbounded near the lock; see :func:`jaxkin.representations.representation_margin`.
    """
    R = jnp.asarray(R)
    if not jnp.issubdtype(R.dtype, jnp.floating):
        R = R.astype(jnp.result_type(float))
    cos_p, yaw, near = _euler_outer(R[0, 0], R[1, 0])
    pitch = jnp.arctan2(-R[2, 0], cos_p)
    # Near the lock: row 1 of Rz(yaw)^T R = Ry(pitch) Rx(roll) is (0, cos(roll), -sin(roll)).
    sy, cy = jnp.sin(yaw), jnp.cos(yaw)
    roll_near = jnp.arctan2(sy * R[0, 2] - cy * R[1, 2], cy * R[1, 1] - sy * R[0, 1])
    roll = jnp.where(near, roll_near, _safe_arctan2(near, R[2, 1], R[2, 2]))
    return jnp.stack([roll, pitch, yaw])


def zyz_to_matrix(zyz: Array) -> Array:
    """``R = Rz(phi) Ry(theta) Rz(psi)`` from ``zyz = (phi, theta, psi)``; (3,) -> (3, 3)."""
    zyz = jnp.asarray(zyz)
    return rot_z(zyz[0]) @ rot_y(zyz[1]) @ rot_z(zyz[2])


def matrix_to_zyz(R: Array) -> Array:
    """``(phi, theta, psi)`` of ``R = Rz(phi) Ry(theta) Rz(psi)``, theta in [0, pi].

    ``zyz_to_matrix(matrix_to_zyz(R))`` rebuilds ``R`` to rounding everywhere, gimbal lock
    included. At theta = 0 or pi exactly (``R[0, 2] == R[1, 2] == 0``) only phi + psi (theta 0)
    resp. psi - phi (theta pi) is determined; the convention there is **phi = 0** (as
    spatialmath's ``tr2eul``), so ``psi = atan2(R[1, 0], R[1, 1])``. Near the lock
    (``sin(theta) < 1e-2``, ``1e-1`` in float32) psi is taken from ``Rz(phi)^T R``; elsewhere the
    result is the plain ``atan2`` formulas' (phi from column 2, psi from row 2).

    Values and gradients are finite everywhere, but phi and psi and their derivatives are
    unbounded near the lock.
    """
    R = jnp.asarray(R)
    if not jnp.issubdtype(R.dtype, jnp.floating):
        R = R.astype(jnp.result_type(float))
    sin_t, phi, near = _euler_outer(R[0, 2], R[1, 2])
    theta = jnp.arctan2(sin_t, R[2, 2])
    # Near the lock: row 1 of Rz(phi)^T R = Ry(theta) Rz(psi) is (sin(psi), cos(psi), 0).
    sf, cf = jnp.sin(phi), jnp.cos(phi)
    psi_near = jnp.arctan2(cf * R[1, 0] - sf * R[0, 0], cf * R[1, 1] - sf * R[0, 1])
    psi = jnp.where(near, psi_near, _safe_arctan2(near, R[2, 1], -R[2, 0]))
    return jnp.stack([phi, theta, psi])


def _safe_norm(v: Array, tiny: float) -> tuple[Array, Array]:
    """Norm of ``v`` with a finite gradient at zero (double-``where`` safe value).

    Returns ``(norm, small)`` where ``small`` flags ``|v|^2 < tiny``; at such points the returned
    norm is exactly 0 and its gradient 0 (never NaN).
    """
    sq = jnp.sum(v * v)
    small = sq < tiny
    safe_sq = jnp.where(small, jnp.ones_like(sq), sq)
    return jnp.where(small, jnp.zeros_like(sq), jnp.sqrt(safe_sq)), small


def _taylor_eps(dtype) -> float:
    # Below this angle the truncated Taylor series is exact to machine precision.
    return 1e-3 if jnp.finfo(dtype).bits == 64 else 3e-2


def exp_so3(w: Array) -> Array:
    """Rotation matrix ``exp(skew(w))`` of a rotation vector ``w`` (axis * angle); (3,) -> (3, 3).

    Value and all derivatives are finite at ``w = 0`` (Taylor branch).
    """
    w = jnp.asarray(w)
    if not jnp.issubdtype(w.dtype, jnp.floating):
        w = w.astype(jnp.result_type(float))
    eps = _taylor_eps(w.dtype)
    theta_sq = jnp.sum(w * w)
    small = theta_sq < eps**2
    safe_sq = jnp.where(small, jnp.ones_like(theta_sq), theta_sq)
    theta = jnp.sqrt(safe_sq)
    # A = sin(t)/t, B = (1 - cos(t))/t^2, with Taylor series near 0.
    A = jnp.where(small, 1.0 - theta_sq / 6.0 + theta_sq**2 / 120.0, jnp.sin(theta) / theta)
    B = jnp.where(
        small, 0.5 - theta_sq / 24.0 + theta_sq**2 / 720.0, (1.0 - jnp.cos(theta)) / safe_sq
    )
    K = skew(w)
    return jnp.eye(3, dtype=w.dtype) + A * K + B * (K @ K)


def log_so3(R: Array) -> Array:
    """Rotation vector ``w`` with ``exp_so3(w) == R`` and angle ``|w|`` in [0, pi]; (3, 3) -> (3,).

    Values and gradients are finite everywhere, including angle 0 (Taylor branch) and angle pi
    (axis recovered from the symmetric part; at exactly pi the sign is the one with the larger
    diagonal entry, since +-pi*axis describe the same rotation).
    """
    R = jnp.asarray(R)
    dtype = R.dtype
    eps = _taylor_eps(dtype)
    tiny = jnp.finfo(dtype).tiny
    a = 2.0 * vee(R)  # = 2 sin(theta) * axis
    s_norm, _ = _safe_norm(a, tiny)
    s = 0.5 * s_norm  # sin(theta) >= 0
    c = 0.5 * (jnp.trace(R) - 1.0)  # cos(theta)
    theta = jnp.arctan2(s, c)

    # Branch 1 (theta < pi - delta): w = theta / sin(theta) * vee(R) (Taylor near 0).
    near_zero = theta < eps
    safe_s = jnp.where(near_zero | (s <= 0), jnp.ones_like(s), s)
    t2 = theta * theta
    factor = jnp.where(near_zero, 1.0 + t2 / 6.0 + 7.0 * t2 * t2 / 360.0, theta / safe_s)
    w_regular = factor * (0.5 * a)

    # Branch 2 (theta near pi): axis from B = (R + R^T)/2 - cos(theta) I = (1 - cos) a a^T.
    Bm = 0.5 * (R + R.T) - c * jnp.eye(3, dtype=dtype)
    k = jnp.argmax(jnp.diagonal(Bm))
    col = Bm[:, k]
    col_norm, col_small = _safe_norm(col, tiny)
    axis = col / jnp.where(col_small, jnp.ones_like(col_norm), col_norm)
    sign = jnp.where(jnp.dot(axis, a) < 0, -1.0, 1.0).astype(dtype)
    w_pi = sign * theta * axis

    near_pi = theta > jnp.pi - 1e-2
    return jnp.where(near_pi, w_pi, w_regular)


def make_transform(R: Array, p: Array) -> Array:
    """Homogeneous transform ``[[R, p], [0, 1]]``; (3, 3), (3,) -> (4, 4)."""
    R = jnp.asarray(R)
    p = jnp.asarray(p, dtype=R.dtype)
    top = jnp.concatenate([R, p[:, None]], axis=1)
    bottom = jnp.array([[0.0, 0.0, 0.0, 1.0]], dtype=R.dtype)
    return jnp.concatenate([top, bottom], axis=0)


def transform_inverse(T: Array) -> Array:
    """Inverse of a homogeneous transform: ``T_b_a`` from ``T_a_b``; (4, 4) -> (4, 4)."""
    T = jnp.asarray(T)
    R = T[:3, :3]
    p = T[:3, 3]
    return make_transform(R.T, -R.T @ p)


def transform_point(T: Array, p: Array) -> Array:
    """``p_a = T_a_b @ p_b`` for a point ``p_b`` (3,) -> (3,)."""
    T = jnp.asarray(T)
    return T[:3, :3] @ jnp.asarray(p) + T[:3, 3]


def adjoint(T: Array) -> Array:
    """Adjoint ``Ad(T_a_b)`` mapping a twist ``[v; omega]`` in frame b to frame a; -> (6, 6).

    ``Ad = [[R, skew(p) R], [0, R]]`` for linear-first twists (both twists referred to the
    origin of their own frame).
    """
    T = jnp.asarray(T)
    R = T[:3, :3]
    p = T[:3, 3]
    z = jnp.zeros((3, 3), dtype=T.dtype)
    top = jnp.concatenate([R, skew(p) @ R], axis=1)
    bottom = jnp.concatenate([z, R], axis=1)
    return jnp.concatenate([top, bottom], axis=0)


def angular_velocity(R_of_t: Callable[[Array], Array], t: Array) -> Array:
    """Spatial angular velocity ``omega = vee(Rdot R^T)`` of ``R(t)`` at ``t``, in the fixed frame.

    ``Rdot`` comes from ``jax.jvp`` (exact, no finite differences); (3,).
    """
    t = jnp.asarray(t)
    R, Rdot = jax.jvp(R_of_t, (t,), (jnp.ones_like(t),))
    return vee(Rdot @ R.T)


def body_angular_velocity(R_of_t: Callable[[Array], Array], t: Array) -> Array:
    """Body angular velocity ``omega_b = vee(R^T Rdot) = R^T omega``, in the moving frame; (3,)."""
    t = jnp.asarray(t)
    R, Rdot = jax.jvp(R_of_t, (t,), (jnp.ones_like(t),))
    return vee(R.T @ Rdot)


def compose_angular_velocities(R_rel: Array, omega_rel: Array) -> Array:
    """Angular velocity of the last frame of a chain, in frame 0 (the chapter's Eq. 4.18).

    ``omega_{0,n}^0 = omega_{0,1}^0 + R_1^0 omega_{1,2}^1 + ... + R_{n-1}^0 omega_{n-1,n}^{n-1}``.

    Args:
      R_rel: (n, 3, 3) relative rotations ``R_{i-1}^{i}`` ... precisely ``R_rel[i]`` is the
        orientation of frame i+1 in frame i.
      omega_rel: (n, 3) ``omega_rel[i]`` is the angular velocity of frame i+1 relative to frame i,
        expressed in frame i.

    Returns:
      (3,) angular velocity of frame n relative to frame 0, expressed in frame 0.
    """
    R_rel = jnp.asarray(R_rel)
    omega_rel = jnp.asarray(omega_rel)

    def step(carry, x):
        R_0_i, total = carry
        R_i_next, w = x
        total = total + R_0_i @ w
        return (R_0_i @ R_i_next, total), None

    init = (jnp.eye(3, dtype=R_rel.dtype), jnp.zeros(3, dtype=R_rel.dtype))
    (_, total), _ = jax.lax.scan(step, init, (R_rel, omega_rel))
    return total
