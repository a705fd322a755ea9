"""Motion sequences: whole-body targets tracked step by step (retargeting).

A motion is a sequence of targets, one per time step ``t``: poses ``T_t`` (k, 4, 4) of k frames
(``T_world_frame``: feet, hands, head...) and optionally a centre of mass ``c_t`` (3,). The
configuration of step ``t`` is found from the previous step's, ``q_{t-1}`` (the warm start), by
a few damped Gauss-Newton (Levenberg-Marquardt) iterations on the weighted residual
``e(q) = w * [p_i* - p_i; log(R_i* R_i^T) ...; c* - c]`` (the residual of ``jk.solve_ik``'s
whole-body targets), each iteration

    dv = dv0 + J^T (J J^T + lambda I)^-1 (e - J dv0),   q <- integrate(q, dv)

(on the configuration manifold: quaternions stay unit), i.e. ``argmin |J dv - e|^2 + lambda
|dv - dv0|^2``, with the pull ``dv0 = min(1, |e|) * (s * difference(q, q_{t-1}) + p *
difference(q, q_ref))``: toward the previous configuration (smoothness ``s``) and, with
``posture=q_ref``, toward a reference posture (``p``: ``posture_weight``), where the targets
leave freedom (their null space). The pull fades with the residual, so a reachable target is
still met to ``tol`` (the pull does not bias the answer). Started at ``q_{t-1}``, the
minimum-norm steps already keep each step next to the previous one (no jumps between the
redundant solutions of consecutive steps); the smoothness pull corrects what a nonlinear
iteration adds. Over a long sequence a redundant robot still drifts through its null space (the
tracked frames do not say where the elbows or the waist go), into its joint limits, where steps
converge slowly or stall: the posture pull holds that drift. On 8,000 steps of a four-frame G1
motion (``bench/motion.py``) 99.3% of the steps converged without it, even with 30 iterations
(largest residual 0.14 m), and all of them with ``posture=`` the first configuration and
``posture_weight=0.1`` (20 iterations, 3.2 per step on average).

A step whose residual grows is rejected and ``lambda`` raised tenfold (lowered tenfold after a
step that is taken); the iterations of one step stop at ``tol`` or after ``iterations``.
``lambda`` starts at ``damping`` at every step. Joints stay within their limits: joints at a
limit that the gradient pushes further are held, and a joint that a step would take past its
limit is set on it while the other joints are solved again (they make up for it in the same
step).

Each step reports its residual ``|e|`` (the frames' rows recomputed with the exact rotation
logarithm and an independent forward pass, as ``jk.solve_ik`` does; the centre of mass is the
one the iterations computed at the returned configuration, the same function of it, not
computed twice), per-frame position and orientation errors,
the iterations used, ``converged`` and a :class:`jaxkin.ik.RESULTS` code. A target with a NaN or
inf entry is flagged, never passed off as a number: that step keeps ``q_{t-1}``, its residual is
NaN and its code ``nonfinite``; the sequence goes on from ``q_{t-1}``. Targets are not checked
for rigidity up front (a sequence can be far larger than memory): a step whose target is no
rigid transform does not converge and says so.

:func:`retarget` runs the whole sequence, streamed through :func:`jaxkin.batch.chunked_scan`:
``chunk_size`` steps per compiled ``lax.scan``, the last configuration carried across chunks,
the per-step results written to numpy arrays or to disk (an npz, CSV or a directory of ``.npy``
files, chunk by chunk) with a progress bar; memory is bounded by the chunk, whatever the
sequence's length (inputs may be ``np.memmap`` arrays). :func:`track_step` is one step (jitted,
the kernel :func:`retarget` scans, traced once for both): ``retarget`` equals calling it in a
loop. The scan is compiled once per robot (value), frames, centre-of-mass target or not,
``iterations``, chunk length and dtype, and kept (``chunked_scan``'s cache): the targets,
``q0``, weights, tolerances, damping, smoothness and posture are its arguments, so a later
call that changes only those compiles nothing.
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import spatial
from ._checks import check_frames, check_inertia, check_q, check_robot, refuse_nonfinite
from ._forward import frame_poses
from ._jacobian_pass import jacobians_pass
from ._jit import robot_jit
from .batch import chunked_scan
from .com import com_and_jacobian
from .configuration import difference, integrate_kernel
from .errors import JaxkinError, ShapeError
from .ik import RESULTS
from .model import Robot
from .pose_errors import pose_error, pose_residual
from .spatial import safe_norm

__all__ = [
    "DEFAULT_DAMPING",
    "DEFAULT_ITERATIONS",
    "DEFAULT_POSTURE_WEIGHT",
    "DEFAULT_SMOOTHNESS",
    "MotionResult",
    "retarget",
    "track_step",
]

DEFAULT_ITERATIONS = 20
"""Most damped Gauss-Newton iterations per time step (fewer when ``tol`` is reached: 3 to 4 on a
smooth motion; steps against joint limits take more)."""

DEFAULT_DAMPING = 1e-4
"""``lambda`` at the start of every step (m^2; adapted tenfold per iteration)."""

DEFAULT_SMOOTHNESS = 0.5
"""Fraction of the gap to ``q_{t-1}`` closed per iteration in the targets' null space."""

DEFAULT_POSTURE_WEIGHT = 0.1
"""``posture_weight`` when ``posture=`` is given without one."""

LAMBDA_MIN, LAMBDA_MAX = 1e-12, 1e12
"""Bounds of the adapted ``lambda``; a step rejected at ``LAMBDA_MAX`` has ``stalled``."""

MOTION_CHUNK_SIZE = 4096
"""Time steps per compiled chunk of :func:`retarget` (memory: a few kB per step)."""


class MotionResult(NamedTuple):
    """Per-step results of :func:`retarget` (leading axis T, the time steps) or of
    :func:`track_step` (no leading axis).

    ``q`` (nq,): the step's configuration (the previous one for a non-finite target);
    ``converged`` bool: ``residual <= tol``; ``residual``: ``|w * e|`` at ``q`` (NaN for a
    non-finite target), ``e`` the residual of the module doc with the exact rotation
    logarithm; ``iterations`` int32; ``result`` int32: a :class:`jaxkin.ik.RESULTS` code
    (``converged``, ``max_steps_reached``: the iterations ran out while the residual was
    still decreasing, ``stalled``: no step decreased it, ``nonfinite``); ``position_error`` (k,)
    (m) and ``orientation_error`` (k,) (rad) per frame, and ``com_error`` (m; None without a
    centre-of-mass target), over the rows with a weight > 0 (an orientation-free frame has
    ``orientation_error`` 0).
    """

    q: jax.Array
    converged: jax.Array
    residual: jax.Array
    iterations: jax.Array
    result: jax.Array
    position_error: jax.Array
    orientation_error: jax.Array
    com_error: Any = None


class _Spec(NamedTuple):
    """What a step solves (static, hashable): frame indices, whether a centre of mass is
    targeted, and the iteration budget."""

    frames: tuple[int, ...]
    com: bool
    iterations: int


class _Params(NamedTuple):
    """Array settings of a step: row weights ``w`` (6 k [+ 3],), ``tol``, ``damping``,
    ``smoothness``."""

    w: jax.Array
    tol: jax.Array
    damping: jax.Array
    smoothness: jax.Array
    q_ref: Any = None
    posture_weight: Any = None


# ----------------------------------------------------------------------------- kernel
def _residual(robot: Robot, spec: _Spec, q, T, com, w):
    """Weighted residual ``e`` (rows,), Jacobian ``J`` (rows, nv) and the centre of mass ``c``
    (3,) at ``q`` (zeros without a centre-of-mass target), one forward pass each for the
    frames and for the centre of mass."""
    g = jacobians_pass(robot, q, spec.frames)
    Ts, Js = g.pose(), g.matrix()
    es = [pose_residual(Ts[i], T[i]) for i in range(len(spec.frames))]
    Jr = [Js.reshape(-1, robot.nv)]
    c = jnp.zeros(3, Js.dtype)
    if spec.com:
        c, Jc = com_and_jacobian(robot, q)
        es.append(com - c)
        Jr.append(Jc)
    return jnp.concatenate(es) * w, jnp.concatenate(Jr, axis=0) * w[:, None], c


def _scalar_entries(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """(nv,) ``q`` index of each velocity entry and whether it belongs to a revolute or
    prismatic joint (the joints with box limits)."""
    ix = np.zeros(robot.nv, dtype=np.int64)
    scalar = np.zeros(robot.nv, dtype=bool)
    for kind, qi, vi in zip(robot.kinds, robot.q_index, robot.v_index, strict=True):
        if qi >= 0 and kind in ("revolute", "prismatic"):
            ix[vi], scalar[vi] = qi, True
    return ix, scalar


def _solve(J, e, lam, free, dv0, dv_fixed):
    """``argmin |J dv - e|^2 + lam |dv - dv0|^2`` over the free entries of ``dv``, the others
    set to ``dv_fixed``: ``dv0 + J_f^T (J_f J_f^T + lam I)^-1 (r - J_f dv0)`` with ``J_f`` the
    free columns and ``r = e - J dv_fixed`` (fixed entries), through the smaller normal
    equations."""
    m, n = J.shape
    dv_fixed = jnp.where(free, 0.0, dv_fixed)
    Jf = jnp.where(free[None, :], J, 0.0)
    dv0 = jnp.where(free, dv0, 0.0)
    r = e - J @ dv_fixed - Jf @ dv0
    if m <= n:
        A = Jf @ Jf.T + lam * jnp.eye(m, dtype=J.dtype)
        dv = Jf.T @ jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(A), True), r)
    else:
        A = Jf.T @ Jf + lam * jnp.eye(n, dtype=J.dtype)
        dv = jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(A), True), Jf.T @ r)
    return dv_fixed + jnp.where(free, dv0 + dv, 0.0)


def _limited_step(J, e, lam, q, dv0, ix, scalar, vlo, vhi):
    """The step within the joint limits: joints at a limit that the gradient pushes further
    are held; then joints that the step would take past a limit are set to reach it exactly and
    the others solved again (one active-set refinement), so that they make up for the clipped
    ones in the same step."""
    qv = q[ix]
    g = J.T @ e
    held = ((qv <= vlo) & (g < 0)) | ((qv >= vhi) & (g > 0))
    zero = jnp.zeros_like(dv0)
    dv = _solve(J, e, lam, ~held, dv0, zero)
    reach = qv + dv
    over = scalar & ~held & ((reach < vlo) | (reach > vhi))
    to_limit = jnp.where(over, jnp.clip(reach, vlo, vhi) - qv, 0.0)
    return _solve(J, e, lam, ~held & ~over, dv0, to_limit)


def _step_impl(robot: Robot, q_prev, T, com, params: _Params, *, spec: _Spec) -> MotionResult:
    """One time step from ``q_prev`` (module doc); jitted as :func:`track_step`'s kernel."""
    dtype = q_prev.dtype
    T = T.astype(dtype)
    com = jnp.zeros(3, dtype) if com is None else com.astype(dtype)
    bad = ~jnp.all(jnp.isfinite(T)) | ~jnp.all(jnp.isfinite(com))
    T = jnp.where(bad, jnp.broadcast_to(jnp.eye(4, dtype=dtype), T.shape), T)  # skipped anyway
    com = jnp.where(bad, 0.0, com)
    w, tol2 = params.w.astype(dtype), params.tol.astype(dtype) ** 2
    lo, hi = robot.lower.astype(dtype), robot.upper.astype(dtype)
    ix, scalar = _scalar_entries(robot)
    vlo = jnp.where(scalar, lo[ix], -jnp.inf)
    vhi = jnp.where(scalar, hi[ix], jnp.inf)

    def evaluate(q):
        e, J, c = _residual(robot, spec, q, T, com, w)
        return e, J, jnp.sum(e * e), c

    def cond(s):
        err, it, stuck = s[3], s[5], s[7]
        return (it <= spec.iterations) & (err > tol2) & ~bad & ~stuck

    def body(s):
        # evaluate the trial (q_prev itself first), keep it if better, and make the next trial:
        # one forward pass per iteration. ``c`` is always the centre of mass at ``q`` (the
        # first trial is ``q`` itself), for the report
        q, e, J, err, lam, it, trial, _, c = s
        et, Jt, errt, ct = evaluate(trial)
        better = errt < err
        pick = lambda a, b: jnp.where(better, a, b)  # noqa: E731
        q, e, J = pick(trial, q), pick(et, e), pick(Jt, J)
        c = jnp.where(better | (it == 0), ct, c)
        stuck = ~better & (lam >= LAMBDA_MAX)
        lam = jnp.where(
            it == 0,
            lam,
            jnp.where(better, jnp.maximum(lam / 10, LAMBDA_MIN), jnp.minimum(lam * 10, LAMBDA_MAX)),
        )
        err = pick(errt, err)
        pull = params.smoothness * difference(robot, q, q_prev)
        if params.q_ref is not None:
            pull = pull + params.posture_weight * difference(robot, q, params.q_ref)
        dv0 = jnp.minimum(1.0, jnp.sqrt(err)) * pull
        dv = _limited_step(J, e, lam, q, dv0, ix, scalar, vlo, vhi)
        trial = jnp.clip(integrate_kernel(robot, q, dv), lo, hi)
        return q, e, J, err, lam, it + 1, trial, stuck, c

    m = 6 * len(spec.frames) + 3 * spec.com
    inf = jnp.asarray(jnp.inf, dtype)
    init = (
        q_prev,
        jnp.zeros(m, dtype),
        jnp.zeros((m, robot.nv), dtype),
        inf,
        params.damping.astype(dtype),
        jnp.int32(0),
        q_prev,
        jnp.zeros((), bool),
        jnp.full(3, jnp.nan, dtype),  # the centre of mass at q: set by the first pass
    )
    q, _, _, _, _, it, _, stuck, c = jax.lax.while_loop(cond, body, init)
    it = jnp.maximum(it - 1, 0)  # the first pass evaluates q_prev
    return _report(robot, spec, q, c, T, com, w, params.tol.astype(dtype), it, stuck, bad)


def _report(robot, spec: _Spec, q, c, T, com, w, tol, it, stuck, bad) -> MotionResult:
    """The step's errors at ``q``: the frames' by an independent forward pass and the exact
    rotation logarithm, the centre of mass' from ``c`` (the iterations' value at ``q``: the
    same function of ``q``, computed once per program); the per-frame and centre-of-mass errors
    count the rows with a weight > 0 only (as ``jk.solve_ik``'s)."""
    k = len(spec.frames)
    R, p = frame_poses(robot, q, spec.frames)
    es = [pose_error(spatial.make_transform(R[i], p[i]), T[i]) for i in range(k)]
    if spec.com:
        es.append(com - c)
    e = jnp.concatenate(es)
    on = jnp.where(w != 0, e, 0.0)  # the errors of the rows asked for (weight > 0)
    ef = on[: 6 * k].reshape(k, 6)
    com_error = safe_norm(on[6 * k :]) if spec.com else None
    residual = safe_norm(w * e)
    nan = jnp.asarray(jnp.nan, q.dtype)
    residual = jnp.where(bad, nan, residual)
    converged = ~bad & (residual <= tol)
    code = jnp.where(
        converged,
        RESULTS.converged,
        jnp.where(
            bad | ~jnp.isfinite(residual),
            RESULTS.nonfinite,
            jnp.where(stuck, RESULTS.stalled, RESULTS.max_steps_reached),
        ),
    ).astype(jnp.int32)
    return MotionResult(
        q=q,
        converged=converged,
        residual=residual,
        iterations=it.astype(jnp.int32),
        result=code,
        position_error=jnp.where(bad, nan, jax.vmap(safe_norm)(ef[:, :3])),
        orientation_error=jnp.where(bad, nan, jax.vmap(safe_norm)(ef[:, 3:])),
        com_error=None if com_error is None else jnp.where(bad, nan, com_error),
    )


_step = robot_jit(_step_impl, ("spec",))


# ----------------------------------------------------------------------------- checks
def _check_frame(robot: Robot, frame: Any, fn: str) -> tuple[tuple[int, ...], bool]:
    """``(frame indices, several)``: a list of frames, or one frame (no k axis)."""
    frames = check_frames(robot, frame, fn)
    if frames is not None:
        return frames, True
    return (robot.frame_index(frame),), False


def _float(x: Any, what: str, fn: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise JaxkinError(f"{fn}: {what} must be a number, got {x!r}.") from None
    if not np.isfinite(v):
        raise JaxkinError(f"{fn}: {what} must be finite, got {x!r}.")
    return v


def _params(
    robot, spec, weights, com_weight, tol, damping, smoothness, posture, posture_weight, fn
) -> _Params:
    """Checked settings (weights >= 0 of shape (6,) or (k, 6); tol, damping > 0; smoothness and
    posture_weight in [0, 1]; posture a configuration (nq,))."""
    dtype = np.dtype(robot.dtype)
    k = len(spec.frames)
    w = np.ones(6) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape not in ((6,), (k, 6)):
        raise ShapeError(
            f"{fn}: weights must have shape (6,) or ({k}, 6) ([v; omega] per frame), got {w.shape}."
        )
    w = np.broadcast_to(w, (k, 6)).reshape(-1)
    if spec.com:
        w = np.concatenate([w, np.broadcast_to(np.asarray(com_weight, np.float64), (3,))])
    refuse_nonfinite(w, "weights", fn)
    if np.any(w < 0):
        raise JaxkinError(f"{fn}: weights must be >= 0 (0 turns a row off), got {w.tolist()}.")
    tol = (1e-10 if dtype == np.float64 else 1e-5) if tol is None else _float(tol, "tol", fn)
    damping = _float(damping, "damping", fn)
    smoothness = _float(smoothness, "smoothness", fn)
    if not tol > 0 or not damping > 0:
        raise JaxkinError(f"{fn}: tol and damping must be > 0, got {tol!r} and {damping!r}.")
    if not 0 <= smoothness <= 1:
        raise JaxkinError(f"{fn}: smoothness must lie in [0, 1], got {smoothness!r}.")
    params = _Params(*(_on_device(x, dtype) for x in (w, tol, damping, smoothness)))
    if posture is None:
        return params
    q_ref = _on_device(check_q(robot, posture, what="posture", fn=fn, host=True), dtype)
    pw = (
        DEFAULT_POSTURE_WEIGHT
        if posture_weight is None
        else _float(posture_weight, "posture_weight", fn)
    )
    if not 0 <= pw <= 1:
        raise JaxkinError(f"{fn}: posture_weight must lie in [0, 1], got {posture_weight!r}.")
    return params._replace(q_ref=q_ref, posture_weight=_on_device(pw, dtype))


def _on_device(x: Any, dtype) -> jax.Array:
    """``x`` as a JAX array of ``dtype``: host data put on the device (``jnp.asarray`` of host
    data compiles a ``stage`` operation once per shape and dtype), a JAX array (or a tracer)
    converted by JAX."""
    if isinstance(x, jax.Array):
        return jnp.asarray(x, dtype)
    return jax.device_put(np.asarray(x, dtype))


def _check_iterations(iterations: Any, fn: str) -> int:
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)):
        raise JaxkinError(f"{fn}: iterations must be an integer >= 1, got {iterations!r}.")
    if iterations < 1:
        raise JaxkinError(f"{fn}: iterations must be >= 1, got {iterations}.")
    return int(iterations)


def _spec(robot, frame, com, iterations, fn) -> tuple[_Spec, bool]:
    frames, several = _check_frame(robot, frame, fn)
    if com is not None:
        check_inertia(robot, fn)
    return _Spec(frames, com is not None, _check_iterations(iterations, fn)), several


# ----------------------------------------------------------------------------- public
def track_step(
    robot: Robot,
    q_prev: Any,
    T_target: Any,
    frame: Any = None,
    *,
    com: Any = None,
    weights: Any = None,
    com_weight: Any = 1.0,
    smoothness: float = DEFAULT_SMOOTHNESS,
    posture: Any = None,
    posture_weight: float | None = None,
    iterations: int = DEFAULT_ITERATIONS,
    damping: float = DEFAULT_DAMPING,
    tol: float | None = None,
) -> MotionResult:
    """One time step of a motion (module doc): the configuration near ``q_prev`` (nq,) that puts
    the frames on ``T_target`` ((k, 4, 4) for ``frame=[f1, ..., fk]``, (4, 4) for one frame) and
    the centre of mass on ``com`` (3,), if given. Jitted (one compile per robot and option set);
    :func:`retarget` scans this kernel. Arguments as for :func:`retarget`; a non-finite target
    gives a ``nonfinite`` result (no exception)."""
    fn = "jk.motion.track_step"
    check_robot(robot, fn)
    spec, several = _spec(robot, frame, com, iterations, fn)
    params = _params(
        robot, spec, weights, com_weight, tol, damping, smoothness, posture, posture_weight, fn
    )
    dtype = np.dtype(robot.dtype)
    q_prev = check_q(robot, q_prev, what="q_prev", fn=fn)
    k = len(spec.frames)
    T = jnp.asarray(T_target, dtype)
    if T.shape != ((k, 4, 4) if several else (4, 4)):
        want = f"({k}, 4, 4)" if several else "(4, 4)"
        raise ShapeError(f"{fn}: T_target must have shape {want}, got {tuple(T.shape)}.")
    c = None if com is None else jnp.asarray(com, dtype)
    if c is not None and c.shape != (3,):
        raise ShapeError(f"{fn}: com must have shape (3,), got {tuple(c.shape)}.")
    r = _step(robot, jnp.asarray(q_prev, dtype), T.reshape(k, 4, 4), c, params, spec=spec)
    return r if several else _one_frame(r)


@dataclasses.dataclass(frozen=True)
class _ScanStep:
    """:func:`retarget`'s row of :func:`jaxkin.batch.chunked_scan`: ``(q, params), T[, c] ->
    ((q', params), result)``, :func:`track_step`'s kernel (one trace for both). The settings
    ride in the carry, unchanged, so that the step is a value (robot, spec, one frame or
    several) and ``chunked_scan`` keeps one compiled scan per value, shapes and dtypes: a
    later call with other targets, weights or tolerances compiles nothing."""

    robot: Robot
    spec: _Spec
    several: bool

    def __call__(self, carry, T, c=None):
        q, params = carry
        r = _step(self.robot, q, T.reshape(len(self.spec.frames), 4, 4), c, params, spec=self.spec)
        return (r.q, params), (r if self.several else _one_frame(r))


def _one_frame(r: MotionResult) -> MotionResult:
    """Drop the frame axis of the per-frame errors (one frame asked as a name or index)."""
    return r._replace(
        position_error=r.position_error[..., 0], orientation_error=r.orientation_error[..., 0]
    )


def retarget(
    robot: Robot,
    T_targets: Any,
    q0: Any,
    frame: Any = None,
    *,
    com: Any = None,
    weights: Any = None,
    com_weight: Any = 1.0,
    smoothness: float = DEFAULT_SMOOTHNESS,
    posture: Any = None,
    posture_weight: float | None = None,
    iterations: int = DEFAULT_ITERATIONS,
    damping: float = DEFAULT_DAMPING,
    tol: float | None = None,
    chunk_size: int = MOTION_CHUNK_SIZE,
    progress: Any = False,
    out: Any = None,
    return_stats: bool = False,
) -> Any:
    """Track a sequence of whole-body targets, each step warm-started from the previous one
    (module doc), in bounded memory.

    Args:
      robot: any robot jaxkin loads (floating bases, ball joints).
      T_targets: (T, k, 4, 4) poses ``T_world_frame`` of the k frames at each of T steps
        (``frame=[f1, ..., fk]``), or (T, 4, 4) for one frame: an array or a row source read
        chunk by chunk (``np.memmap``, an h5py dataset: see :func:`jaxkin.batch.chunked_map`).
      q0: (nq,) configuration before the first step (e.g. ``jk.solve_ik``'s solution of the
        first target, or ``jk.neutral(robot)``).
      frame: the frames (names or indices), a list; or one frame (default: the robot's).
      com: None, or (T, 3) centre-of-mass targets (world coordinates); needs masses.
      weights: (6,) or (k, 6) row weights ``[v; omega]`` per frame (0 turns a row off:
        position-only or orientation-only targets); com_weight: the centre of mass' weight.
      smoothness: in [0, 1], the pull toward the previous configuration (module doc); 0: none
        (the warm start and the minimum-norm steps only).
      posture: None, or a reference configuration (nq,) pulled toward in the targets' null
        space (module doc), e.g. ``q0``: recommended for long sequences of a redundant robot;
        posture_weight: its weight in [0, 1] (default :data:`DEFAULT_POSTURE_WEIGHT`).
      iterations: most iterations per step; damping: ``lambda`` at the start of each step.
      tol: residual threshold of ``converged``; default 1e-10 in float64, 1e-5 in float32.
      chunk_size: steps per compiled chunk.
      progress: True for a progress bar (tqdm), or a bar (see :func:`jaxkin.batch.chunked_map`).
      out: None (numpy arrays), or where the per-step results go: a path (``.npz``, ``.csv``
        or a directory, written chunk by chunk by a :class:`jaxkin.io.ResultWriter`; fields
        ``q``, ``converged``, ``residual``, ``iterations``, ``result``, ``position_error``,
        ``orientation_error`` and ``com_error`` with ``com=``), a sink, or a pytree of arrays.
      return_stats: also return the :class:`jaxkin.batch.MapStats` (compile and run times).

    Returns:
      A :class:`MotionResult` of numpy arrays with a leading T axis (``out`` itself, or the
      written file's absolute path, when ``out`` is given); with ``return_stats=True`` the pair
      ``(result, stats)``.

    Raises:
      ShapeError: ``T_targets``, ``com`` or ``q0`` of the wrong shape.
      JaxkinError: bad settings.
      ModelError: ``com=`` for a robot without masses.

    Non-finite targets raise no error: their steps are flagged ``nonfinite`` (module doc).

    >>> import numpy as np, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> qs = np.stack([np.linspace(0.2, 0.8, 20), np.linspace(0.5, 1.0, 20)], axis=1)
    >>> T = np.stack([jk.fk(robot, q) for q in qs])  # the tip's path, (20, 4, 4)
    >>> res = jk.retarget(robot, T, qs[0])
    >>> bool(res.converged.all()), bool(np.abs(res.q - qs).max() < 1e-6)
    (True, True)
    >>> res.iterations.tolist()[:5]  # warm-started: the first step is already solved
    [0, 3, 3, 3, 3]
    """
    fn = "jk.motion.retarget"
    check_robot(robot, fn)
    spec, several = _spec(robot, frame, com, iterations, fn)
    params = _params(
        robot, spec, weights, com_weight, tol, damping, smoothness, posture, posture_weight, fn
    )
    dtype = np.dtype(robot.dtype)
    q0 = _on_device(check_q(robot, q0, what="q0", fn=fn, host=True), dtype)
    k = len(spec.frames)
    row = (k, 4, 4) if several else (4, 4)
    shape = tuple(getattr(T_targets, "shape", np.shape(T_targets)))
    if len(shape) != len(row) + 1 or shape[1:] != row:
        want = f"(T, {k}, 4, 4) (one pose per frame and step)" if several else "(T, 4, 4)"
        raise ShapeError(
            f"{fn}: T_targets must have shape {want} for frame={frame!r}, got {shape}."
        )
    inputs = [T_targets]
    if com is not None:
        cshape = tuple(getattr(com, "shape", np.shape(com)))
        if cshape != (shape[0], 3):
            raise ShapeError(f"{fn}: com must have shape ({shape[0]}, 3), got {cshape}.")
        inputs.append(com)

    _, *results = chunked_scan(
        _ScanStep(robot, spec, several),
        (q0, params),
        *inputs,
        chunk_size=chunk_size,
        progress=progress,
        out=out,
        return_stats=return_stats,
    )
    return tuple(results) if return_stats else results[0]
