"""Inverse differential kinematics for a stack of prioritised tasks, with hard joint limits.

A *task* asks for a velocity of something the robot moves: a frame's twist (rows
``[v; omega]``, or only the position rows ``v`` or only the orientation rows ``omega``), the
centre of mass' velocity, or the joint velocity toward a reference configuration (posture).
Each task gives rows ``J_i qd = x_i`` (``J_i`` (m_i, nv), ``x_i`` (m_i,)). Tasks are listed in
priority order; a tuple (or list) of tasks inside the list is one level whose rows are stacked
(weighted least squares among them). :func:`solve_tasks` returns the joint velocity ``qd``
(nv,) of the recursive null-space scheme (Siciliano & Slotine 1991): level 1 is solved as well
as it can be, level 2 as well as it can be without disturbing level 1, and so on::

    qd_k = qd_{k-1} + (J_k P_{k-1})^# (x_k - J_k qd_{k-1})
    P_k  = P_{k-1} - (J_k P_{k-1})^# J_k P_{k-1}

with ``qd_0 = 0`` (the velocity nearest 0 in the limits' box, below, when a joint is outside its
limits) and ``P_0 = I``. For two tasks this is the textbook's
``qd = J1^+ x1 + (J2 N1)^+ (x2 - J2 J1^+ x1)``, ``N1 = I - J1^+ J1``.

Damping (``damping = lambda``): each ``(J_k P_{k-1})^#`` is a damped pseudo-inverse with the
damping applied per singular value, ``sigma / (sigma^2 + lambda_i^2)`` with
``lambda_i^2 = max(lambda^2 - sigma^2 / 4, 0)`` (Chiaverini's singularity-adaptive damping,
per singular value, with threshold ``2 lambda``): singular values ``sigma >= 2 lambda`` are
inverted exactly (``1 / sigma``: a well-conditioned task is met exactly), smaller ones are
damped and their gain never exceeds ``1 / (sqrt(3) lambda)``, so a singular task gives bounded
joint velocities, never inf (for ``lambda > 0``). Singular values below ``sqrt(eps) * |J_k|_F``
count as zero (rank). ``lambda = 0`` gives the plain pseudo-inverse with that cut.

Hard limits. Each joint velocity is bounded, ``lo <= qd <= hi``: by ``velocity_limits`` and, for
revolute and prismatic joints with finite limits, by the position limits reached in one step,
``lower <= q + qd dt <= upper``. A robot already outside its limits is driven back (the bound
asks for the velocity toward the range, at most the velocity limit). Free, ball and planar
joints have no position limits. The limits hold exactly: every ``qd`` returned satisfies them
(a final clip removes rounding only).

Why saturation in the null space (SNS; Flacco, De Luca & Khatib, IEEE T-RO 2015) and not a QP
per step: the limits are boxes on ``qd``, for which SNS is exact and needs no solver. At each
level it solves the task, and while a joint leaves its box it saturates the most critical joint
(the one that leaves first along the correction) at its bound, as an extra constraint ranked
between the higher levels and this task (``(D P_{k-1})^#`` with ``D`` selecting the saturated
joints), and solves again with the remaining joints; if saturating would cost the task a
direction (a singular value falls below ``2 lambda``), it keeps the largest feasible fraction
``s`` of the best correction found instead (task scaling). So the limits are met by
construction (not to a solver tolerance), higher levels are never disturbed by lower ones
(every correction lies in their null space), at most ``nv + 1`` iterations of two small SVDs
per level bound the work (a ``lax.while_loop`` with fixed shapes, vmappable), and nothing is
added to the
dependencies (a QP in JAX would need a solver such as jaxopt/OSQP, iterate to a tolerance, and
give limits met only to that tolerance). What SNS does not do that a QP can: inequality tasks
and general linear constraints (this module needs only boxes), and a guarantee of the largest
feasible scale in every case (SNS chooses greedily; in the tests it met the primary exactly in
each of 36 boxes where a linear program found it feasible). Where scaling is used, the
level's correction ``qd_k - qd_{k-1}`` is scaled (not its task velocity alone), so ``s = 0``
returns the higher levels' solution, which is feasible; ``scale`` reports ``s`` per level (1
when the level's task was met as fully as without limits).

:func:`follow_paths` runs the scheme as a closed-loop resolved-rate controller (CLIK) along
paths of poses for several frames at once (``lax.scan``, jitted), feeding back each frame's
pose error so that drift does not accumulate, and integrates on the configuration manifold
(:func:`jaxkin.integrate`), so floating-base and ball-joint robots work.

Conventions: frame poses ``T_world_frame``; twists and rows ``[v; omega]``; ``reference``
(``"world_aligned"``, ``"local"``, ``"world"``) as in :mod:`jaxkin.jacobians`; velocities have
``robot.nv`` entries (:mod:`jaxkin.configuration`). Kernels work on one configuration; batch with
``jax.vmap``; float32 and float64. Not differentiable in general (SVDs of rank-deficient
matrices, and the discrete choice of saturated joints). Non-finite input follows
:mod:`jaxkin.analysis` ("Non-finite input"): eagerly raises naming the argument, under a trace
the result is NaN.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import spatial
from ._checks import (
    check_frames,
    check_inertia,
    check_poses,
    check_q,
    check_reference,
    check_robot,
    check_scalar,
    finite_guard,
    is_traced,
    result_dtype,
)
from ._jacobian_pass import jacobians_pass
from ._jit import robot_jit
from .com import com_and_jacobian
from .configuration import difference, integrate_kernel
from .errors import JaxkinError, ShapeError
from .model import Robot
from .pose_errors import pose_error, pose_error_norms

__all__ = [
    "ComTask",
    "FollowResult",
    "FrameTask",
    "PostureTask",
    "TaskSolution",
    "follow_paths",
    "solve_tasks",
]

ROWS = {"all": slice(0, 6), "position": slice(0, 3), "orientation": slice(3, 6)}


# ----------------------------------------------------------------------------- task specs
def _pytree(data: tuple[str, ...], meta: tuple[str, ...]):
    def register(cls):
        return jax.tree_util.register_dataclass(cls, data_fields=list(data), meta_fields=list(meta))

    return register


@_pytree(data=("target", "velocity", "gain", "weight"), meta=("frame", "rows", "reference"))
@dataclasses.dataclass(frozen=True)
class FrameTask:
    """Rows ``J_frame qd = x`` for one frame, or for several frames at once.

    Args:
      frame: a frame name or index, or a list of them (k frames; then ``target`` is (k, 4, 4),
        ``velocity`` (k, m) and ``weight`` may be (k, m)).
      target: optional desired pose(s) ``T_world_frame`` (4, 4): the task velocity gets
        ``gain * e / dt``, ``e`` the pose error ``[p_d - p; log(R_d R^T)]`` (world axes, at the
        frame origin: :func:`jaxkin.pose_error`) expressed in ``reference``.
      velocity: optional desired twist (m,), in ``reference`` (default 0): the feed-forward.
      rows: ``"all"`` (m = 6, ``[v; omega]``), ``"position"`` (m = 3, ``v``: the origin's
        velocity) or ``"orientation"`` (m = 3, ``omega``).
      reference: ``"world_aligned"`` (default: frame origin, world axes), ``"local"`` (frame
        origin, frame axes) or ``"world"`` (spatial velocity: the point at the world origin,
        world axes); as :func:`jaxkin.geometric_jacobian`.
      gain: the fraction of the pose error removed per step, in [0, 1] (1: aim at the target in
        one step; used only with ``target``).
      weight: weight (>= 0) of the rows within their level, scalar or (m,) (or (k, m)).
    """

    frame: Any
    target: Any = None
    velocity: Any = None
    rows: str = "all"
    reference: str = "world_aligned"
    gain: Any = 1.0
    weight: Any = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.frame, list):
            object.__setattr__(self, "frame", tuple(self.frame))


@_pytree(data=("target", "velocity", "gain", "weight"), meta=("axes",))
@dataclasses.dataclass(frozen=True)
class ComTask:
    """Rows ``Jc[axes] qd = x`` for the centre of mass (world coordinates; ``Jc`` of
    :func:`jaxkin.com_jacobian`), for a robot with inertial data.

    Args:
      target: optional desired centre of mass (3,) in world coordinates: the task velocity gets
        ``gain * (target - c)[axes] / dt``.
      velocity: optional desired centre-of-mass velocity (m,) along ``axes`` (default 0).
      axes: which world axes, a string of distinct letters from ``"xyz"`` in that order (m of
        them): ``"xy"`` keeps the centre of mass over a point of the ground and leaves its
        height free.
      gain: the fraction of the error removed per step, in [0, 1].
      weight: weight (>= 0) of the rows within their level, scalar or (m,).
    """

    target: Any = None
    velocity: Any = None
    axes: str = "xyz"
    gain: Any = 1.0
    weight: Any = 1.0


@_pytree(data=("target", "gain", "weight"), meta=())
@dataclasses.dataclass(frozen=True)
class PostureTask:
    """Rows ``I qd = gain * difference(q, target) / dt`` (nv rows): move toward the reference
    configuration ``target`` (nq,) (e.g. ``jk.neutral(robot)``, or the start), usually as the
    last level, where it only uses what the other tasks leave free. ``gain`` in [0, 1] is the
    fraction of the difference closed per step; ``weight`` scalar or (nv,) (e.g. 0 for the
    free-flyer's entries to leave the base out)."""

    target: Any
    gain: Any = 1.0
    weight: Any = 1.0


class TaskSolution(NamedTuple):
    """Output of :func:`solve_tasks`: ``qd`` (nv,) the joint velocity, within the limits;
    ``scale`` (levels,) in [0, 1]: the fraction of each level's correction that the limits let
    through (1: the level's task was met as fully as without limits)."""

    qd: jax.Array
    scale: jax.Array


class FollowResult(NamedTuple):
    """Output of :func:`follow_paths` for N targets per frame and k frames.

    ``q`` (N + 1, nq): ``q[0] = q0``, ``q[t + 1]`` after step t; ``qd`` (N, nv) the commanded
    velocities; ``scale`` (N, levels) as :class:`TaskSolution`; ``position_error`` (N, k) metres
    and ``orientation_error`` (N, k) radians: after step t, of each frame against its target
    ``t + 1`` (the last target for the last step), 0 for rows a frame does not track
    (``rows="position"`` or ``"orientation"``); ``max_position_error`` and
    ``max_orientation_error``: their maxima.
    """

    q: jax.Array
    qd: jax.Array
    scale: jax.Array
    position_error: jax.Array
    orientation_error: jax.Array
    max_position_error: jax.Array
    max_orientation_error: jax.Array


# ----------------------------------------------------------------------------- linear algebra
def _inverse(A: jax.Array, lam2: Any, rel_cut: float):
    """``(A^#, A^# A, rank)`` with the per-singular-value damping of the module doc; ``rank``
    counts the singular values inverted exactly (above the cut and ``2 lambda``)."""
    dtype = A.dtype
    U, s, Vt = jax.lax.linalg.svd(A, full_matrices=False)
    cut = rel_cut * jnp.sqrt(jnp.sum(A * A)) + jnp.finfo(dtype).tiny
    keep = s > cut
    exact = keep & (s >= 2.0 * jnp.sqrt(lam2))
    lam_i2 = jnp.maximum(lam2 - 0.25 * s * s, 0.0)
    denom = jnp.where(keep, s * s + lam_i2, 1.0)
    g = jnp.where(keep, s / denom, 0.0)
    Ainv = Vt.T @ (g[:, None] * U.T)
    AinvA = Vt.T @ ((g * s)[:, None] * Vt)
    return Ainv, AinvA, jnp.sum(exact)


def _scales(qd_prev, delta, lo, hi):
    """Per joint the largest s in [0, inf] with ``lo <= qd_prev + s delta <= hi``."""
    pos, neg = delta > 0, delta < 0
    d = jnp.where(pos | neg, delta, 1.0)
    return jnp.where(pos, (hi - qd_prev) / d, jnp.where(neg, (lo - qd_prev) / d, jnp.inf))


def _sns_level(J, x, qd_prev, P, lo, hi, lam2):
    """One level of the SNS recursion (module doc): ``(qd, s, P_next)``.

    Iteration 0 (nothing saturated) is the unconstrained step; it also gives the level's rank
    and the next projector ``P - (J P)^# J P``. Each further iteration saturates one joint."""
    dtype = J.dtype
    nv = qd_prev.shape[0]
    rel_cut = float(np.sqrt(np.finfo(dtype).eps))
    tol = 64 * jnp.finfo(dtype).eps

    def body(state):
        it, _, sat, qdN, best_s, best_qd, rank0, P_next = state
        D = sat.astype(dtype)
        Ainv, AinvA, _ = _inverse(D[:, None] * P, 0.0, rel_cut)
        qd_s = qd_prev + Ainv @ (D * (qdN - qd_prev))
        Binv, BinvB, rank = _inverse(J @ (P - AinvA), lam2, rel_cut)
        qd1 = qd_s + Binv @ (x - J @ qd_s)
        first = it == 0
        rank0 = jnp.where(first, rank.astype(rank0.dtype), rank0)
        P_next = jnp.where(first, P - BinvB, P_next)
        lost = rank < rank0
        delta = qd1 - qd_prev
        s_j = _scales(qd_prev, delta, lo, hi)
        s_max = jnp.clip(jnp.min(s_j), 0.0, 1.0)
        slack = tol * (1.0 + jnp.abs(qd1))
        viol = (qd1 > hi + slack) | (qd1 < lo - slack)
        feasible = ~jnp.any(viol)
        s_new = jnp.where(feasible, 1.0, s_max).astype(dtype)
        qd_new = jnp.where(feasible, qd1, qd_prev + s_max * delta)
        better = ~lost & (s_new > best_s)
        best_s = jnp.where(better, s_new, best_s)
        best_qd = jnp.where(better, qd_new, best_qd)
        free_viol = viol & ~sat
        j = jnp.argmin(jnp.where(free_viol, s_j, jnp.inf))
        stop = feasible | lost | ~jnp.any(free_viol)
        add = ~stop & (jnp.arange(nv) == j)
        sat = sat | add
        qdN = jnp.where(add, jnp.where(qd1 > hi, hi, lo), qdN)
        return it + 1, stop, sat, qdN, best_s, best_qd, rank0, P_next

    def cond(state):
        return ~state[1] & (state[0] <= nv)

    init = (
        jnp.zeros((), jnp.int32),
        jnp.zeros((), bool),
        jnp.zeros(nv, bool),
        jnp.zeros(nv, dtype),
        jnp.zeros((), dtype),
        qd_prev,
        jnp.zeros((), jnp.int32),
        P,
    )
    _, _, _, _, s, qd, _, P_next = jax.lax.while_loop(cond, body, init)
    return jnp.clip(qd, lo, hi), s, P_next


# ----------------------------------------------------------------------------- kernels
def _scalar_joints(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """``(q indices, v indices)`` of the revolute and prismatic coordinates (the ones with
    position limits), each once."""
    seen: dict[int, int] = {}
    for kind, qi, vi in zip(robot.kinds, robot.q_index, robot.v_index, strict=True):
        if qi >= 0 and kind in ("revolute", "prismatic") and qi not in seen:
            seen[qi] = vi
    qs = sorted(seen)
    return np.asarray(qs, dtype=np.int64), np.asarray([seen[k] for k in qs], dtype=np.int64)


def _bounds(robot: Robot, q, dt, vlo, vhi, position_limits: bool):
    """``(lo, hi)`` (nv,): the velocity box of the module doc."""
    if not position_limits:
        return vlo, vhi
    qi, vi = _scalar_joints(robot)
    if qi.size == 0:
        return vlo, vhi
    dtype = q.dtype
    lower = robot.lower.astype(dtype)[qi]
    upper = robot.upper.astype(dtype)[qi]
    plo, phi = (lower - q[qi]) / dt, (upper - q[qi]) / dt
    lo = jnp.maximum(vlo[vi], jnp.minimum(plo, vhi[vi]))
    hi = jnp.minimum(vhi[vi], jnp.maximum(phi, vlo[vi]))
    return vlo.at[vi].set(lo), vhi.at[vi].set(hi)


def _clip_to_limits(robot: Robot, q):
    """``q`` with its revolute and prismatic entries clipped to the robot's limits."""
    qi, _ = _scalar_joints(robot)
    if qi.size == 0:
        return q
    dtype = q.dtype
    return q.at[qi].set(
        jnp.clip(q[qi], robot.lower.astype(dtype)[qi], robot.upper.astype(dtype)[qi])
    )


def _frame_rows(J, T, spec, data, dt):
    """``(J_rows, x_rows)`` of one frame: J (6, nv) world_aligned and T (4, 4) from the pass."""
    _, _, rows, reference, _, _ = spec
    target, velocity, gain, _ = data
    R, p = T[:3, :3], T[:3, 3]
    if reference == "local":
        J = jnp.concatenate([R.T @ J[:3], R.T @ J[3:]])
    elif reference == "world":
        J = jnp.concatenate([J[:3] + spatial.skew(p) @ J[3:], J[3:]])
    sl = ROWS[rows]
    x = jnp.zeros(sl.stop - sl.start, J.dtype) if velocity is None else velocity
    if target is not None:
        e = pose_error(T, target)
        if reference == "local":
            e = jnp.concatenate([R.T @ e[:3], R.T @ e[3:]])
        elif reference == "world":
            e = jnp.concatenate([e[:3] + jnp.cross(p, e[3:]), e[3:]])
        x = x + gain * e[sl] / dt
    return J[sl], x


def _level_rows(robot, q, level, data, frames, Js, Ts, com, dt):
    """The stacked, weighted rows ``(J, x)`` of one level."""
    Jr, xr = [], []
    for spec, d in zip(level, data, strict=True):
        if spec[0] == "frame":
            i = frames.index(spec[1])
            J, x = _frame_rows(Js[i], Ts[i], spec, d, dt)
            w = d[3]
        elif spec[0] == "com":
            axes = np.asarray(["xyz".index(a) for a in spec[1]])
            target, velocity, gain, w = d
            c, Jc = com
            J = Jc[axes]
            x = jnp.zeros(len(axes), q.dtype) if velocity is None else velocity
            if target is not None:
                x = x + gain * (target - c)[axes] / dt
        else:  # posture
            target, gain, w = d
            J = jnp.eye(robot.nv, dtype=q.dtype)
            x = gain * difference(robot, q, target) / dt
        Jr.append(w[:, None] * J)
        xr.append(w * x)
    return jnp.concatenate(Jr), jnp.concatenate(xr)


def _stack_kernel(
    robot, q, data, dt, vlo, vhi, damping, levels, frames, Js, Ts, position_limits, com=None
):
    """:func:`solve_tasks` on checked arrays, with the frames' Jacobians ``Js`` (k, 6, nv) and
    poses ``Ts`` (k, 4, 4) given (world_aligned), and ``com = (c, Jc)`` when a level has a
    centre-of-mass task."""
    lo, hi = _bounds(robot, q, dt, vlo, vhi, position_limits)
    qd = jnp.clip(jnp.zeros(robot.nv, q.dtype), lo, hi)
    P = jnp.eye(robot.nv, dtype=q.dtype)
    lam2 = damping * damping
    rows = [
        _level_rows(robot, q, lv, d, frames, Js, Ts, com, dt)
        for lv, d in zip(levels, data, strict=True)
    ]
    if len(rows) == 1:
        qd, s, _ = _sns_level(*rows[0], qd, P, lo, hi, lam2)
        return qd, s[None]
    # the levels padded with zero rows (which change no solution) to one height and scanned:
    # one compiled level however many there are
    m = max(J.shape[0] for J, _ in rows)
    J = jnp.stack([jnp.pad(J, ((0, m - J.shape[0]), (0, 0))) for J, _ in rows])
    x = jnp.stack([jnp.pad(x, (0, m - x.shape[0])) for _, x in rows])

    def level(carry, Jx):
        qd, P = carry
        qd, s, P = _sns_level(*Jx, qd, P, lo, hi, lam2)
        return (qd, P), s

    (qd, _), scales = jax.lax.scan(level, (qd, P), (J, x))
    return qd, scales


def _frames_of(levels) -> tuple[int, ...]:
    return tuple(dict.fromkeys(spec[1] for level in levels for spec in level if spec[0] == "frame"))


def _pass(robot, q, frames):
    if not frames:
        return None, None
    g = jacobians_pass(robot, q, frames)
    return g.matrix(), g.pose()


def _solve_impl(robot, q, data, dt, vlo, vhi, damping, *, levels, position_limits):
    frames = _frames_of(levels)
    Js, Ts = _pass(robot, q, frames)
    has_com = any(spec[0] == "com" for level in levels for spec in level)
    com = com_and_jacobian(robot, q) if has_com else None
    qd, scale = _stack_kernel(
        robot, q, data, dt, vlo, vhi, damping, levels, frames, Js, Ts, position_limits, com
    )
    return TaskSolution(qd, scale)


_solve = robot_jit(_solve_impl, ("levels", "position_limits"))


def _follow_impl(
    robot,
    q0,
    targets,
    twists,
    gains,
    weights,
    dt,
    vlo,
    vhi,
    damping,
    posture,
    *,
    levels,
    position_limits,
):
    frames = _frames_of(levels[:1])
    k = len(frames)
    dtype = q0.dtype
    if twists is None:
        twists = _path_twists(targets, dt)

    def step(q, xs):
        Td, V = xs
        Js, Ts = _pass(robot, q, frames)
        data0 = tuple((Td[i], V[i][ROWS[levels[0][i][2]]], gains[i], weights[i]) for i in range(k))
        data = (data0,) + (((posture[0], posture[1], posture[2]),),) * (len(levels) - 1)
        qd, scale = _stack_kernel(
            robot, q, data, dt, vlo, vhi, damping, levels, frames, Js, Ts, position_limits
        )
        q_next = integrate_kernel(robot, q, qd, dt)
        if position_limits:
            q_next = _clip_to_limits(robot, q_next)
        ep, eo = jax.vmap(pose_error_norms)(Ts, Td)
        return q_next, (q_next, qd, scale, ep, eo)

    # one step more, on the last target, measures where the last real step arrived (one pass
    # in the compiled loop instead of a second one after it); its own motion is dropped
    targets = jnp.concatenate([targets, targets[-1:]])
    twists = jnp.concatenate([twists, jnp.zeros_like(twists[-1:])])
    _, (qs, qds, scales, ep, eo) = jax.lax.scan(step, q0, (targets, twists))
    # the scan measured q_t against targets[t]; report q_{t+1} against targets[t + 1]
    tracked = [spec[2] for spec in levels[0]]  # rows not tracked report 0
    ep = ep[1:].astype(dtype) * jnp.asarray([[r != "orientation" for r in tracked]], dtype)
    eo = eo[1:].astype(dtype) * jnp.asarray([[r != "position" for r in tracked]], dtype)
    q = jnp.concatenate([q0[None], qs[:-1]])
    return FollowResult(q, qds[:-1], scales[:-1], ep, eo, jnp.max(ep), jnp.max(eo))


_follow = robot_jit(_follow_impl, ("levels", "position_limits"))


def _path_twists(Ts: jax.Array, dt) -> jax.Array:
    """(N, k, 6) feed-forward twists (world_aligned) from successive targets; 0 for the last."""
    V = jax.vmap(jax.vmap(pose_error))(Ts[:-1], Ts[1:]) / dt
    return jnp.concatenate([V, jnp.zeros((1, *V.shape[1:]), V.dtype)])


# ----------------------------------------------------------------------------- checks
def _array(x, what, fn, shape, dtype, meaning):
    """``x`` as a ``dtype`` array of ``shape`` (ShapeError naming ``what`` otherwise)."""
    if not hasattr(x, "shape"):
        try:
            x = np.asarray(x, dtype=float)
        except (TypeError, ValueError):
            raise ShapeError(f"{fn}: {what} must be {meaning}, got {x!r:.80}.") from None
    if np.dtype(x.dtype).kind not in "fiub":
        raise ShapeError(f"{fn}: {what} must be real numbers ({meaning}), got dtype {x.dtype}.")
    if tuple(x.shape) != tuple(shape):
        raise ShapeError(
            f"{fn}: {what} must have shape {tuple(shape)} ({meaning}), got {tuple(x.shape)}."
        )
    return jnp.asarray(x, dtype=dtype)


def _check_rigid(Ts, what, fn):
    """Concrete poses (..., 4, 4) must be finite rigid transforms (``_checks.check_poses``)."""
    if not is_traced(Ts):
        Tn = np.asarray(Ts, dtype=np.float64).reshape(-1, 4, 4)
        check_poses(Tn, fn, what, np.float64, batch="required")


def _weights(w, m, k, what, fn, dtype):
    """A weight given as a scalar, (m,) or (k, m) (k frames), as (k, m)."""
    a = w if hasattr(w, "shape") else np.asarray(w, dtype=float)
    shape = tuple(a.shape)
    if shape not in ((), (m,), (k, m)):
        many = f" or ({k}, {m}) (one row per frame)" if k > 1 else ""
        raise ShapeError(
            f"{fn}: {what} must be one number or have shape ({m},){many}, got {shape}."
        )
    if not is_traced(a) and not np.all(np.asarray(a, dtype=float) >= 0):
        raise JaxkinError(f"{fn}: {what} must be >= 0, got {np.asarray(a).tolist()}.")
    return jnp.broadcast_to(jnp.asarray(a, dtype=dtype), (k, m))


def _frame_weights(weight, k, fn, dtype):
    """:func:`follow_paths`' ``weight``: one number, (k,) (one per frame) or (k, 6), as (k, 6)."""
    a = weight if hasattr(weight, "shape") else np.asarray(weight, dtype=float)
    shape = tuple(a.shape)
    if shape not in ((), (k,), (k, 6)):
        raise ShapeError(
            f"{fn}: weight must be one number, ({k},) (one per frame) or ({k}, 6) (one per row "
            f"[v; omega] of each frame), got {shape}."
        )
    if shape == (k,):
        a = jnp.broadcast_to(jnp.asarray(a, dtype=dtype)[:, None], (k, 6))
    return _weights(a, 6, k, "weight", fn, dtype)


def _gain(g, what, fn, dtype):
    g = check_scalar(g, what, fn, "the fraction of the error removed per step, in [0, 1]")
    if not is_traced(g) and not 0.0 <= float(g) <= 1.0:
        raise JaxkinError(
            f"{fn}: {what} must be in [0, 1] (the fraction of the error removed per step; 1 "
            f"aims at the target in one step), got {float(g)}."
        )
    return jnp.asarray(g, dtype=dtype)


def _check_frame_task(robot, task, dtype, fn, where):
    if task.rows not in ROWS:
        raise JaxkinError(f"{fn}: {where}.rows must be one of {tuple(ROWS)}, got {task.rows!r}.")
    check_reference(task.reference)
    many = check_frames(robot, task.frame, fn)
    frames = many if many is not None else (robot.frame_index(task.frame),)
    k, m = len(frames), ROWS[task.rows].stop - ROWS[task.rows].start
    lead = (k,) if many is not None else ()
    target = velocity = None
    if task.target is not None:
        what = "one pose per frame" if lead else "a pose T_world_frame"
        target = _array(task.target, f"{where}.target", fn, (*lead, 4, 4), dtype, what)
        target = target.reshape(k, 4, 4)
        _check_rigid(target, f"{where}.target", fn)
    if task.velocity is not None:
        what = f"rows {task.rows!r} of a twist in reference {task.reference!r}"
        velocity = _array(task.velocity, f"{where}.velocity", fn, (*lead, m), dtype, what)
        velocity = velocity.reshape(k, m)
    gain = _gain(task.gain, f"{where}.gain", fn, dtype)
    weight = _weights(task.weight, m, k, f"{where}.weight", fn, dtype)
    specs, data = [], []
    for i, f in enumerate(frames):
        specs.append(
            ("frame", f, task.rows, task.reference, target is not None, velocity is not None)
        )
        data.append(
            (
                None if target is None else target[i],
                None if velocity is None else velocity[i],
                gain,
                weight[i],
            )
        )
    inputs = {
        f"{where}.target": target,
        f"{where}.velocity": velocity,
        f"{where}.weight": weight,
        f"{where}.gain": gain,
    }
    return specs, data, inputs


def _check_posture(robot, task, dtype, fn, where):
    target = check_q(robot, task.target, what=f"{where}.target", fn=fn).astype(dtype)
    gain = _gain(task.gain, f"{where}.gain", fn, dtype)
    weight = _weights(task.weight, robot.nv, 1, f"{where}.weight", fn, dtype)[0]
    inputs = {f"{where}.target": target, f"{where}.weight": weight, f"{where}.gain": gain}
    return [("posture",)], [(target, gain, weight)], inputs


def _check_com(robot, task, dtype, fn, where):
    check_inertia(robot, fn)
    axes = task.axes
    if (
        not isinstance(axes, str)
        or not axes
        or "".join(sorted(set(axes))) != axes
        or not set(axes) <= set("xyz")
    ):
        raise JaxkinError(
            f"{fn}: {where}.axes must be distinct letters of 'xyz' in that order (e.g. 'xyz', "
            f"'xy', 'z'), got {axes!r}."
        )
    m = len(axes)
    target = velocity = None
    if task.target is not None:
        target = _array(task.target, f"{where}.target", fn, (3,), dtype, "a point, world")
    if task.velocity is not None:
        what = f"the centre of mass' velocity along {axes!r}, world axes"
        velocity = _array(task.velocity, f"{where}.velocity", fn, (m,), dtype, what)
    gain = _gain(task.gain, f"{where}.gain", fn, dtype)
    weight = _weights(task.weight, m, 1, f"{where}.weight", fn, dtype)[0]
    inputs = {
        f"{where}.target": target,
        f"{where}.velocity": velocity,
        f"{where}.weight": weight,
        f"{where}.gain": gain,
    }
    spec = ("com", axes, target is not None, velocity is not None)
    return [spec], [(target, velocity, gain, weight)], inputs


TASK_TYPES = (FrameTask, ComTask, PostureTask)


def _check_tasks(robot, tasks, dtype, fn):
    """``(levels, data, inputs)``: the static structure, the arrays, the named inputs."""
    if isinstance(tasks, TASK_TYPES):
        tasks = [tasks]
    if not isinstance(tasks, Sequence) or isinstance(tasks, str) or len(tasks) == 0:
        raise JaxkinError(
            f"{fn}: tasks must be a non-empty list of tasks in priority order (a tuple inside it "
            "is one level), e.g. [jk.FrameTask('tool0', velocity=v), jk.PostureTask(q_ref)], "
            f"got {tasks!r:.80}."
        )
    levels, data, inputs = [], [], {}
    for i, level in enumerate(tasks):
        members = list(level) if isinstance(level, (list, tuple)) else [level]
        if not members:
            raise JaxkinError(f"{fn}: tasks[{i}] is an empty level; give at least one task.")
        lspec, ldata = [], []
        for j, task in enumerate(members):
            where = f"tasks[{i}]" if not isinstance(level, (list, tuple)) else f"tasks[{i}][{j}]"
            if isinstance(task, FrameTask):
                s, d, named = _check_frame_task(robot, task, dtype, fn, where)
            elif isinstance(task, PostureTask):
                s, d, named = _check_posture(robot, task, dtype, fn, where)
            elif isinstance(task, ComTask):
                s, d, named = _check_com(robot, task, dtype, fn, where)
            else:
                raise JaxkinError(
                    f"{fn}: {where} must be a task (jk.FrameTask, jk.ComTask, jk.PostureTask), got "
                    f"{type(task).__name__}."
                )
            lspec += s
            ldata += d
            inputs.update(named)
        levels.append(tuple(lspec))
        data.append(tuple(ldata))
    return tuple(levels), tuple(data), inputs


def _check_dt(dt, fn):
    dt = check_scalar(dt, "dt", fn, "the control period in seconds")
    if not is_traced(dt) and not float(dt) > 0:
        raise JaxkinError(f"{fn}: dt must be a positive number of seconds, got {float(dt)}.")
    return dt


def _check_damping(damping, fn, dtype):
    lam = check_scalar(damping, "damping", fn, "lambda >= 0, in the units of J's singular values")
    if not is_traced(lam) and not float(lam) >= 0:
        raise JaxkinError(f"{fn}: damping must be >= 0, got {float(lam)}.")
    return jnp.asarray(lam, dtype=dtype)


def _check_velocity_limits(robot, limits, fn, dtype):
    """``(lo, hi)`` (nv,) from None (no limit), one number or (nv,) (symmetric, >= 0; inf for
    none)."""
    nv = robot.nv
    if limits is None:
        inf = jnp.full(nv, jnp.inf, dtype)
        return -inf, inf
    a = limits if hasattr(limits, "shape") else np.asarray(limits, dtype=float)
    if tuple(a.shape) not in ((), (nv,)):
        raise ShapeError(
            f"{fn}: velocity_limits must be one number or have shape ({nv},) (one bound |qd_i| "
            f"<= limit per velocity entry {list(robot.velocity_names)}), got {tuple(a.shape)}."
        )
    if not is_traced(a):
        v = np.asarray(a, dtype=float)
        if np.any(np.isnan(v)) or not np.all(v >= 0):
            raise JaxkinError(
                f"{fn}: velocity_limits must be >= 0 (inf for no limit), got {v.tolist()}."
            )
    hi = jnp.broadcast_to(jnp.asarray(a, dtype=dtype), (nv,))
    return -hi, hi


# ----------------------------------------------------------------------------- public
def solve_tasks(
    robot: Robot,
    q: Any,
    tasks: Any,
    *,
    dt: Any,
    velocity_limits: Any = None,
    position_limits: bool = True,
    damping: Any = 1e-2,
) -> TaskSolution:
    """Joint velocity (nv,) for prioritised tasks with hard limits (module doc: the recursive
    null-space scheme, damped, with saturation in the null space).

    Args:
      robot: any robot (free, ball and planar joints included: ``qd`` has ``robot.nv`` entries;
        step with ``jk.integrate(robot, q, qd, dt)``).
      q: configuration (nq,).
      tasks: a list in priority order (first = highest); each entry a task
        (:class:`FrameTask`, :class:`ComTask`, :class:`PostureTask`) or a tuple of tasks
        sharing one level.
      dt: the step in seconds: position limits apply to ``q + qd dt``, and targets' errors are
        divided by it.
      velocity_limits: None, one number or (nv,): ``|qd_i| <= limit_i`` (inf for none).
      position_limits: keep revolute and prismatic joints within ``robot.lower``/``upper``.
      damping: lambda >= 0 (module doc; default 0.01): singular values of each level below
        ``2 lambda`` are damped, so ``|qd|`` stays bounded at singularities.

    Returns a :class:`TaskSolution` ``(qd, scale)``. Non-finite input: module doc.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("ur5")
    >>> q = jnp.array([0.3, -1.2, 1.4, -1.6, -1.5, 0.2])
    >>> v = jnp.array([0.05, 0.0, -0.02])  # tool origin: 5 cm/s along x, 2 cm/s down
    >>> sol = jk.solve_tasks(robot, q, [jk.FrameTask("link6", velocity=v, rows="position"),
    ...                                 jk.PostureTask(q, gain=0.0)], dt=0.01,
    ...                      velocity_limits=1.0)
    >>> J = jk.geometric_jacobian(robot, q, frame="link6")
    >>> bool(jnp.allclose(J[:3] @ sol.qd, v)), sol.scale.tolist()
    (True, [1.0, 1.0])
    """
    fn = "jk.solve_tasks"
    check_robot(robot, fn)
    hint = f"jax.vmap(lambda q: {fn}(robot, q, tasks, dt=dt))(qs)"
    q = check_q(robot, q, fn=fn, batch_hint=hint)
    dtype = result_dtype(robot, q)
    levels, data, inputs = _check_tasks(robot, tasks, dtype, fn)
    dt = _check_dt(dt, fn)
    lam = _check_damping(damping, fn, dtype)
    vlo, vhi = _check_velocity_limits(robot, velocity_limits, fn, dtype)
    if not isinstance(position_limits, bool):
        raise JaxkinError(f"{fn}: position_limits must be True or False, got {position_limits!r}.")
    guard = finite_guard(fn, q=q, dt=dt, damping=lam, **inputs)
    q = guard.clean(q.astype(dtype))
    data = jax.tree_util.tree_map(guard.clean, data)
    out = _solve(
        robot,
        q,
        data,
        jnp.asarray(dt, dtype),
        vlo,
        vhi,
        lam,
        levels=levels,
        position_limits=position_limits,
    )
    return guard(out)


def follow_paths(
    robot: Robot,
    q0: Any,
    targets: Any,
    frames: Any,
    dt: float,
    *,
    rows: Any = "all",
    gain: Any = 1.0,
    weight: Any = 1.0,
    twists: Any = None,
    posture: Any = None,
    posture_gain: Any = 0.1,
    velocity_limits: Any = None,
    position_limits: bool = True,
    damping: Any = 1e-2,
) -> FollowResult:
    """Closed-loop resolved-rate control (CLIK) of several frames along paths of poses, jitted
    ``lax.scan``; returns the joint trajectory and the tracking errors.

    At step t, with the robot at ``q_t``: the frames' tasks (one level, world_aligned rows) ask
    for ``V_t + gain * e_t / dt``, ``e_t`` the pose error of each frame against
    ``targets[t]`` (:func:`jaxkin.pose_error`) and ``V_t`` the feed-forward twist
    (default ``pose_error(targets[t], targets[t + 1]) / dt``, 0 at the end); with ``posture``
    a second level pulls toward that configuration; :func:`solve_tasks` gives ``qd_t`` within
    the limits, and ``q_{t+1} = integrate(robot, q_t, qd_t, dt)`` (on the manifold: floating
    bases and ball joints work; revolute and prismatic entries clipped to their limits to
    remove rounding). Feeding the error back keeps drift from accumulating: with ``gain = 1``
    each step aims at the next target.

    Args:
      robot, q0: the robot and its start configuration (nq,).
      targets: (N, k, 4, 4) poses ``T_world_frame`` of the k frames at times ``0, dt, ...``
        ((N, 4, 4) when ``frames`` is one frame).
      frames: a frame name or index, or a list of k of them.
      dt: the control period in seconds.
      rows: ``"all"``, ``"position"`` or ``"orientation"`` (for every frame, or a list, one
        per frame): which rows of each frame are tracked.
      gain: in [0, 1], the fraction of the pose error removed per step.
      weight: per-frame weights within the level: one number, (k,) or (k, 6) (rows are
        selected from the six).
      twists: optional (N, k, 6) feed-forward twists (world_aligned; (N, 6) for one frame).
      posture: optional reference configuration (nq,) for a second level (e.g. ``q0``).
      posture_gain: its gain in [0, 1].
      velocity_limits, position_limits, damping: as :func:`solve_tasks`.

    Returns a :class:`FollowResult`. Non-finite input: module doc.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("ur5")
    >>> q0 = jnp.array([0.3, -1.2, 1.4, -1.6, -1.5, 0.2])
    >>> T0 = jk.fk(robot, q0, frame="link6")
    >>> path = jnp.stack([T0.at[2, 3].add(0.001 * t) for t in range(50)])  # 5 cm up in 0.5 s
    >>> out = jk.follow_paths(robot, q0, path, "link6", 0.01, velocity_limits=2.0)
    >>> out.q.shape, bool(out.max_position_error < 1e-4)
    ((51, 6), True)
    """
    fn = "jk.follow_paths"
    check_robot(robot, fn)
    q0 = check_q(
        robot,
        q0,
        what="q0",
        fn=fn,
        batch_hint=(
            f"jax.vmap(lambda q0: {fn}(robot, q0, targets, frames, dt))(q0s), one run per start"
        ),
    )
    dtype = result_dtype(robot, q0)
    many = check_frames(robot, frames, fn)
    fidx = many if many is not None else (robot.frame_index(frames),)
    k = len(fidx)
    Ts = targets if hasattr(targets, "shape") else np.asarray(targets, dtype=float)
    shape = tuple(Ts.shape)
    want = (
        "(N, k, 4, 4) (N targets for each of the k frames)"
        if many is not None
        else ("(N, 4, 4) (N targets of the frame)")
    )
    if (
        (many is not None and (len(shape) != 4 or shape[1:] != (k, 4, 4)))
        or (many is None and (len(shape) != 3 or shape[1:] != (4, 4)))
        or shape[0] < 1
    ):
        raise ShapeError(f"{fn}: targets must have shape {want} with N >= 1, got {shape}.")
    Ts = jnp.asarray(Ts, dtype=dtype).reshape(shape[0], k, 4, 4)
    row_list = [rows] * k if isinstance(rows, str) else list(rows)
    if len(row_list) != k or any(r not in ROWS for r in row_list):
        raise JaxkinError(
            f"{fn}: rows must be one of {tuple(ROWS)} or a list of {k} of them (one per frame), "
            f"got {rows!r}."
        )
    dt_a = _check_dt(dt, fn)
    g = _gain(gain, "gain", fn, dtype)
    w6 = _frame_weights(weight, k, fn, dtype)
    weights = tuple(w6[i][ROWS[r]] for i, r in enumerate(row_list))
    if twists is None:
        Vs = None
    else:
        lead = (Ts.shape[0], k) if many is not None else (Ts.shape[0],)
        what = "one feed-forward twist [v; omega] per target and frame"
        Vs = _array(twists, "twists", fn, (*lead, 6), dtype, what).reshape(Ts.shape[0], k, 6)
    level0 = tuple(
        ("frame", f, r, "world_aligned", True, True) for f, r in zip(fidx, row_list, strict=True)
    )
    levels = (level0,)
    post = (None, None, None)
    if posture is not None:
        target = check_q(robot, posture, what="posture", fn=fn).astype(dtype)
        post = (target, _gain(posture_gain, "posture_gain", fn, dtype), jnp.ones(robot.nv, dtype))
        levels = (level0, (("posture",),))
    lam = _check_damping(damping, fn, dtype)
    vlo, vhi = _check_velocity_limits(robot, velocity_limits, fn, dtype)
    if not isinstance(position_limits, bool):
        raise JaxkinError(f"{fn}: position_limits must be True or False, got {position_limits!r}.")
    _check_rigid(Ts, "targets", fn)
    guard = finite_guard(
        fn,
        q0=q0,
        targets=Ts,
        twists=Vs,
        dt=dt,
        gain=g,
        weight=w6,
        posture=post[0],
        posture_gain=post[1],
        damping=lam,
    )
    Ts = guard.clean(Ts)
    dt_a = jnp.asarray(dt_a, dtype)
    Vs = None if Vs is None else guard.clean(Vs)  # None: from the targets, in the loop
    out = _follow(
        robot,
        guard.clean(q0.astype(dtype)),
        Ts,
        Vs,
        (g,) * k,
        weights,
        dt_a,
        vlo,
        vhi,
        lam,
        post,
        levels=levels,
        position_limits=position_limits,
    )
    return guard(out)
