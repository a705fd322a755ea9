"""The configuration manifold: ``integrate``, ``difference``, ``neutral`` and ``normalize``.

A configuration ``q`` has ``robot.nq`` entries and a velocity (a tangent vector) ``v`` has
``robot.nv``; they differ when the robot has free, ball or planar joints, whose coordinates are
(:data:`jaxkin.model.COORDINATES`):

==========  =====================================  ==========================================
joint       ``q`` entries                          ``v`` entries
==========  =====================================  ==========================================
revolute,   the angle or displacement              its rate
prismatic
free        ``(x, y, z, qw, qx, qy, qz)``          ``(vx, vy, vz, wx, wy, wz)``
ball        ``(qw, qx, qy, qz)``                   ``(wx, wy, wz)``
planar      ``(x, y, cos(theta), sin(theta))``     ``(vx, vy, wz)``
==========  =====================================  ==========================================

* A free joint's ``(x, y, z)`` is the child frame's origin in the joint frame (its parent's
  frame moved by the joint's placement) and ``(qw, qx, qy, qz)`` the child frame's orientation
  there, as a unit quaternion, scalar first (MuJoCo's ``qpos`` order; Pinocchio stores
  ``(x, y, z, w)``). A planar joint moves in its joint frame's xy plane (Pinocchio's
  ``JointModelPlanar``).
* Velocities follow Pinocchio: ``v`` is the child frame's twist relative to the joint frame,
  linear part first, expressed in the child frame's own axes (``LOCAL``): for a free joint the
  velocity of the child origin and the angular velocity, both in child axes. (MuJoCo's
  free-joint ``qvel`` gives the linear velocity in world axes instead: ``v_lin = R^T
  qvel[:3]``, with ``R`` the child frame's orientation in its parent frame.)
* ``integrate(robot, q, v, dt)`` moves each joint along the exponential: ``M(q') = M(q)
  exp(v dt)``, the exponential of SE(3) for a free joint (translation and rotation coupled, as
  ``pinocchio.integrate``), of SO(3) for a ball joint, of SE(2) for a planar joint, and
  ``q' = q + v dt`` for revolute and prismatic joints. ``difference(robot, q0, q1)`` is its
  inverse, ``log(M(q0)^-1 M(q1))``: the ``v`` with ``integrate(q0, v) == q1`` (rotation angles
  in [0, pi]); ``pinocchio.difference`` computes the same.

Quaternions and (cos, sin) pairs are normalised before use, as the forward kinematics does; the
results of :func:`integrate` are unit. All functions are pure and jittable, work on one
configuration (batch with ``jax.vmap``) in float32 and float64; called eagerly they reuse a
compiled executable.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import check_q, check_robot, check_scalar, check_v, result_dtype
from ._jit import eager
from .model import COORDINATES, JOINT_SIZES, Robot, resolve_dtype
from .spatial import (
    left_jacobian_so3,
    left_jacobian_so3_inverse,
    quaternion_conjugate,
    quaternion_exp,
    quaternion_log,
    quaternion_multiply,
    quaternion_to_matrix,
    small_angle,
)

__all__ = ["difference", "integrate", "neutral", "normalize"]


# ----------------------------------------------------------------------------- layout
def _segments(robot: Robot) -> list[tuple[str, int, int]]:
    """``(kind, q start, v start)`` of every independent joint, in ``q`` order (1-dof joints,
    mimic leaders included, as kind "scalar")."""
    seen: dict[int, tuple[str, int, int]] = {}
    for kind, qi, vi in zip(robot.kinds, robot.q_index, robot.v_index, strict=True):
        if qi >= 0 and qi not in seen:
            seen[qi] = (kind if kind in COORDINATES else "scalar", qi, vi)
    return [seen[k] for k in sorted(seen)]


def _unit(x):
    """``x`` / ``|x|``, scaled by its largest magnitude first so that no square overflows or
    underflows (NaN for ``x = 0``)."""
    x = x / jnp.max(jnp.abs(x))
    return x * jax.lax.rsqrt(jnp.sum(x * x))


# ----------------------------------------------------------------------------- quaternions
def _same_hemisphere(q1, q0):
    """``q1`` or ``-q1`` (the same rotation), whichever is nearer ``q0`` (Pinocchio's choice)."""
    return jnp.where(jnp.dot(q1, q0) < 0, -q1, q1)


# ----------------------------------------------------------------------------- SE(2)
def _se2_AB(w):
    """``(sin w / w, (1 - cos w) / w)``, the entries of SE(2)'s ``V = [[A, -B], [B, A]]``."""
    sq = w * w
    small, _ = small_angle(sq)
    ws = jnp.where(small, jnp.ones_like(w), w)
    A = jnp.where(small, 1.0 - sq / 6.0 + sq * sq / 120.0, jnp.sin(ws) / ws)
    B = jnp.where(small, w * (0.5 - sq / 24.0 + sq * sq / 720.0), (1.0 - jnp.cos(ws)) / ws)
    return A, B


# ----------------------------------------------------------------------------- per joint
def _integrate_joint(kind: str, q, v):
    if kind == "ball":
        q0 = _unit(q)
        return _unit(_same_hemisphere(quaternion_multiply(q0, quaternion_exp(v)), q0))
    if kind == "free":
        t0, q0 = q[:3], _unit(q[3:])
        t1 = t0 + quaternion_to_matrix(q0) @ (left_jacobian_so3(v[3:]) @ v[:3])
        q1 = _unit(_same_hemisphere(quaternion_multiply(q0, quaternion_exp(v[3:])), q0))
        return jnp.concatenate([t1, q1])
    # planar
    cs = _unit(q[2:])
    c0, s0 = cs[0], cs[1]
    w = v[2]
    A, B = _se2_AB(w)
    lx, ly = A * v[0] - B * v[1], B * v[0] + A * v[1]
    cw, sw = jnp.cos(w), jnp.sin(w)
    return jnp.stack(
        [
            q[0] + c0 * lx - s0 * ly,
            q[1] + s0 * lx + c0 * ly,
            c0 * cw - s0 * sw,
            s0 * cw + c0 * sw,
        ]
    )


def _difference_joint(kind: str, q0, q1):
    if kind == "ball":
        return quaternion_log(quaternion_multiply(quaternion_conjugate(_unit(q0)), _unit(q1)))
    if kind == "free":
        r0, r1 = _unit(q0[3:]), _unit(q1[3:])
        w = quaternion_log(quaternion_multiply(quaternion_conjugate(r0), r1))
        t = quaternion_to_matrix(r0).T @ (q1[:3] - q0[:3])
        return jnp.concatenate([left_jacobian_so3_inverse(w) @ t, w])
    a, b = _unit(q0[2:]), _unit(q1[2:])
    c0, s0, c1, s1 = a[0], a[1], b[0], b[1]
    w = jnp.arctan2(c0 * s1 - s0 * c1, c0 * c1 + s0 * s1)
    dx, dy = q1[0] - q0[0], q1[1] - q0[1]
    lx, ly = c0 * dx + s0 * dy, -s0 * dx + c0 * dy  # R0^T (t1 - t0)
    A, B = _se2_AB(w)
    n = A * A + B * B
    return jnp.stack([(A * lx + B * ly) / n, (-B * lx + A * ly) / n, w])


# ----------------------------------------------------------------------------- kernels
def _integrate(robot: Robot, q, v, dt):
    dtype = result_dtype(robot, q, v)
    q, v = q.astype(dtype), v.astype(dtype) * jnp.asarray(dt, dtype)
    if robot.nq == robot.nv:
        return q + v
    parts = []
    for kind, qi, vi in _segments(robot):
        if kind == "scalar":
            parts.append((q[qi] + v[vi])[None])
        else:
            nq, nv = JOINT_SIZES[kind]
            parts.append(_integrate_joint(kind, q[qi : qi + nq], v[vi : vi + nv]))
    return jnp.concatenate(parts) if parts else q


def _difference(robot: Robot, q0, q1):
    dtype = result_dtype(robot, q0, q1)
    q0, q1 = q0.astype(dtype), q1.astype(dtype)
    if robot.nq == robot.nv:
        return q1 - q0
    parts = []
    for kind, qi, _ in _segments(robot):
        if kind == "scalar":
            parts.append((q1[qi] - q0[qi])[None])
        else:
            nq = JOINT_SIZES[kind][0]
            parts.append(_difference_joint(kind, q0[qi : qi + nq], q1[qi : qi + nq]))
    return jnp.concatenate(parts) if parts else q1 - q0


def _normalize(robot: Robot, q):
    q = q.astype(result_dtype(robot, q))
    if robot.nq == robot.nv:
        return q
    parts = []
    for kind, qi, _ in _segments(robot):
        if kind == "scalar":
            parts.append(q[qi][None])
        elif kind == "ball":
            parts.append(_unit(q[qi : qi + 4]))
        elif kind == "free":
            parts.append(jnp.concatenate([q[qi : qi + 3], _unit(q[qi + 3 : qi + 7])]))
        else:
            parts.append(jnp.concatenate([q[qi : qi + 2], _unit(q[qi + 2 : qi + 4])]))
    return jnp.concatenate(parts)


_integrate_eager = eager(_integrate)
_difference_eager = eager(_difference)
_normalize_eager = eager(_normalize)


def integrate_kernel(robot: Robot, q: jax.Array, v: jax.Array, dt: Any = 1.0) -> jax.Array:
    """:func:`integrate` on checked arrays (for kernels that differentiate through it)."""
    return _integrate(robot, q, v, dt)


# ----------------------------------------------------------------------------- public
def integrate(robot: Robot, q: Any, v: Any, dt: Any = 1.0) -> jax.Array:
    """The configuration reached from ``q`` (nq,) by moving with velocity ``v`` (nv,) for
    time ``dt`` (one number; for several, ``jax.vmap`` over it); shape (nq,).

    Each joint follows the exponential map (module doc): ``M(q') = M(q) exp(v dt)``, the
    velocity expressed in the child frame (Pinocchio's ``integrate``); revolute and prismatic
    joints add ``v dt``. Quaternions and (cos, sin) pairs of the result are unit; a quaternion
    keeps the sign nearest the input's.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.Robot.from_joints([dict(name="root", type="free", child="body")])
    >>> robot.nq, robot.nv
    (7, 6)
    >>> q = jk.neutral(robot)  # origin, identity quaternion (1, 0, 0, 0)
    >>> v = jnp.array([1.0, 0.0, 0.0, 0.0, 0.0, jnp.pi])  # forward while turning about z
    >>> q1 = jk.integrate(robot, q, v)
    >>> q1.round(6).tolist()  # a half circle of diameter 2/pi, facing back
    [0.0, 0.63662, 0.0, 0.0, 0.0, 0.0, 1.0]
    >>> bool(jnp.allclose(jk.difference(robot, q, q1), v))
    True
    """
    fn = "jk.integrate"
    hint = "jax.vmap(lambda q, v: jk.integrate(robot, q, v))(qs, vs)"
    q = check_q(robot, q, fn=fn, batch_hint=hint)
    v = check_v(robot, v, what="v", fn=fn, batch_hint=hint)
    dt = check_scalar(
        dt,
        "dt",
        fn,
        "the time to move for",
        " For several times use jax.vmap(lambda dt: jk.integrate(robot, q, v, dt))(dts).",
    )
    return _integrate_eager(robot, q, v, jnp.asarray(dt, result_dtype(robot, q, v)))


def difference(robot: Robot, q0: Any, q1: Any) -> jax.Array:
    """The velocity ``v`` (nv,) that moves ``q0`` to ``q1`` (both (nq,)) in unit time:
    ``integrate(robot, q0, difference(robot, q0, q1)) == q1`` (quaternions up to sign).

    ``log(M(q0)^-1 M(q1))`` joint by joint (module doc), as ``pinocchio.difference``; rotation
    angles are taken in [0, pi] (at exactly pi the axis' sign is arbitrary); revolute and
    prismatic joints give ``q1 - q0``.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.Robot.from_joints([dict(name="ball", type="ball", child="link")])
    >>> q0 = jk.neutral(robot)
    >>> q1 = jnp.array([jnp.cos(0.25), 0.0, jnp.sin(0.25), 0.0])  # 0.5 rad about y
    >>> jk.difference(robot, q0, q1).round(6).tolist()
    [0.0, 0.5, 0.0]
    """
    fn = "jk.difference"
    hint = "jax.vmap(lambda q0, q1: jk.difference(robot, q0, q1))(q0s, q1s)"
    q0 = check_q(robot, q0, what="q0", fn=fn, batch_hint=hint)
    q1 = check_q(robot, q1, what="q1", fn=fn, batch_hint=hint)
    return _difference_eager(robot, q0, q1)


def neutral(robot: Robot, dtype: Any = None) -> jax.Array:
    """The neutral configuration (nq,): 0 for revolute and prismatic joints, the identity
    ``(1, 0, 0, 0)`` quaternion for free and ball joints (free: at the origin), ``(0, 0, 1, 0)``
    for planar joints. As Pinocchio's ``neutral`` (quaternions reordered, scalar first).

    >>> import jaxkin as jk
    >>> robot = jk.Robot.from_joints(
    ...     [dict(name="p", type="planar", child="a"), dict(name="j", type="revolute", child="b")]
    ... )
    >>> jk.neutral(robot).tolist(), robot.joint_names
    ([0.0, 0.0, 1.0, 0.0, 0.0], ('p.x', 'p.y', 'p.cos', 'p.sin', 'j'))
    """
    check_robot(robot, "jk.neutral")
    dt = robot.dtype if dtype is None else resolve_dtype(dtype)
    q = np.zeros(robot.nq)
    for kind, qi, _ in _segments(robot):
        if kind == "free":
            q[qi + 3] = 1.0
        elif kind == "ball":
            q[qi] = 1.0
        elif kind == "planar":
            q[qi + 2] = 1.0
    return jnp.asarray(q, dtype=dt)


def normalize(robot: Robot, q: Any) -> jax.Array:
    """``q`` (nq,) with each quaternion and (cos, sin) pair scaled to unit length (the other
    entries unchanged); a zero one raises eagerly and gives NaN under a trace.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.Robot.from_joints([dict(name="ball", type="ball", child="link")])
    >>> jk.normalize(robot, jnp.array([2.0, 0.0, 0.0, 0.0])).tolist()
    [1.0, 0.0, 0.0, 0.0]
    """
    q = check_q(robot, q, fn="jk.normalize")
    return _normalize_eager(robot, q)
