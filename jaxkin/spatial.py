"""Spatial algebra: skew matrices, rotations, homogeneous transforms, angular velocity.

Conventions (see the project README):

* ``T_a_b`` is the pose of frame b in frame a, so ``p_a = T_a_b @ p_b``.
* Twists are ordered ``[v; omega]`` (linear first).
* ``rpy`` is roll-pitch-yaw, ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``, the vector ordered
  ``(roll, pitch, yaw)``; ``zyz`` is ``R = Rz(phi) @ Ry(theta) @ Rz(psi)``, ordered
  ``(phi, theta, psi)``; a rotation vector ``w`` is ``R = exp(skew(w))``.

This module is the one home of jaxkin's rotation math: every other module imports its SO(3)
and SE(3) functions, quaternion conversions, small-angle threshold (:func:`get_epsilon`) and
safe norm (:func:`safe_norm`) from here. A quaternion is ``(w, x, y, z)``, scalar first
(MuJoCo's order).

Every jnp function works on one element (a single vector, rotation or transform); batch with
``jax.vmap``. All of them are pure, jittable and differentiable. The exponential and logarithm
maps and the Jacobians of SO(3) are NaN-free in value and gradient at angle 0 and angle pi.

The last section, *host side (numpy)*, holds the float64 numpy twins that the builders, parsers
and writers (:mod:`jaxkin.build`, :mod:`jaxkin.mjcf`, :mod:`jaxkin.urdf_export`) run before any
tracing; each is named after its jnp kernel with an ``_np`` suffix.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

Array = jax.Array

__all__ = [
    "adjoint",
    "angular_velocity",
    "body_angular_velocity",
    "compose_angular_velocities",
    "exp_so3",
    "get_epsilon",
    "left_jacobian_so3",
    "left_jacobian_so3_inverse",
    "log_so3",
    "make_transform",
    "make_transform_np",
    "matrix_to_rpy",
    "matrix_to_rpy_np",
    "matrix_to_zyz",
    "max_scaled",
    "quaternion_conjugate",
    "quaternion_exp",
    "quaternion_log",
    "quaternion_multiply",
    "quaternion_rotation",
    "quaternion_to_matrix",
    "quaternion_to_matrix_np",
    "right_jacobian_so3",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotation_about_axis",
    "rotation_about_axis_np",
    "rpy_to_matrix",
    "safe_norm",
    "safe_sqrt",
    "skew",
    "small_angle",
    "transform_inverse",
    "transform_point",
    "vee",
    "zyz_to_matrix",
]


# ----------------------------------------------------------------------------- thresholds, norms
def get_epsilon(dtype: Any) -> float:
    """The small-angle threshold of ``dtype`` (an angle, rad): 1e-3 in float64, 3e-2 in float32
    and narrower floats. Below it every Taylor branch here (:func:`exp_so3`, :func:`log_so3`,
    the SO(3) Jacobians, the quaternion maps) is exact to machine precision, so it is the one
    threshold of the rotation math (as jaxlie's ``get_epsilon``)."""
    return 1e-3 if jnp.finfo(dtype).bits == 64 else 3e-2


def small_angle(theta_sq: Array) -> tuple[Array, Array]:
    """``(small, safe)`` for a squared angle ``theta_sq``: ``small`` flags
    ``theta_sq < get_epsilon(dtype) ** 2`` (take the Taylor branch), ``safe`` is ``theta_sq``
    with 1 where small, so that the regular branch, evaluated on both sides of a ``where``, stays
    finite in value and gradient (the double-``where``)."""
    small = theta_sq < get_epsilon(theta_sq.dtype) ** 2
    return small, jnp.where(small, jnp.ones_like(theta_sq), theta_sq)


def safe_sqrt(x: Array, pos: Array | None = None) -> Array:
    """``sqrt(x)`` where ``pos`` (default ``x > 0``), exactly 0 elsewhere, with gradient 0 there
    (never NaN): the double-``where`` (the square root is taken of 1 where it is not used)."""
    pos = x > 0 if pos is None else pos
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def safe_norm(v: Array, axis: Any = None) -> Array:
    """Euclidean norm of ``v`` (along ``axis``; all entries by default) with gradient 0 (never
    NaN) where it is 0: :func:`safe_sqrt` of the sum of squares."""
    v = jnp.asarray(v)
    return safe_sqrt(jnp.sum(v * v, axis=axis))


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
    n = safe_sqrt(n_sq, ~locked)
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


def exp_so3(w: Array) -> Array:
    """Rotation matrix ``exp(skew(w))`` of a rotation vector ``w`` (axis * angle); (3,) -> (3, 3).

    Value and all derivatives are finite at ``w = 0`` (Taylor branch).
    """
    w = jnp.asarray(w)
    if not jnp.issubdtype(w.dtype, jnp.floating):
        w = w.astype(jnp.result_type(float))
    theta_sq = jnp.sum(w * w)
    small, safe_sq = small_angle(theta_sq)
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
    tiny = jnp.finfo(dtype).tiny
    a = 2.0 * vee(R)  # = 2 sin(theta) * axis
    a_sq = jnp.sum(a * a)
    s = 0.5 * safe_sqrt(a_sq, ~(a_sq < tiny))  # sin(theta) >= 0
    c = 0.5 * (jnp.trace(R) - 1.0)  # cos(theta)
    theta = jnp.arctan2(s, c)

    # Branch 1 (theta < pi - delta): w = theta / sin(theta) * vee(R) (Taylor near 0).
    near_zero = theta < get_epsilon(dtype)
    safe_s = jnp.where(near_zero | (s <= 0), jnp.ones_like(s), s)
    t2 = theta * theta
    factor = jnp.where(near_zero, 1.0 + t2 / 6.0 + 7.0 * t2 * t2 / 360.0, theta / safe_s)
    w_regular = factor * (0.5 * a)

    # Branch 2 (theta near pi): axis from B = (R + R^T)/2 - cos(theta) I = (1 - cos) a a^T.
    Bm = 0.5 * (R + R.T) - c * jnp.eye(3, dtype=dtype)
    k = jnp.argmax(jnp.diagonal(Bm))
    col = Bm[:, k]
    col_sq = jnp.sum(col * col)
    col_small = col_sq < tiny
    col_norm = safe_sqrt(col_sq, ~col_small)
    axis = col / jnp.where(col_small, jnp.ones_like(col_norm), col_norm)
    sign = jnp.where(jnp.dot(axis, a) < 0, -1.0, 1.0).astype(dtype)
    w_pi = sign * theta * axis

    near_pi = theta > jnp.pi - 1e-2
    return jnp.where(near_pi, w_pi, w_regular)


def left_jacobian_so3(w: Array) -> Array:
    """Left Jacobian of SO(3) at the rotation vector ``w``: ``J_l = I + (1 - cos t) / t^2 K +
    (t - sin t) / t^3 K^2`` with ``K = skew(w)``, ``t = |w|`` (the ``V`` of SE(3)'s exponential,
    and the rate matrix of rotation vectors); (3,) -> (3, 3). Taylor branch below
    :func:`get_epsilon`: finite value and gradient at ``w = 0``."""
    w = jnp.asarray(w)
    sq = jnp.sum(w * w)
    small, safe = small_angle(sq)
    t = jnp.sqrt(safe)
    B = jnp.where(small, 0.5 - sq / 24.0 + sq * sq / 720.0, (1.0 - jnp.cos(t)) / safe)
    C = jnp.where(small, 1.0 / 6.0 - sq / 120.0 + sq * sq / 5040.0, (t - jnp.sin(t)) / (safe * t))
    K = skew(w)
    return jnp.eye(3, dtype=w.dtype) + B * K + C * (K @ K)


def left_jacobian_so3_inverse(w: Array) -> Array:
    """Inverse of :func:`left_jacobian_so3`: ``I - K/2 + (1 - t sin t / (2 (1 - cos t))) / t^2
    K^2`` (angle ``t`` <= pi); (3,) -> (3, 3). Taylor branch near ``w = 0``."""
    w = jnp.asarray(w)
    sq = jnp.sum(w * w)
    small, safe = small_angle(sq)
    t = jnp.sqrt(safe)
    regular = (1.0 - t * jnp.sin(t) / (2.0 * (1.0 - jnp.cos(t)))) / safe
    D = jnp.where(small, 1.0 / 12.0 + sq / 720.0 + sq * sq / 30240.0, regular)
    K = skew(w)
    return jnp.eye(3, dtype=w.dtype) - 0.5 * K + D * (K @ K)


def right_jacobian_so3(w: Array) -> Array:
    """Right Jacobian of SO(3), ``J_r(w) = J_l(-w) = J_l(w)^T``; (3,) -> (3, 3)."""
    return left_jacobian_so3(w).T


# ----------------------------------------------------------------------------- quaternions
def max_scaled(*coords: Any) -> list:
    """``coords`` (scalars) divided by the largest of their magnitudes: the same direction, with
    squares that neither overflow (a quaternion scaled by 1e200) nor underflow (by 1e-200); all
    NaN when every one is zero. Division, not a reciprocal: ``1 / m`` overflows for subnormal
    ``m``."""
    m = functools.reduce(jnp.maximum, [jnp.abs(c) for c in coords])
    return [c / m for c in coords]


def quaternion_rotation(w: Any, x: Any, y: Any, z: Any) -> tuple:
    """The rotation (nested tuples of scalars, for the forward pass's elementwise kernel) of the
    quaternion ``(w, x, y, z)`` divided by its norm: ``I + 2 / |q|^2 (w [v]x + [v]x^2)``, so a
    non-unit quaternion of any finite nonzero size gives the rotation of its unit multiple
    (scaled first, :func:`max_scaled`) and the zero quaternion gives NaN."""
    w, x, y, z = max_scaled(w, x, y, z)
    s = 2.0 / (w * w + x * x + y * y + z * z)
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    return (
        (1.0 - (yy + zz), xy - wz, xz + wy),
        (xy + wz, 1.0 - (xx + zz), yz - wx),
        (xz - wy, yz + wx, 1.0 - (xx + yy)),
    )


def quaternion_to_matrix(q: Array) -> Array:
    """Rotation matrix of the quaternion ``q = (w, x, y, z)`` divided by its norm (any finite
    nonzero size; :func:`quaternion_rotation`); (4,) -> (3, 3)."""
    q = jnp.asarray(q)
    return jnp.stack([jnp.stack(row) for row in quaternion_rotation(q[0], q[1], q[2], q[3])])


def quaternion_conjugate(q: Array) -> Array:
    """``(w, -x, -y, -z)``: the inverse rotation of a unit quaternion; (4,) -> (4,)."""
    q = jnp.asarray(q)
    return q * jnp.asarray([1.0, -1.0, -1.0, -1.0], q.dtype)


def quaternion_multiply(a: Array, b: Array) -> Array:
    """Hamilton product ``a b`` of quaternions ``(w, x, y, z)``: the rotation ``R(a) R(b)``;
    (4,), (4,) -> (4,)."""
    w1, x1, y1, z1 = a[0], a[1], a[2], a[3]
    w2, x2, y2, z2 = b[0], b[1], b[2], b[3]
    return jnp.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def quaternion_exp(w: Array) -> Array:
    """Unit quaternion of the rotation vector ``w``: ``(cos(t/2), sin(t/2) w / t)``, ``t = |w|``;
    (3,) -> (4,). Taylor branch below :func:`get_epsilon`."""
    w = jnp.asarray(w)
    sq = jnp.sum(w * w)
    small, safe = small_angle(sq)
    t = jnp.sqrt(safe)
    half = jnp.where(small, 0.5 - sq / 48.0 + sq * sq / 3840.0, jnp.sin(0.5 * t) / t)
    c = jnp.where(small, 1.0 - sq / 8.0 + sq * sq / 384.0, jnp.cos(0.5 * t))
    return jnp.concatenate([c[None], half * w])


def quaternion_log(q: Array) -> Array:
    """Rotation vector (angle in [0, pi]) of the unit quaternion ``q``; (4,) -> (3,). Taylor
    branch where ``|(x, y, z)|`` is below :func:`get_epsilon`."""
    q = jnp.asarray(q)
    q = jnp.where(q[0] < 0, -q, q)
    w, v = q[0], q[1:]
    sq = jnp.sum(v * v)
    small, safe = small_angle(sq)
    n = jnp.sqrt(safe)
    # 2 atan2(n, w) / n; near n = 0 (w near 1): 2 / w (1 - u^2 / 3 + u^4 / 5), u = n / w
    u2 = sq / (w * w)
    near = 2.0 / w * (1.0 - u2 / 3.0 + u2 * u2 / 5.0)
    return jnp.where(small, near, 2.0 * jnp.arctan2(n, w) / n) * v


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


# ----------------------------------------------------------------------------- host side (numpy)
# float64 numpy twins of the kernels above, for the builders, parsers and writers (no tracing).


def quaternion_to_matrix_np(q: Any) -> np.ndarray:
    """(3, 3) rotation of the quaternion ``(w, x, y, z)`` (scalar first, MuJoCo's order),
    normalised in float64 first (as MuJoCo's compiler does); ``q`` must be nonzero. Host twin of
    :func:`quaternion_to_matrix`.

    >>> bool(np.allclose(quaternion_to_matrix_np([0.0, 0.0, 0.0, 1.0]), np.diag([-1.0, -1, 1])))
    True
    """
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q / math.hypot(*(float(v) for v in q))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotation_about_axis_np(axis: Any, angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` (rad) about ``axis`` (normalised here), by Rodrigues. Host
    twin of :func:`rotation_about_axis` (which takes a unit axis)."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def make_transform_np(R: Any = None, p: Any = None) -> np.ndarray:
    """(4, 4) ``[[R, p], [0, 1]]``; ``R`` None means identity, ``p`` None means zero. Host twin
    of :func:`make_transform`.

    >>> make_transform_np(None, [1.0, 2.0, 3.0])[:3, 3].tolist()
    [1.0, 2.0, 3.0]
    """
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def matrix_to_rpy_np(R: Any) -> np.ndarray:
    """Roll, pitch, yaw (``R = Rz(yaw) Ry(pitch) Rx(roll)``) of a 3x3 rotation, in float64 on
    the host: yaw from the first column, then roll and pitch from ``Rz(-yaw) R = Ry(pitch)
    Rx(roll)``, whose entries stay of order one, so the angles rebuild ``R`` to rounding (about
    1e-16) everywhere, at and near gimbal lock (pitch = +-pi/2; yaw is 0 where the first
    column has no x, y component at all) too. Host twin of :func:`matrix_to_rpy`: the two agree
    to rounding away from gimbal lock and both take yaw = 0 exactly at it.

    >>> matrix_to_rpy_np(np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]))  # pitch = pi/2
    array([0.        , 1.57079633, 0.        ])
    """
    R = np.asarray(R, dtype=np.float64)
    c = math.hypot(R[0, 0], R[1, 0])
    yaw = math.atan2(R[1, 0], R[0, 0]) if c > 0.0 else 0.0
    cy, sy = math.cos(yaw), math.sin(yaw)
    # Rz(-yaw) R = Ry(pitch) Rx(roll) = [[cp, sp sr, sp cr], [0, cr, -sr], [-sp, cp sr, cp cr]]
    r00 = cy * R[0, 0] + sy * R[1, 0]
    r11 = -sy * R[0, 1] + cy * R[1, 1]
    r12 = -sy * R[0, 2] + cy * R[1, 2]
    roll = math.atan2(-r12, r11)
    pitch = math.atan2(-R[2, 0], r00)
    return np.array([roll, pitch, yaw]) + 0.0  # no -0.0
