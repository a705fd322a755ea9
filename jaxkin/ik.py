"""Inverse kinematics: ``jk.solve_ik(robot, T_target, q0)``, jitted, batched, with result codes.

Find ``q`` with ``fk(robot, q, frame) == T_target``. The residual is the pose error

    e(q) = [p_target - p(q); log(R_target R(q)^T)]        (6,), world axes, metres and radians

and ``residual = |e|`` (2-norm); a solve has converged when ``residual <= tol`` (default 1e-10
in float64, 1e-5 in float32), so position and orientation errors are both below ``tol``.

Two solvers, both one jitted ``lax.while_loop`` that stops as soon as the target is reached:

* ``method="lm"`` (default): Levenberg-Marquardt with the geometric Jacobian,
  ``dq = J^T (J J^T + lambda I)^-1 e``, steps accepted only when they reduce ``|e|``, ``lambda``
  divided by 10 after a success and multiplied by 10 after a failure (a trust region: damped far
  from the solution or near singularities, Gauss-Newton near a regular solution, hence quadratic
  convergence). Joint limits: a revolute joint whose range spans a full turn (the UR's +-2 pi)
  is wrapped by 2 pi back into it, never clipped; other joints are clipped, with an active set
  (joints pinned at a limit and pushed outwards drop out of the step); continuous joints
  (infinite limits) are left alone. As in TRAC-IK, a start that stalls (``patience`` steps
  without progress) or spends its ``max_steps`` is abandoned for a random restart, until one
  converges or ``num_seeds`` starts are spent: the default (64 starts of at most 30 steps) costs
  easy targets nothing more. From the mid-limit start, 1,000 random reachable targets each of
  the Panda, UR5, UR10, Kinova and Niryo One: 99.9-100% (one start: 67-87%; a few targets
  needed 30-50 starts). Inside the same loop: only the targets that need restarts pay for
  them, and the last targets' remaining starts run side by side (the answer is still the first
  converging start's, in the order of the starts);
* ``method="optax"``: minimises ``0.5 |e|^2`` with an optax optimiser (default: L-BFGS with a
  backtracking line search; any ``GradientTransformation`` works), projected onto the joint
  limits after every update, from all seeds at once (``vmap``), keeping the best. The loss has
  a zero gradient, not NaN, at an exact solution. It typically stalls around a residual of
  1e-10 (L-BFGS in float64): use it with ``tol=1e-9`` or looser, and LM for tighter tolerances.

Whole body (``frame=[f1, ..., fk]``, ``weights=``, ``com=``, ``posture=``, or a robot with free,
ball or planar joints, e.g. a humanoid loaded with ``floating_base=True``): LM on the stacked,
weighted residual

    e(q) = [w_1 * e_1(q); ...; w_k * e_k(q); w_c * (c_target - c(q))]     (6k [+ 3],)

(``e_i`` the pose error of frame i as above, ``c`` the centre of mass) with the stacked
Jacobian (one forward pass for every frame); ``residual = |e|`` and convergence at
``residual <= tol`` as above, so every weighted row is within ``tol``. The step is a velocity
``v`` (nv,), ``argmin |J v - e|^2 + lambda |v - v_posture|^2`` (the smaller of the two normal
systems, by Cholesky), applied on the manifold by ``jk.integrate`` (quaternions stay unit);
then the joint limits of the joints that have them, as above. On a floating-base robot the
random restarts keep ``q0``'s base and move it rigidly onto the targets (the frames' origins and
axes fitted in least squares, Kabsch), and draw the other joints from the middle of their
ranges outwards: the first restart at mid-range, the whole range from the ninth on
(:data:`RESTART_RAMP`). A random base orientation (a humanoid upside down) would start far from
every target, while placing the base is the easy part of the solve; and a humanoid's or
quadruped's mid-range limbs are a posture LM reaches most targets from, where joints drawn
uniformly within the limits are not. Defaults: ``damping=0.1`` and ``max_steps=60``
(:data:`WHOLE_BODY_DEFAULTS`). From ``jk.neutral(robot)`` with default arguments, random
reachable targets (``jk.fk`` of configurations drawn by ``jk.sample_configurations``: the base
anywhere in [-1, 1]^3 m, any orientation), 500 each, judged by ``jk.fk`` to 1e-6 m and 1e-6 rad
(``python3 -m bench.wholebody_ik``): G1's ankles and hands, Talos's soles and grippers and
Solo12's four feet 100%, in 0.75 / 0.70 / 0.32 ms per target batched. The neutral start
converges for 39% / 28% / 46% of them; of the others the first restart for 70% / 82% / 49%
(23% / 38% / 45% with the earlier rule: joints uniform within the limits, the base placed by
one frame), 100 / 90 / 78 LM steps per target on average (244 / 187 / 82 before).

Outcomes are returned as codes (:class:`RESULTS`), not raised from inside ``jit``; with
``throw=True`` (the default, as in diffrax) :func:`solve_ik` raises :class:`IKError` after the
solve when any target failed, carrying every target's solution (``except jk.IKError as e:
e.solution``: one failed target does not lose the batch); under an outer ``jit``/``vmap`` a
runtime error carrying the same message. ``throw=False`` returns the codes for you to inspect.
"""

from __future__ import annotations

import enum
import functools
import warnings
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import configuration, sampling, spatial
from ._checks import (
    check_frames,
    check_inertia,
    check_poses,
    check_q,
    check_robot,
    is_traced,
    refuse_nonfinite,
)
from ._forward import frame_pose, frame_poses
from ._jacobian_pass import jacobian_pass, jacobians_pass
from ._jit import robot_jit
from ._linalg import polar_rotation, unrolled_cholesky
from ._traces import staged
from .com import com_and_jacobian
from .configuration import integrate_kernel
from .errors import JaxkinError, ShapeError
from .ik_gradients import damped_pinv_apply, full_rank, solution_tangent
from .model import Robot
from .optimizers import default_optimizer
from .placements import joint_placements
from .pose_errors import pose_error, pose_error_norms, pose_residual
from .spatial import quaternion_exp, quaternion_multiply, quaternion_to_matrix, safe_norm

__all__ = ["RESULTS", "IKError", "IKSolution", "reach_bound", "sample_configurations", "solve_ik"]

METHODS = ("lm", "optax")


class RESULTS(enum.IntEnum):
    """Outcome of an inverse-kinematics solve (``IKSolution.result``, int32)."""

    converged = 0
    """``residual <= tol``."""
    max_steps_reached = 1
    """The step budget ran out while the residual was still decreasing."""
    unreachable = 2
    """The target is farther from the base than the robot can reach (proven by the reach bound
    :func:`reach_bound`); no step was taken."""
    stalled = 3
    """Every start stopped making progress above ``tol``: a local minimum, joint limits in the
    way, or a target outside the workspace (an orientation the robot cannot take there). Try
    more starts (``num_seeds``) or check the target."""
    nonfinite = 4
    """The residual became NaN or infinite (non-finite input)."""

    @classmethod
    def message(cls, code: int) -> str:
        return {
            cls.converged: "converged",
            cls.max_steps_reached: "max_steps reached before the residual fell below tol "
            "(raise max_steps or num_seeds)",
            cls.unreachable: "target unreachable: farther from the base than the robot's reach",
            cls.stalled: "stalled above tol from every start (local minimum, joint limits, or "
            "a target outside the workspace); try more starts (num_seeds)",
            cls.nonfinite: "non-finite residual (check T_target and q0 for NaN/inf)",
        }[cls(int(code))]


class IKError(JaxkinError):
    """Raised by :func:`solve_ik` with ``throw=True`` when a target was not reached.

    ``solution``: the whole :class:`IKSolution` of the call (every target's, the reached ones
    included; ``solution.converged`` says which), so that one failed target does not lose the
    batch: ``except jk.IKError as e: sol = e.solution``. None when raised from inside an outer
    ``jit``/``vmap`` (no concrete solution exists there: pass ``throw=False``).
    """

    def __init__(self, message: str, solution: Any = None) -> None:
        super().__init__(message)
        self.solution = solution

    def __reduce__(self):
        return (type(self), (str(self), self.solution))


class IKSolution(NamedTuple):
    """Result of :func:`solve_ik`; for a batch of N targets every field gains a leading N axis.

    ``q`` (dof,): the best configuration found (within the joint limits); ``converged`` bool;
    ``residual``: ``|e(q)|`` (see the module doc); ``steps`` int32: solver iterations over all
    starts; ``result`` int32: a :class:`RESULTS` code; ``position_error`` (m) and
    ``orientation_error`` (rad) of ``q``; ``seed`` int32: index of the start that produced ``q``;
    ``singular`` bool: the Jacobian at ``q`` (joints held at a limit left out) is rank-deficient
    to working precision, where derivatives of ``q`` are damped (:mod:`jaxkin.ik_gradients`).

    Whole-body solves (:func:`solve_ik` with ``frame=[f1, ..., fk]``): ``q`` (nq,) (unit
    quaternions), ``position_error`` and ``orientation_error`` (k,), one per frame, each over
    the rows whose weight is not 0 (0 when all three are off), by ``jk.fk`` at ``q``;
    ``residual`` is the weighted ``|e|`` over every row; ``com_error`` (m) the centre of mass's
    distance to its target (None without ``com=``); ``singular`` counts only the rows whose
    weight is not 0.

    ``q`` is differentiable (``jax.grad``/``jvp`` with respect to the target and the robot's
    parameters, by the implicit function theorem: :mod:`jaxkin.ik_gradients`).
    """

    q: jax.Array
    converged: jax.Array
    residual: jax.Array
    steps: jax.Array
    result: jax.Array
    position_error: jax.Array
    orientation_error: jax.Array
    seed: jax.Array
    singular: jax.Array
    com_error: Any = None


# ----------------------------------------------------------------------------- helpers
def reach_bound(robot: Robot, frame: int | str | None = None) -> jax.Array:
    """An upper bound on ``|p_frame - p_base|`` over all configurations within the limits.

    The sum, along the chain from the base to ``frame``, of each joint's constant offsets
    (``|B_p| + |A_p|``: ``sqrt(a^2 + d^2)`` per DH row, ``|xyz|`` per placement), the largest
    prismatic travel and the tool offset. ``inf`` when a prismatic joint on the chain is
    unbounded, or a free or planar joint (a floating base) is on it. A target farther than this
    is certainly unreachable.
    """
    f = robot.frame_index(frame)
    return _reach_bound(robot, f)


def _reach_bound(robot: Robot, f: int) -> jax.Array:
    dtype = robot.base.dtype
    place = joint_placements(robot)
    total = jnp.zeros((), dtype=dtype)
    lo = robot.lower.astype(dtype)
    hi = robot.upper.astype(dtype)
    for j in robot.ancestors(f):
        if robot.kinds[j] in ("free", "planar"):  # translates without bound
            return jnp.asarray(jnp.inf, dtype=dtype)
        for pl in (place.B, place.A):
            if pl is not None:
                total = total + jnp.linalg.norm(jnp.asarray(pl[1][j], dtype=dtype))
        if robot.kinds[j] == "prismatic":
            qi = robot.q_index[j]
            travel = jnp.maximum(jnp.abs(lo[qi]), jnp.abs(hi[qi]))
            total = total + jnp.abs(robot.multiplier[j]) * travel + jnp.abs(robot.offset[j])
    if robot.has_tool and f == robot.n_frames - 1:
        total = total + jnp.linalg.norm(robot.tool[:3, 3].astype(dtype))
    return total


def sample_configurations(robot: Robot, key: jax.Array, n: int) -> jax.Array:
    """Deprecated: use :func:`jaxkin.sample_configurations` ``(robot, n, key)``."""
    warnings.warn(
        "jk.ik.sample_configurations(robot, key, n) is deprecated; use "
        "jk.sample_configurations(robot, n, key).",
        DeprecationWarning,
        stacklevel=2,
    )
    return sampling.sample_configurations(robot, n, key)


def _pose_and_jacobian(robot: Robot, q: jax.Array, f: int):
    g = jacobian_pass(robot, q, f, None, "world_aligned")  # one forward pass for both
    return g.pose(), g.matrix()


def _damped_step(J: jax.Array, e: jax.Array, lam: jax.Array, free: jax.Array) -> jax.Array:
    """``dq = Jf^T (Jf Jf^T + lam I)^-1 e`` with ``Jf = J * free`` (columns of blocked joints
    zeroed), unrolled into scalar operations.

    The 6x6 Cholesky of :func:`jaxkin._linalg.unrolled_cholesky`, then both triangular solves,
    written entry by entry (fused into one elementwise loop under ``vmap``).
    """
    m, n = J.shape
    Jf = jnp.where(free[None, :], J, 0.0)
    c = [[Jf[i, j] for j in range(n)] for i in range(m)]

    def entry(i: int, k: int) -> Any:
        a = sum(c[i][j] * c[k][j] for j in range(n))
        return a + lam if i == k else a

    L, _ = unrolled_cholesky(entry, m)
    y: list[Any] = [None] * m
    for i in range(m):
        y[i] = (e[i] - sum((L[i][j] * y[j] for j in range(i)), start=jnp.zeros_like(lam))) / L[i][i]
    x: list[Any] = [None] * m
    for i in reversed(range(m)):
        acc = sum((L[j][i] * x[j] for j in range(i + 1, m)), start=jnp.zeros_like(lam))
        x[i] = (y[i] - acc) / L[i][i]
    return jnp.stack([sum(c[i][j] * x[i] for i in range(m)) for j in range(n)])


# ----------------------------------------------------------------------------- LM
DEFAULT_NUM_SEEDS = 64
"""Starts per target of a default LM solve: ``q0``, then random restarts while it fails."""

ARM_DEFAULTS = {"max_steps": 30, "damping": 1e-3}
"""``max_steps`` and ``damping`` of a solve for one frame of a robot without free, ball or
planar joints."""

WHOLE_BODY_DEFAULTS = {"max_steps": 60, "damping": 1e-1}
"""``max_steps`` and ``damping`` of a whole-body solve (several frames, weights, ``com=``,
``posture=``, or free, ball or planar joints): a more cautious first step and twice the steps
per start. On G1's hands and feet from the neutral configuration these reach 100% of
``bench.wholebody_ik``'s 500 targets, where ``max_steps=30, damping=1e-3`` (the arm defaults)
reach 99.4% (``python3 -m bench.wholebody_ik --robots g1 --max-steps 30 --damping 1e-3``; 95%
of 200 before the restarts' rule of :data:`RESTART_RAMP`)."""


class _Lane(NamedTuple):
    """One LM worker: the start it runs (start ``seed`` of target ``job``; ``job == N`` when the
    lane is idle) and its iterate."""

    job: jax.Array
    seed: jax.Array
    q: jax.Array
    e: jax.Array  # residual at q
    J: jax.Array  # Jacobian at q
    err: jax.Array  # |e|^2 at q (inf: q is a new start, not evaluated yet)
    lam: jax.Array
    seed_steps: jax.Array  # steps from this start
    stall: jax.Array  # consecutive steps without real progress
    best_q: jax.Array  # best configuration of this start
    best_err: jax.Array
    hit_max: jax.Array  # this start ran out of steps while still progressing


class _Targets(NamedTuple):
    """What the LM queue knows of each target, (N + 1, ...) each (row N: idle lanes' dummy)."""

    q: jax.Array  # the answer so far: the first converged start's q, else the best start's
    err: jax.Array  # |e|^2 of that q
    seed: jax.Array  # the start that gave q
    hit_max: jax.Array  # int32 > 0: some start ran out of steps while still progressing
    steps: jax.Array  # LM steps on this target, all starts
    win: jax.Array  # the smallest converged start (S: none yet)
    handed: jax.Array  # starts handed out so far (S: no more; also set for unreachable)


class _Limits(NamedTuple):
    """Joint limits, (dof,) each; ``wraps``: see :func:`_project`."""

    lo: jax.Array
    hi: jax.Array
    wraps: jax.Array


def _limits(robot: Robot, dtype) -> _Limits:
    lo = robot.lower.astype(dtype)
    hi = robot.upper.astype(dtype)
    revolute = np.array([k == "revolute" for k in robot.joint_kinds])
    wraps = revolute & jnp.isfinite(lo) & jnp.isfinite(hi) & (hi - lo >= 2 * np.pi)
    return _Limits(lo, hi, wraps)


def _project(q: jax.Array, lim: _Limits) -> jax.Array:
    """``q`` brought within the limits. A revolute joint whose range spans a full turn (the UR's
    +-2 pi) is wrapped by a multiple of 2 pi (the same pose, and no wall for the iteration to
    stick to: clipping it there halves the UR5's success per start); other joints are clipped;
    continuous joints (infinite limits) are left alone."""
    over = (q < lim.lo) | (q > lim.hi)
    wrapped = q - 2 * np.pi * jnp.floor((q - lim.lo) / (2 * np.pi))
    return jnp.clip(jnp.where(lim.wraps & over, wrapped, q), lim.lo, lim.hi)


def _lm_lane_step(robot, f, T_target, unreachable, lane: _Lane, c):
    """One Levenberg-Marquardt iteration of one lane's start (one forward pass, at the trial
    point). Returns ``(lane, done, converged, stepped)``: the start is done when it converged,
    stalled, spent ``max_steps`` or its target is unreachable; ``stepped``: a step was taken (not
    the evaluation of a new start)."""
    lim = c[0]
    fresh = ~(lane.err < jnp.inf)
    # A fresh start is evaluated where it is; otherwise step from q and test the trial point.
    # Active set: a clipped joint at a limit, pushed outwards by the gradient, sits this out.
    g = lane.J.T @ lane.e
    blocked = ~lim.wraps & (((lane.q <= lim.lo) & (g < 0)) | ((lane.q >= lim.hi) & (g > 0)))
    dq = _damped_step(lane.J, lane.e, lane.lam, ~blocked)
    q_trial = jnp.where(fresh, lane.q, _project(lane.q + dq, lim))
    T_trial, J_trial = _pose_and_jacobian(robot, q_trial, f)
    e_trial = pose_residual(T_trial, T_target)
    return _lm_update(lane, fresh, q_trial, e_trial, J_trial, unreachable, c)


def _lm_update(lane: _Lane, fresh, q_trial, e_trial, J_trial, unreachable, c):
    """The bookkeeping of one LM iteration, given the trial point ``q_trial`` and its residual
    and Jacobian: accept or reject, adapt ``lambda``, count stalls; returns what
    :func:`_lm_lane_step` returns."""
    _, tol2, max_steps, lam0, patience, lam_min, lam_max = c
    err_trial = jnp.sum(e_trial * e_trial)
    accept = fresh | (jnp.isfinite(err_trial) & (err_trial < lane.err))
    q = jnp.where(accept, q_trial, lane.q)
    err = jnp.where(accept, err_trial, lane.err)
    lam = jnp.where(
        fresh, lam0, jnp.where(accept, jnp.maximum(lane.lam * 0.1, lam_min), lane.lam * 10.0)
    )
    seed_steps = lane.seed_steps + (~fresh).astype(jnp.int32)
    gain = jnp.where(accept & ~fresh, (lane.err - err_trial) / jnp.maximum(lane.err, 1e-300), 0.0)
    # Progress: a relative decrease of |e|^2 of at least 1e-3, or a rejected step while lambda
    # can still grow, resets the stall counter.
    progress = (gain > 1e-3) | (~fresh & ~accept & (lam < lam_max))
    stall = jnp.where(fresh | progress, 0, lane.stall + 1)
    better = err < lane.best_err  # q is always within the limits
    converged = err <= tol2
    stuck = (stall >= patience) | (lam >= lam_max) | ~jnp.isfinite(err)
    give_up = ~converged & ((seed_steps >= max_steps) | stuck)
    lane = lane._replace(
        q=q,
        e=jnp.where(accept, e_trial, lane.e),
        J=jnp.where(accept, J_trial, lane.J),
        err=err,
        lam=lam,
        seed_steps=seed_steps,
        stall=stall,
        best_q=jnp.where(better, q, lane.best_q),
        best_err=jnp.where(better, err, lane.best_err),
        hit_max=give_up & ~stuck,
    )
    return lane, converged | unreachable | give_up, converged, ~fresh


def _idle_lanes(B: int, n: int, N: int, dtype, m: int = 6, nv: int | None = None) -> _Lane:
    """``B`` idle lanes (``job == N``) for a robot with ``n`` entries of ``q``, ``nv`` of ``v``
    (default ``n``) and ``m`` residual rows."""
    nv = n if nv is None else nv
    zero = jnp.zeros(B, jnp.int32)
    q = jnp.zeros((B, n), dtype)
    inf = jnp.full(B, jnp.inf, dtype)
    return _Lane(
        job=jnp.full(B, N, jnp.int32),
        seed=zero,
        q=q,
        e=jnp.zeros((B, m), dtype),
        J=jnp.zeros((B, m, nv), dtype),
        err=inf,
        lam=jnp.ones(B, dtype),
        seed_steps=zero,
        stall=zero,
        best_q=q,
        best_err=inf,
        hit_max=jnp.zeros(B, bool),
    )


def _begin(lane: _Lane, free: jax.Array, job: jax.Array, seed: jax.Array) -> _Lane:
    """Lanes where ``free``: start ``seed`` of target ``job`` (idle when ``job == N``); its
    configuration is set by :func:`_place` at the next iteration. Only what a new start reads
    is reset; ``e``, ``J`` and ``lam`` are set by its first evaluation."""

    def pick(new, old):
        return jnp.where(free, new, old)

    zero = jnp.zeros_like(lane.stall)
    inf = jnp.full_like(lane.err, jnp.inf)
    return lane._replace(
        job=pick(job, lane.job),
        seed=pick(seed, lane.seed),
        err=pick(inf, lane.err),
        seed_steps=pick(zero, lane.seed_steps),
        stall=pick(zero, lane.stall),
        best_err=pick(inf, lane.best_err),
        hit_max=lane.hit_max & ~free,
    )


START_SLOTS = 8
"""Lanes whose new start :func:`_place` evaluates on their own in an iteration where at most
this many (of more) lanes begin one; otherwise it evaluates every lane's."""


def _place(lane: _Lane, begun: jax.Array, starts) -> _Lane:
    """The lanes ``begun`` (B,) by :func:`_begin` placed at their start's configuration
    (``starts(job, seed)``, vmapped), inside the loop.

    Usually a few lanes begin a start in an iteration (the first iteration: all of them); a
    whole-body start is a forward pass and a base fit, so where at most :data:`START_SLOTS`
    lanes begin, only theirs are evaluated (gathered, then scattered back), else every lane's
    (G1's targets: 0.85-0.89 -> 0.74 ms each; ``python3 -m bench.wholebody_ik --robots g1``
    with and without ``--start-slots 1000000``). The same values up to rounding (the two are
    compiled for different numbers of lanes: a start near the edge of converging can then go
    either way)."""
    B = begun.shape[0]

    def every():
        return starts(lane.job, lane.seed)

    def some():
        ix = jnp.nonzero(begun, size=START_SLOTS, fill_value=0)[0]
        return lane.q.at[ix].set(starts(lane.job[ix], lane.seed[ix]))

    if B <= START_SLOTS:
        q = every()
    else:
        q = jax.lax.cond(jnp.sum(begun) <= START_SLOTS, some, every)
    return lane._replace(
        q=jnp.where(begun[:, None], q, lane.q), best_q=jnp.where(begun[:, None], q, lane.best_q)
    )


def _hand_out(free, going_on, holding, tg: _Targets, queue, N: int, S: int):
    """Work for the ``free`` lanes (B,): ``(job, seed, tg, queue)``, ``job == N`` for a lane left
    idle; ``queue = (next_job, turn)``; ``holding``: the target of each lane that goes on with
    its start (N for free lanes).

    In order of priority: (1) a lane whose start failed (``going_on``: its target, else N) goes
    on with its target's next start, unless another lane still works on that target (one lane
    per target goes on); (2) targets not yet started, in order from ``next_job``, with their
    start 0; (3) once every target has started, further starts of the targets still being
    solved (none converged, starts left), handed round-robin from where the last round stopped
    (``turn``), so that a hard target's remaining starts run side by side at the end instead of
    one after another. By (1), every target still being solved is held by a lane: (3) looks
    at the lanes (B), not at all N targets.
    """
    next_job, turn = queue
    B = free.shape[0]
    ix = jnp.arange(B, dtype=jnp.int32)
    at = jnp.where(going_on < N, going_on, N)
    held = jnp.zeros(N + 1, bool).at[holding].set(True)
    open_ = (going_on < N) & (tg.win[at] == S) & (tg.handed[at] < S) & ~held[at]
    first = jnp.full(N + 1, B, jnp.int32).at[jnp.where(open_, at, N)].min(ix)
    go_on = open_ & (first[at] == ix)
    rest = free & ~go_on
    rank = jnp.cumsum(rest.astype(jnp.int32)) - 1
    n_new = N - next_job
    new = rest & (rank < n_new)
    extra = jnp.maximum(rank - n_new, 0)
    n_extra = jnp.sum(rest & ~new, dtype=jnp.int32)
    handed = tg.handed.at[jnp.where(go_on, at, N)].add(1)

    def extra_starts():
        # The targets still being solved (one holding lane each), numbered 0..m-1; extra lane
        # e takes number (turn + e) % m.
        t = jnp.where(go_on, at, holding)
        solving = (t < N) & (tg.win[t] == S) & (handed[t] < S)
        first = jnp.full(N + 1, B, jnp.int32).at[jnp.where(solving, t, N)].min(ix)
        solving = solving & (first[t] == ix)
        m = jnp.maximum(jnp.sum(solving, dtype=jnp.int32), 1)
        pos = jnp.cumsum(solving.astype(jnp.int32)) - 1
        by_pos = jnp.full(B, N, jnp.int32).at[jnp.where(solving, pos, B)].set(t, mode="drop")
        t0 = turn % m
        r = t0 + extra
        p = r % m
        # lanes given the same target this round (the round wraps around) take its next starts
        dup = r // m - (p < t0)
        return by_pos[p], dup, (t0 + n_extra) % m

    # Only once every target has started and a lane is left over.
    other, dup, turn = jax.lax.cond(
        n_extra > 0, extra_starts, lambda: (jnp.full_like(rank, N), jnp.zeros_like(rank), turn)
    )
    seed = jnp.where(go_on, tg.handed[at], jnp.where(new, 0, handed[other] + dup))
    job = jnp.where(go_on, at, jnp.where(new, next_job + rank, other))
    job = jnp.where(free & (job < N) & (seed < S), job, N).astype(jnp.int32)
    to = jnp.where((job < N) & ~go_on, job, N)
    tg = tg._replace(handed=handed.at[to].add(1))
    next_job = jnp.minimum(next_job + jnp.sum(new, dtype=jnp.int32), N).astype(jnp.int32)
    return job, seed.astype(jnp.int32), tg, (next_job, turn.astype(jnp.int32))


def _lm_queue(
    robot, T_all, start, S, unreachable, f, tol, max_steps, lam0, patience, lanes, task=None
):
    """Levenberg-Marquardt for N targets on ``lanes`` workers (one jitted ``while_loop``).

    ``T_all``: the targets, (N, 4, 4) for one frame (``f``), or a :class:`_Goals` of a
    whole-body ``task`` (:class:`_Task`, with its weights), every leaf with a leading N axis.

    A lane runs one start of one target at a time (``start(job, s)``, ``s < S``); when the start
    ends it takes new work (:func:`_hand_out`): its own target's next start, the next target not
    yet started, or, once all have started, a further start of a target still being solved.
    Targets differ widely in the work they need (a median of about 15 steps, a tail of hundreds
    over many starts): one lane per target would keep the batch iterating until the slowest
    finished, and one target's starts tried one after another would do the same at the end of
    the queue; persistent lanes keep busy, and the last targets' starts run side by side.

    The answer is the one of trying the starts in turn, whatever the number of lanes (up to
    rounding): the converged start with the smallest index (a start with a larger one still
    running is abandoned), else the best of all ``S`` starts (of equal ones, the first).
    ``steps`` counts every step taken on the target, abandoned starts included.
    """
    N = unreachable.shape[0]
    dtype = jax.tree_util.tree_leaves(T_all)[0].dtype
    is64 = jnp.finfo(dtype).bits == 64
    c = (_limits(robot, dtype), tol * tol, max_steps, lam0, patience, 1e-12 if is64 else 1e-6, 1e10)
    # Index N is an idle lane's dummy target (a copy of target 0).
    T_pad = jax.tree_util.tree_map(lambda x: jnp.concatenate([x, x[:1]], 0), T_all)
    unr_pad = jnp.concatenate([unreachable, jnp.ones(1, bool)], 0)
    if task is None:
        step = jax.vmap(lambda T, u, ln: _lm_lane_step(robot, f, T, u, ln, c))
        n, m, nv = robot.dof, 6, robot.dof
    else:
        step = jax.vmap(lambda T, u, ln: _task_lane_step(robot, task, T, u, ln, c))
        n, m, nv = robot.nq, task.rows, robot.nv
    starts = jax.vmap(start)
    zeros = jnp.zeros(N + 1, jnp.int32)
    tg0 = _Targets(
        q=jnp.zeros((N + 1, n), dtype),
        err=jnp.full(N + 1, jnp.inf, dtype),
        seed=jnp.full(N + 1, S, jnp.int32),
        hit_max=zeros,
        steps=zeros,
        win=jnp.full(N + 1, S, jnp.int32),
        handed=zeros,
    )

    def cond(carry):
        return jnp.any(carry[0].job < N)

    def body(carry):
        lane, tg, queue, begun = carry
        lane = _place(lane, begun, starts)
        busy = lane.job < N
        T_job = jax.tree_util.tree_map(lambda x: x[lane.job], T_pad)
        new, done, conv, stepped = step(T_job, unr_pad[lane.job], lane)
        done = done & busy
        conv = conv & done
        failed = done & ~conv
        at = lane.job  # N for idle lanes: their updates land in the dummy row
        win = tg.win.at[jnp.where(conv, at, N)].min(lane.seed)
        # A failed start's best counts while no start of its target has converged; of equal
        # ones the smaller start wins, as if the starts had been tried in turn.
        failed_open = failed & (win[at] == S)
        err = tg.err.at[jnp.where(failed_open, at, N)].min(new.best_err)
        tie = failed_open & (err[at] == new.best_err)
        seed = tg.seed.at[jnp.where(tie & (new.best_err < tg.err[at]), at, N)].set(S)
        seed = seed.at[jnp.where(tie, at, N)].min(lane.seed)
        first_converged = conv & (win[at] == lane.seed)
        seed = seed.at[jnp.where(first_converged, at, N)].set(lane.seed)
        to = jnp.where(first_converged | (tie & (seed[at] == lane.seed)), at, N)
        # Abandon starts whose target converged from a start with a smaller index.
        abandon = busy & ~done & (win[at] < lane.seed)
        tg = _Targets(
            q=tg.q.at[to].set(new.best_q),
            err=err.at[to].set(new.best_err),
            seed=seed,
            hit_max=tg.hit_max.at[at].add((failed & new.hit_max).astype(jnp.int32)),
            steps=tg.steps.at[at].add((busy & stepped).astype(jnp.int32)),
            win=win,
            handed=tg.handed.at[jnp.where(done & unr_pad[at], at, N)].set(S),
        )
        free = ~busy | done | abandon
        holding = jnp.where(free, N, at)
        job, seed, tg, queue = _hand_out(free, jnp.where(failed, at, N), holding, tg, queue, N, S)
        return _begin(new, free, job, seed), tg, queue, free

    B = lanes
    free0 = jnp.ones(B, bool)
    none = jnp.full(B, N, jnp.int32)
    zero = jnp.zeros((), jnp.int32)
    job0, seed0, tg0, queue0 = _hand_out(free0, none, none, tg0, (zero, zero), N, S)
    idle = _idle_lanes(B, n, N, dtype, m, nv)
    lane0 = _begin(idle, free0, job0, seed0)
    _, tg, _, _ = jax.lax.while_loop(cond, body, (lane0, tg0, queue0, free0))
    return tg.q[:N], tg.steps[:N], tg.seed[:N], tg.hit_max[:N] > 0


# ----------------------------------------------------------------------------- whole body
class _Task(NamedTuple):
    """What a whole-body solve targets (static, hashable): the frame indices, whether there is a
    centre-of-mass target and a posture term."""

    frames: tuple[int, ...]
    com: bool
    posture: bool
    random_starts: bool = True  # drawn, not given as seeds=: their floating base is placed

    @property
    def rows(self) -> int:
        """Residual rows: 6 per frame, then 3 for the centre of mass."""
        return 6 * len(self.frames) + 3 * self.com


class _Goals(NamedTuple):
    """One whole-body target (a leading N axis in a batch): frame poses ``T`` (k, 4, 4), the
    centre of mass ``com`` (3,) or None, the posture ``q_ref`` (nq,) or None, the row weights
    ``w`` (rows,) (frame by frame ``[v; omega]``, then the centre of mass) and the posture
    weights ``wp`` (nv,) or None."""

    T: jax.Array
    com: Any
    q_ref: Any
    w: jax.Array
    wp: Any


class _VLimits(NamedTuple):
    """The joint limits seen from the velocity ``v`` (nv,): ``ix`` the ``q`` entry of each
    velocity entry (0 for those of free, ball and planar joints, which have no box limit:
    ``lo = -inf``, ``hi = inf``), and :class:`_Limits`' ``wraps``."""

    ix: np.ndarray
    lo: jax.Array
    hi: jax.Array
    wraps: jax.Array


def _v_limits(robot: Robot, dtype) -> _VLimits:
    lim = _limits(robot, dtype)
    ix = np.zeros(robot.nv, dtype=np.int64)
    scalar = np.zeros(robot.nv, dtype=bool)
    for kind, qi, vi in zip(robot.kinds, robot.q_index, robot.v_index, strict=True):
        if qi >= 0 and kind not in ("free", "ball", "planar"):
            ix[vi], scalar[vi] = qi, True
    inf = jnp.asarray(np.inf, dtype)
    lo = jnp.where(scalar, lim.lo[ix], -inf)
    hi = jnp.where(scalar, lim.hi[ix], inf)
    return _VLimits(ix, lo, hi, jnp.asarray(scalar) & lim.wraps[ix])


def _held_v(q: jax.Array, vl: _VLimits) -> jax.Array:
    """:func:`_held` per velocity entry (nv,)."""
    qv = q[vl.ix]
    return ~vl.wraps & ((qv <= vl.lo) | (qv >= vl.hi))


def _task_residual(robot: Robot, task: _Task, q: jax.Array, goal: _Goals):
    """The weighted residual ``e`` (rows,) and Jacobian ``J`` (rows, nv) of a whole-body target
    at ``q``: per frame ``w * [p_t - p; log(R_t R^T)]`` with its world-aligned Jacobian, then
    ``w * (c_t - c)`` with the centre-of-mass Jacobian."""
    Ts, c, J = _task_pass(robot, task, q)
    return _task_error(task, Ts, c, goal), J * goal.w[:, None]


def _task_pass(robot: Robot, task: _Task, q: jax.Array):
    """The frames' poses ``Ts`` (k, 4, 4), the centre of mass ``c`` (3,) or None and the
    unweighted Jacobian (rows, nv) at ``q``: what :func:`_task_residual` reads of ``q``."""
    g = jacobians_pass(robot, q, task.frames)  # one forward pass for every frame
    Ts, Js = g.pose(), [g.matrix().reshape(-1, robot.nv)]
    c = None
    if task.com:
        c, Jc = com_and_jacobian(robot, q)
        Js.append(Jc)
    return Ts, c, jnp.concatenate(Js, axis=0)


def _task_error(task: _Task, Ts: jax.Array, c: Any, goal: _Goals) -> jax.Array:
    """The weighted residual (rows,) of the poses ``Ts`` and centre of mass ``c`` (see
    :func:`_task_pass`) against ``goal``."""
    es = [pose_residual(Ts[i], goal.T[i]) for i in range(len(task.frames))]
    if task.com:
        es.append(goal.com - c)
    return jnp.concatenate(es) * goal.w


def _least_squares_step(J, e, lam, free, dv0=None):
    """``argmin |J_f dv - e|^2 + lam |dv - dv0|^2`` (nv,), ``J_f``: ``J`` with the columns of
    blocked joints zeroed (their ``dv`` is 0); ``dv0`` (the posture's pull, or None: 0).

    ``dv0 + J_f^T (J_f J_f^T + lam I)^-1 (e - J_f dv0)``: the 6 x 6 system unrolled
    (:func:`_damped_step`) for one frame, else a Cholesky factorisation of the smaller of
    ``J_f J_f^T`` and ``J_f^T J_f`` (plus ``lam I``).
    """
    m, n = J.shape
    Jf = jnp.where(free[None, :], J, 0.0)
    if dv0 is not None:
        dv0 = jnp.where(free, dv0, 0.0)
        e = e - Jf @ dv0
    if m <= 6:
        dv = _damped_step(J, e, lam, free)
    elif m <= n:
        A = Jf @ Jf.T + lam * jnp.eye(m, dtype=J.dtype)
        dv = Jf.T @ jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(A), True), e)
    else:
        A = Jf.T @ Jf + lam * jnp.eye(n, dtype=J.dtype)
        dv = jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(A), True), Jf.T @ e)
    return dv if dv0 is None else dv + dv0


def _task_lane_step(robot, task: _Task, goal: _Goals, unreachable, lane: _Lane, c):
    """:func:`_lm_lane_step` for a whole-body target: the step is a velocity ``v`` (nv,),
    applied by :func:`jaxkin.configuration.integrate_kernel` (quaternions stay unit), then the
    joint limits (:func:`_project`); the posture, if any, pulls in the targets' null space."""
    lim, lam0 = c[0], c[3]
    dtype = lane.q.dtype
    vl = _v_limits(robot, dtype)
    fresh = ~(lane.err < jnp.inf)
    g = lane.J.T @ lane.e
    qv = lane.q[vl.ix]
    blocked = ~vl.wraps & (((qv <= vl.lo) & (g < 0)) | ((qv >= vl.hi) & (g > 0)))
    dv0 = None
    if task.posture:
        # The pull fades with the targets' residual |e| (its second-order effect on them is then
        # O(|e|^2): LM keeps converging quadratically) and as lambda grows past its start
        # (rejected steps: (lam0 / lam)^2 beats the 1 / lam of the targets' gradient step).
        fade = jnp.minimum(1.0, lam0 / lane.lam) ** 2 * jnp.minimum(1.0, jnp.sqrt(lane.err))
        dv0 = fade * goal.wp * configuration.difference(robot, lane.q, goal.q_ref)
    dv = _least_squares_step(lane.J, lane.e, lane.lam, ~blocked, dv0)
    q_trial = jnp.where(fresh, lane.q, _project(integrate_kernel(robot, lane.q, dv), lim))
    e_trial, J_trial = _task_residual(robot, task, q_trial, goal)
    return _lm_update(lane, fresh, q_trial, e_trial, J_trial, unreachable, c)


def _task_unreachable(robot: Robot, task: _Task, goals: _Goals, tol) -> jax.Array:
    """(N,) bool: some frame's target lies farther from the base than its reach bound."""
    dtype = goals.T.dtype
    base_p = robot.base[:3, 3].astype(dtype)
    out = jnp.zeros(goals.T.shape[0], bool)
    for i, f in enumerate(task.frames):
        bound = _reach_bound(robot, f).astype(dtype)  # inf below a floating base
        dist = jax.vmap(lambda T, i=i: safe_norm(T[i, :3, 3] - base_p))(goals.T)
        out = out | (dist > bound * (1 + 1e-12) + tol)
    return out


BASE_FIT_AXIS = 0.1
"""Metres: in the base fit of :func:`_aligned_starts`, each frame's orientation counts as its
three axes' tips at this distance from its origin (a frame's rotation error ``theta`` moves
them by about ``0.1 theta`` m)."""


def _base_fit(R, p, goal: _Goals, i):
    """The rigid motion ``(Rg, tg)`` (world coordinates) that best moves the frames at poses
    ``(R, p)`` ((k, 3, 3), (k, 3)) onto their targets ``goal.T``: weighted least squares
    (Kabsch) over the frames' origins (each weighted by the mean of its position rows' weights)
    and their axes' tips at :data:`BASE_FIT_AXIS` (the mean of its orientation rows' weights).
    Where that fit is degenerate (collinear origins and no orientation rows, or a reflection),
    frame ``i``'s own alignment: ``T_target_i T_i^-1``."""
    k = R.shape[0]
    w = goal.w[: 6 * k].reshape(k, 6)
    wp, wo = jnp.mean(w[:, :3], axis=1), jnp.mean(w[:, 3:], axis=1)
    Rt, pt = goal.T[:, :3, :3], goal.T[:, :3, 3]
    total = jnp.sum(wp)
    has = total > 0
    mean = lambda x: jnp.sum(wp[:, None] * x, axis=0) / jnp.where(has, total, 1.0)  # noqa: E731
    pc = jnp.where(has, mean(p), jnp.mean(p, axis=0))
    xc = jnp.where(has, mean(pt), pc)  # no position rows: turn about the frames' centroid
    M = jnp.einsum("k,ki,kj->ij", wp, pt - xc[None], p - pc[None])
    M = M + BASE_FIT_AXIS**2 * jnp.einsum("k,kia,kja->ij", wo, Rt, R)
    Rk, ok = polar_rotation(M)
    Ri = Rt[i] @ R[i].T
    Rg = jnp.where(ok, Rk, Ri)
    tg = jnp.where(ok, xc - Rk @ pc, pt[i] - Ri @ p[i])
    return Rg, tg


def _aligned_starts(robot: Robot, task: _Task, start, goals: _Goals):
    """``start(job, s)`` with the floating base of every random restart (``s > 0``) moved
    rigidly onto the targets (:func:`_base_fit`: the frames' origins and axes fitted in least
    squares, the joints as drawn): a restart then begins with the base about where the targets
    put it, whatever the start's joint angles. Unchanged for a robot without a free joint."""
    free = [j for j, kind in enumerate(robot.kinds) if kind == "free"]
    if not free:
        return start
    j = free[0]  # the floating base
    qi = robot.q_index[j]
    k = len(task.frames)
    N = goals.T.shape[0]

    def aligned(job, s):
        q = start(job, s)
        goal = jax.tree_util.tree_map(lambda x: x[jnp.minimum(job, N - 1)], goals)
        R, p = frame_poses(robot, q, (*task.frames, j + 1))  # one pass
        A, t = _base_fit(R[:k], p[:k], goal, s % k)
        RB, pB = R[k], p[k]
        # M' = M D with D = B^-1 G B, G = (A, t) the world motion, B the base link's world pose
        dR = RB.T @ A @ RB
        dp = RB.T @ (A @ pB + t - pB)
        quat = q[qi + 3 : qi + 7]
        t = q[qi : qi + 3] + quaternion_to_matrix(quat) @ dp
        quat = quaternion_multiply(quat, quaternion_exp(spatial.log_so3(dR)))
        moved = q.at[qi : qi + 3].set(t).at[qi + 3 : qi + 7].set(quat)
        return jnp.where(s > 0, moved, q)

    return aligned


def _finish_task(robot, task: _Task, goal: _Goals, q, steps, seed, hit_max, unreachable, tol):
    """:func:`_finish` of a whole-body target, checked by an independent forward kinematics
    (the kernel of ``jk.fk``, not the solver's Jacobian pass) and the exact
    rotation logarithm: per frame the position and orientation errors of the rows with a
    nonzero weight (k,), the centre of mass's, and the residual ``|w * e|`` over all rows.
    The centre of mass is the one of the Jacobian pass that flags singular rows (the same
    function of ``q``, traced once)."""
    k = len(task.frames)
    w = goal.w
    R, p = frame_poses(robot, q, task.frames)
    es = [pose_error(spatial.make_transform(R[i], p[i]), goal.T[i]) for i in range(k)]
    _, c, J = _task_pass(robot, task, q)
    com_error = None
    if task.com:
        es.append(goal.com - c)
    e = jnp.concatenate(es)
    on = w != 0
    ef = jnp.where(on[: 6 * k], e[: 6 * k], 0.0).reshape(k, 6)
    ep = jax.vmap(safe_norm)(ef[:, :3])
    eo = jax.vmap(safe_norm)(ef[:, 3:])
    if task.com:
        com_error = safe_norm(jnp.where(on[6 * k :], e[6 * k :], 0.0))
    residual = safe_norm(w * e)
    converged = residual <= tol
    code = _result_code(converged, residual, unreachable, hit_max)
    J = J * w[:, None]
    held = _held_v(q, _v_limits(robot, q.dtype))
    return IKSolution(
        q=q,
        converged=converged,
        residual=residual,
        steps=steps.astype(jnp.int32),
        result=code,
        position_error=ep,
        orientation_error=eo,
        seed=seed.astype(jnp.int32),
        singular=~full_rank(jax.lax.stop_gradient(J), held, on),
        com_error=com_error,
    )


def _task_tangent(robot, task: _Task, q, goal: _Goals, goal_dot: _Goals, robot_dot):
    """The implicit-function derivative of a whole-body solution (:mod:`jaxkin.ik_gradients`):
    ``dv = J_f^+ b`` (damped) with ``b`` the residual's derivative along the targets' (and the
    robot's) tangents at fixed ``q``, mapped to ``dq`` (nq,) through ``integrate``."""
    Ts, c, J = _task_pass(robot, task, q)
    J = J * goal.w[:, None]

    def e_of(goal_T, goal_com):  # q held: the pass above, not traced again under jvp
        return _task_error(task, Ts, c, goal._replace(T=goal_T, com=goal_com))

    _, b = jax.jvp(e_of, (goal.T, goal.com), (goal_dot.T, goal_dot.com))
    if robot_dot is not None:
        _, b_robot = jax.jvp(
            lambda rb: _task_residual(rb, task, q, goal)[0], (robot,), (robot_dot,)
        )
        b = b + b_robot
    finite = jnp.all(jnp.isfinite(J))
    held = _held_v(q, _v_limits(robot, q.dtype))
    dv = damped_pinv_apply(jnp.where(finite, J, 0.0), held, jnp.where(finite, b, 0.0))
    zero = jnp.zeros_like(dv)
    return jax.jvp(lambda v: integrate_kernel(robot, q, v), (zero,), (dv,))[1]


# ----------------------------------------------------------------------------- optax
def _optax_one(robot, T_target, seeds, f, tol, max_steps, optimizer, patience, unreachable):
    """An optax optimiser from every seed in parallel; returns the best."""
    import optax

    dtype = seeds.dtype
    lo = robot.lower.astype(dtype)
    hi = robot.upper.astype(dtype)
    tol2 = tol * tol

    def loss(q):
        e = pose_residual(spatial.make_transform(*frame_pose(robot, q, f)), T_target)
        return 0.5 * jnp.sum(e * e)

    # Not optax.value_and_grad_from_state with a line search's store_grad=True: optax transposes
    # its linearisation with a Python-float cotangent (float64 under x64), which a float32 loss
    # rejects with a TypeError.
    value_and_grad = jax.value_and_grad(loss)

    def run(q0):
        state0 = optimizer.init(q0)

        def cond(c):
            return ~c[-1]

        def body(c):
            q, st, k, best_q, best_v, stall, _ = c
            v, g = value_and_grad(q)
            updates, st = optimizer.update(g, st, q, value=v, grad=g, value_fn=loss)
            q = jnp.clip(optax.apply_updates(q, updates), lo, hi)
            v_new = loss(q)
            better = v_new < best_v
            gain = (best_v - v_new) / jnp.maximum(best_v, 1e-300)
            stall = jnp.where(better & (gain > 1e-4), 0, stall + 1)
            best_q = jnp.where(better, q, best_q)
            best_v = jnp.where(better, v_new, best_v)
            k = k + 1
            done = (2 * best_v <= tol2) | (k >= max_steps) | (stall >= patience)
            done = done | ~jnp.isfinite(v_new)
            return q, st, k, best_q, best_v, stall, done

        v0 = loss(q0)
        zero = jnp.zeros((), jnp.int32)
        init = (q0, state0, zero, q0, v0, zero, unreachable | (2 * v0 <= tol2))
        _, _, k, best_q, best_v, stall, _ = jax.lax.while_loop(cond, body, init)
        hit_max = (k >= max_steps) & (stall < patience) & (2 * best_v > tol2)
        return best_q, best_v, k, hit_max

    qs, vs, ks, hit = jax.vmap(run)(seeds)
    vs = jnp.where(jnp.isfinite(vs), vs, jnp.inf)
    i = jnp.argmin(vs)
    return qs[i], jnp.sum(ks), i.astype(jnp.int32), hit[i]


# ----------------------------------------------------------------------------- entry point
def _finish(robot, T_target, q, steps, seed, hit_max, unreachable, f, tol) -> IKSolution:
    """Errors, flags and result code of the final ``q`` of one target."""
    g = _pose_and_jacobian(robot, q, f)
    ep, eo = pose_error_norms(g[0], T_target)
    residual = safe_norm(jnp.stack([ep, eo]))
    converged = residual <= tol
    code = _result_code(converged, residual, unreachable, hit_max)
    held = _held(q, _limits(robot, q.dtype))
    return IKSolution(
        q=q,
        converged=converged,
        residual=residual,
        steps=steps.astype(jnp.int32),
        result=code,
        position_error=ep,
        orientation_error=eo,
        seed=seed.astype(jnp.int32),
        singular=~full_rank(jax.lax.stop_gradient(g[1]), held),
    )


def _result_code(converged, residual, unreachable, hit_max) -> jax.Array:
    """The :class:`RESULTS` code (int32) of a final configuration."""
    return jnp.where(
        converged,
        RESULTS.converged,
        jnp.where(
            ~jnp.isfinite(residual),
            RESULTS.nonfinite,
            jnp.where(
                unreachable,
                RESULTS.unreachable,
                jnp.where(hit_max, RESULTS.max_steps_reached, RESULTS.stalled),
            ),
        ),
    ).astype(jnp.int32)


RESTART_RAMP = 8
"""Restarts of a floating-base robot's whole-body solve draw each joint from the middle
``(s - 1) / RESTART_RAMP`` of its range (start ``s``; the whole range from ``s = 9`` on): the
first restart at mid-range, later ones spread out (see :func:`_start_fn`). Of 2, 4, 8, 16 and 32,
8 gave the least time per target over G1, Talos and Solo12 together (``python3 -m
bench.wholebody_ik --restart-ramp R``, 500 targets each; every value solved 100%)."""


def _start_fn(robot, q0, pool, n, S, dtype, keep_base=True):
    """``start(job, s)``: start ``s < S`` of target ``job < n`` (traced ints), within the
    limits (see :func:`_project`): ``q0`` (dof,) or ``q0[job]`` (n, dof) for ``s == 0``, then
    ``pool[(job * (S - 1) + s - 1) % P]`` from the (P, dof) pool of other starts (given seeds, or
    configurations drawn by :func:`jaxkin.sample_configurations`): one row per start and target
    while ``P >= n (S - 1)``, and ``S - 1`` distinct rows per target as long as ``P >= S - 1``.
    With ``keep_base`` (random starts), a pool row's floating-base coordinates (see
    :func:`_base_entries`) are replaced by the ones of ``q0``, and its other revolute and
    prismatic joints drawn towards mid-range: ``mid + a (row - mid)``, ``a = min(1, (s - 1) /``
    :data:`RESTART_RAMP` ``)`` (``mid`` the middle of :func:`jaxkin.sampling_bounds`): on a
    humanoid's or quadruped's limbs mid-range joints are a posture from which LM reaches most
    targets (the module doc has the measured effect)."""
    lim = _limits(robot, dtype)
    q0 = jnp.broadcast_to(q0.astype(dtype), (n, robot.nq))
    if pool is not None:
        pool = pool.astype(dtype)
    base = _base_entries(robot) if keep_base else None
    if base is not None:
        lo, hi = sampling.sampling_bounds(robot)
        mid = ((jnp.asarray(lo) + jnp.asarray(hi)) / 2).astype(dtype)
        scalar = np.zeros(robot.nq, dtype=bool)
        for kind, qi in zip(robot.kinds, robot.q_index, strict=True):
            if kind in ("revolute", "prismatic"):
                scalar[qi] = True

    def start(job, s):
        job = jnp.minimum(job, n - 1)
        q = q0[job]
        if pool is not None:
            i = (job * (S - 1) + jnp.maximum(s - 1, 0)) % pool.shape[0]
            other = pool[i]
            if base is not None:
                a = jnp.minimum(1.0, (s - 1) / RESTART_RAMP).astype(dtype)
                other = jnp.where(scalar, mid + a * (other - mid), other)
                other = jnp.where(base, q, other)
            q = jnp.where(s == 0, q, other)
        return _project(q, lim)

    return start


def _base_entries(robot: Robot) -> np.ndarray | None:
    """(nq,) bool: the coordinates of the free joints (floating bases), or None without one.

    Random restarts keep them from ``q0``: a random orientation of a humanoid's pelvis (upside
    down, on its side) starts far from any whole-body target, while the base pose is the
    easiest part of the solve (six unconstrained columns of the Jacobian)."""
    mask = np.zeros(robot.nq, dtype=bool)
    for kind, qi in zip(robot.kinds, robot.q_index, strict=True):
        if kind == "free":
            mask[qi : qi + 7] = True
    return mask if mask.any() else None


def _solve_batch_impl(
    robot,
    T_all,
    q0,
    pool,
    tol,
    lam0,
    max_steps,
    patience,
    starts,
    *,
    f,
    method,
    optimizer,
    lanes,
    num_seeds,
    task=None,
):
    """The jitted solve of a batch: ``_solve_core``'s loops, their answer differentiable
    (:func:`_solution`), then ``_finish`` per target.

    ``starts`` (int32): the starts per target of an LM solve, an argument (traced), so that
    calls differing only in ``num_seeds`` share one compiled solver, as ``max_steps`` and
    ``tol`` do; ``num_seeds`` (static) is that count for optax (its starts run side by side, an
    array axis), None for LM.
    """
    if task is None:
        T_all = T_all.reshape(-1, 4, 4)
    static = (f, method, optimizer, lanes, num_seeds, task)
    args = (T_all, q0, pool, tol, lam0, max_steps, patience, starts)
    # The loops are traced once and never differentiated (their inputs' tangents stopped);
    # ``_solution`` gives their answer its derivative. A concrete robot stays out of the
    # differentiated arguments (static: constants folded); a traced one is an argument, so that
    # derivatives reach its leaves.
    traced = is_traced(robot)
    loops_robot = jax.lax.stop_gradient(robot) if traced else robot
    q, steps, seed, hit_max, unreachable = _solve_core(
        loops_robot, static, *jax.lax.stop_gradient(args)
    )
    if traced:
        q = _solution(None, static, robot, T_all, q)
    else:
        q = _solution(robot, static, None, T_all, q)
    if task is not None:
        return jax.vmap(
            lambda G, qq, k, sd, h, u: _finish_task(robot, task, G, qq, k, sd, h, u, tol)
        )(T_all, q, steps, seed, hit_max, unreachable)
    return jax.vmap(lambda T, qq, k, sd, h, u: _finish(robot, T, qq, k, sd, h, u, f, tol))(
        T_all, q, steps, seed, hit_max, unreachable
    )


def _solve_core(robot, static, T_all, q0, pool, tol, lam0, max_steps, patience, starts):
    """The solver loops: ``(q, steps, seed, hit_max, unreachable)`` per target, never
    differentiated (:func:`_solution` gives ``q`` its derivative)."""
    f, method, optimizer, lanes, num_seeds, task = static
    if method == "lm":
        num_seeds = starts  # traced: one compile for every num_seeds
    if task is not None:  # a whole-body target (LM only)
        dtype = T_all.T.dtype
        N = T_all.T.shape[0]
        start = _start_fn(robot, q0, pool, N, num_seeds, dtype, task.random_starts)
        if task.random_starts:
            start = _aligned_starts(robot, task, start, T_all)
        unreachable = _task_unreachable(robot, task, T_all, tol)
        q, steps, seed, hit_max = _lm_queue(
            robot,
            T_all,
            start,
            num_seeds,
            unreachable,
            f,
            tol,
            max_steps,
            lam0,
            patience,
            lanes,
            task,
        )
        return q, steps, seed, hit_max, unreachable
    dtype = T_all.dtype
    N = T_all.shape[0]
    start = _start_fn(robot, q0, pool, N, num_seeds, dtype)
    base_p = robot.base[:3, 3].astype(dtype)
    bound = _reach_bound(robot, f).astype(dtype)
    dist = jax.vmap(lambda T: safe_norm(T[:3, 3] - base_p))(T_all)
    unreachable = dist > bound * (1 + 1e-12) + tol
    if method == "lm":
        q, steps, seed, hit_max = _lm_queue(
            robot, T_all, start, num_seeds, unreachable, f, tol, max_steps, lam0, patience, lanes
        )
    else:
        idx = jnp.arange(num_seeds, dtype=jnp.int32)
        seeds = jax.vmap(lambda j: jax.vmap(lambda s: start(j, s))(idx))(jnp.arange(N))
        q, steps, seed, hit_max = jax.vmap(
            lambda T, sd, u: _optax_one(robot, T, sd, f, tol, max_steps, optimizer, patience, u)
        )(T_all, seeds, unreachable)
    return q, steps, seed, hit_max, unreachable


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def _solution(robot_static, static, robot_traced, T_all, q):
    """``q``, the loops' solutions of the targets ``T_all`` (N, ...), unchanged; differentiated
    by :func:`_solution_jvp` (the implicit function theorem), so that a derivative of a solve
    traces the loops once, without their tangents."""
    return q


@_solution.defjvp
def _solution_jvp(robot_static, static, primals, tangents):
    """``dq`` of every target by :func:`jaxkin.ik_gradients.solution_tangent` (see that
    module's doc); ``q``'s own tangent is zero (the loops' inputs are stopped)."""
    robot_traced, T_all, q = primals
    robot_dot, T_dot = tangents[0], tangents[1]
    # q again through the rule: an outer derivative (a second order) sees q's dependence
    q = _solution(robot_static, static, robot_traced, T_all, q)
    robot = robot_static if robot_traced is None else robot_traced
    f, task = static[0], static[-1]
    rb_dot = None if robot_traced is None else _each_target(robot_dot, q.shape[0])
    if task is not None:
        dq = jax.vmap(lambda qq, G, Gd, rd: _task_tangent(robot, task, qq, G, Gd, rd))(
            q, T_all, jax.tree_util.tree_map(lambda x: x.astype(q.dtype), T_dot), rb_dot
        )
        return q, dq.astype(q.dtype)
    held = jax.vmap(lambda qq: _held(qq, _limits(robot, q.dtype)))(q)
    dq = jax.vmap(lambda qq, T, h, Td, rd: solution_tangent(robot, qq, T, f, h, Td, rd))(
        q, T_all, held, T_dot.astype(T_all.dtype), rb_dot
    )
    return q, dq.astype(q.dtype)


def _each_target(robot_dot: Robot, N: int) -> Robot:
    """The robot's tangent repeated for each of the N targets (a leading axis on every leaf),
    mapped by the rule's ``vmap`` with the targets. Under reverse mode its transpose then sums
    the targets' cotangents once per leaf array: closed over instead, each scalar of the robot
    the kinematics reads got its own sum over the targets, a reduction that XLA fuses with its
    own copy of the pass (a UR5's gradient over 8 targets: 241 of them, 10.2 s of compiling
    against 5.8). Forward mode computes the same values either way; reverse mode adds the
    same terms in another order (last-bit differences)."""
    return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (N, *jnp.shape(x))), robot_dot)


def _held(q: jax.Array, lim: _Limits) -> jax.Array:
    """Joints held at a limit (the derivative keeps them there): clipped joints exactly at one."""
    return ~lim.wraps & ((q <= lim.lo) | (q >= lim.hi))


_solve_batch = robot_jit(
    _solve_batch_impl, ("f", "method", "optimizer", "lanes", "num_seeds", "task")
)


def solve_ik(
    robot: Robot,
    T_target: Any,
    q0: Any,
    frame: int | str | None = None,
    *,
    method: str = "lm",
    tol: float | None = None,
    max_steps: int | None = None,
    num_seeds: int | None = None,
    key: Any = None,
    seeds: Any = None,
    optimizer: Any = None,
    damping: float | None = None,
    patience: int = 8,
    lanes: int | None = None,
    throw: bool = True,
    weights: Any = None,
    com: Any = None,
    com_weight: Any = 1.0,
    posture: Any = None,
    posture_weight: Any = None,
) -> IKSolution:
    """Inverse kinematics: a ``q`` with ``fk(robot, q, frame) == T_target``, within the limits.

    Any robot: free (floating-base) and ball joints included, and several frames at once
    (``frame=[f1, ..., fk]``), with per-row weights, a centre-of-mass target and a posture
    term: the whole-body solve of the module doc.

    Args:
      robot: the robot.
      T_target: (4, 4) target pose ``T_world_frame``, or (N, 4, 4) for a batch of N targets
        (solved together in one jitted, vmapped loop); with ``frame=[f1, ..., fk]``: (k, 4, 4),
        one pose per frame, or (N, k, 4, 4).
      q0: (nq,) start configuration, or (N, nq) one per target. It is the first seed.
      frame: the frame to place (default: the tip, tool included), or a list of k frames
        (names or indices) to place at once.
      method: ``"lm"`` (Levenberg-Marquardt, default) or ``"optax"`` (see the module doc).
      tol: convergence threshold on the residual ``|e|`` (metres and radians); default 1e-10 in
        float64, 1e-5 in float32.
      max_steps: iteration budget per start (LM steps or optimiser updates); a target's steps
        over all its starts are at most ``num_seeds * max_steps``. Default 30 for one frame of a
        robot without free, ball or planar joints, 60 for a whole-body solve
        (:data:`ARM_DEFAULTS`, :data:`WHOLE_BODY_DEFAULTS`).
      num_seeds: the most starts per target: ``q0``, then ``num_seeds - 1`` configurations
        drawn uniformly within the limits by :func:`jaxkin.sample_configurations` from ``key``
        (default ``jax.random.key(0)``; infinite limits sample [-pi, pi] or [-1, 1] m). LM
        tries them in turn, restarting only when a start fails, until one converges; optax runs
        them all and keeps the best. Default: 64 for LM (:data:`DEFAULT_NUM_SEEDS`), 1 for
        optax. ``num_seeds=1``: ``q0`` only. For LM a new value does not recompile the solver
        (nor do ``max_steps``, ``tol``, ``damping`` and ``patience``). A floating base is not
        drawn at random (see the module doc: restarts keep ``q0``'s base, then move it onto
        the targets, and draw the joints from mid-range outwards).
      seeds: explicit extra starts instead of random ones: (S, nq), the same for every target,
        or (N, S, nq); tried after ``q0`` (brought within the limits; a floating base as
        given), and no others. Excludes ``num_seeds``. For one frame of a fixed-base arm, a call
        with seeds shares the compiled solver of one without (while ``N * S <= 4096``).
      optimizer: for ``method="optax"``: an optax ``GradientTransformation`` (default: L-BFGS
        with a backtracking line search). Optimisers hash by identity: one compile per object.
      damping: initial LM damping ``lambda`` (m^2, adapted at every step); default 1e-3 for one
        frame of a fixed-base arm, 0.1 for a whole-body solve.
      patience: a start is abandoned (``stalled``) after this many steps without a relative
        decrease of ``|e|^2`` of 1e-3 (LM) or 1e-4 (optax).
      lanes: LM only: the number of parallel workers for a batch, an integer >= 1 (default: N
        up to 64, then N / 8, at least 64). Each runs one start at a time and then takes the
        next piece of work, so a few hard targets do not keep the whole batch iterating; at the
        end the remaining starts of the last targets run side by side. The answer does not
        depend on it (up to rounding): the first converging start in the order of the starts
        wins.
      throw: raise :class:`IKError` if any target did not converge (default; the error's
        ``solution`` holds the whole :class:`IKSolution`); ``False`` returns the
        :class:`RESULTS` codes in ``result`` instead.
      weights: per residual row, >= 0: (6,) for every frame or (k, 6) one row per frame, each
        ``[vx, vy, vz, wx, wy, wz]`` (position rows first, world axes). A weight scales its row
        of the residual, in the least squares and in the convergence test alike: 0 turns the row
        off (``(1, 1, 1, 0, 0, 0)``: position only; ``(0, 0, 0, 1, 1, 1)``: orientation only;
        ``(0, 0, 1, 0, 0, 0)``: height only), a row of weight ``w`` converges when
        ``w |e_row| <= tol``. Default: all 1. One array for both uses, since rows are what the
        solver weighs (a per-frame scalar weight is ``w[:, None] * np.ones(6)``).
      com: a centre-of-mass target (3,) in world coordinates, or (N, 3) one per target (the
        robot needs inertial data: :func:`jaxkin.center_of_mass`); three more residual rows
        ``c_target - c(q)``.
      com_weight: the weight of the centre-of-mass rows: a number or (3,) (e.g. ``(1, 1, 0)``:
        over the support polygon, any height).
      posture: a reference configuration (nq,) or (N, nq) to pull toward: a soft, secondary
        objective. Each step adds ``posture_weight * difference(q, posture)`` projected into
        the null space of the targets' rows (the damped least-squares step taken toward it
        instead of toward 0), faded as the targets' residual shrinks and as the damping grows,
        so it never stops the targets from converging; the solve still ends as soon as they
        do, so the answer is pulled toward the posture, not the posture-optimal solution.
      posture_weight: the fraction (0 to 1) of the gap to the posture closed per step: a
        number, applied to every joint but the free joints (the base is placed by the
        targets), or (nv,) per velocity entry. Default 0.5 (:data:`DEFAULT_POSTURE_WEIGHT`).

    Returns:
      :class:`IKSolution` (fields with a leading N axis for a batch). ``q`` always lies within
      the joint limits, its quaternions unit; when a solve fails it is the best configuration
      found. With ``frame=[...]``, ``position_error`` and ``orientation_error`` have a k axis
      (N, k); ``com_error`` is set with ``com=``.

    Not started exactly at a solution, a singular configuration or a limit changes nothing: the
    loop checks the residual before its first step (``steps == 0`` at a solution), the damping
    keeps every step finite at singularities, and the optax loss has a zero (not NaN) gradient
    at the solution.
    """
    fn = "jk.solve_ik"
    _check_settings(fn, method, max_steps, num_seeds, patience, lanes)
    check_robot(robot, fn)
    dtype = np.dtype(robot.dtype)
    whole_body = (
        isinstance(frame, (list, tuple))
        or robot.nq != robot.nv
        or any(x is not None for x in (weights, com, posture))
    )
    task = None
    if whole_body:
        if method != "lm":
            raise JaxkinError(
                f"{fn}: several frames, weights, com=, posture= and robots with free, ball or "
                f"planar joints are solved by method='lm' only, got method={method!r}."
            )
        task, T, batched = _whole_body_goals(
            robot, T_target, frame, weights, com, com_weight, posture, posture_weight, fn, dtype
        )
        task = task._replace(random_starts=seeds is None)
        f = None
        N = T.T.shape[0]
        defaults = WHOLE_BODY_DEFAULTS
    else:
        f = robot.frame_index(frame)
        T, batched = check_poses(T_target, fn, "T_target", dtype)
        N = T.shape[0] if batched else 1
        defaults = ARM_DEFAULTS
    max_steps = defaults["max_steps"] if max_steps is None else max_steps
    damping = defaults["damping"] if damping is None else damping
    q0 = _check_q0(robot, q0, batched, N, fn)
    seeds, num_seeds = _check_seeds(robot, seeds, num_seeds, N, fn)
    S = _num_starts(seeds, num_seeds, method)
    if tol is None:
        tol = 1e-10 if dtype == np.float64 else 1e-5
    if not is_traced(tol) and not tol > 0:  # a traced tol <= 0 converges nowhere (flagged)
        raise JaxkinError(f"{fn}: tol must be > 0, got {tol!r}.")
    if method == "optax" and optimizer is None:
        optimizer = default_optimizer()
    # Staged out (the caller's jit): traced inline, into the caller's program; a nested jit
    # there would be traced again for every derivative taken of it (its tangents).
    solve = _solve_batch_impl if staged() else _solve_batch
    sol = solve(
        robot,
        T,
        q0,
        _pool(robot, seeds, key, N, S, dtype, method),
        jnp.asarray(tol, dtype),
        jnp.asarray(damping, dtype),
        jnp.asarray(max_steps, jnp.int32),
        jnp.asarray(patience, jnp.int32),
        jnp.asarray(S, jnp.int32),
        f=f,
        method=method,
        optimizer=optimizer if method == "optax" else None,
        lanes=_lanes(N) if lanes is None else int(lanes),
        num_seeds=S if method == "optax" else None,
        task=task,
    )
    if task is not None and not isinstance(frame, (list, tuple)):  # one frame: no k axis
        sol = sol._replace(
            position_error=sol.position_error[:, 0], orientation_error=sol.orientation_error[:, 0]
        )
    if not batched:
        sol = jax.tree_util.tree_map(lambda x: x[0], sol)
    if throw:
        _raise_if_failed(sol)
    return sol


DEFAULT_POSTURE_WEIGHT = 0.5
"""``posture_weight`` when ``posture=`` is given without one: at most this fraction of the gap
to the posture is closed per step, in the targets' null space."""


def _whole_body_goals(
    robot, T_target, frame, weights, com, com_weight, posture, posture_weight, fn, dtype
):
    """``(task, goals, batched)`` of a whole-body call: :class:`_Task` and :class:`_Goals` with a
    leading N axis, every argument checked (shapes, finite, rigid poses, weights >= 0)."""
    frames = check_frames(robot, frame, fn)
    many = frames is not None
    frames = frames if many else (robot.frame_index(frame),)
    k = len(frames)
    T = _as_float(T_target, fn, "T_target", dtype)
    one = (k, 4, 4) if many else (4, 4)
    shape = tuple(T.shape)
    batched = len(shape) == len(one) + 1 and shape[1:] == one
    if shape != one and not batched:
        want = (
            f"({k}, 4, 4) (one pose per frame) or (N, {k}, 4, 4)" if many else "(4, 4) or (N, 4, 4)"
        )
        raise ShapeError(f"{fn}: T_target must have shape {want} for frame={frame!r}, got {shape}.")
    T, _ = check_poses(T.reshape(-1, 4, 4), fn, "T_target", dtype)  # finite and rigid
    T = T.reshape(-1, k, 4, 4)
    N = T.shape[0]
    w = np.ones(6) if weights is None else weights
    w = _weights(w, (6,), (k, 6), "weights", fn, dtype, "[v; omega] per frame")
    w = jnp.broadcast_to(w, (k, 6)).reshape(-1)
    c = None
    if com is not None:
        check_inertia(robot, fn)
        c = _per_target(com, (3,), N, batched, "com", fn, dtype)
        wc = _weights(com_weight, (), (3,), "com_weight", fn, dtype, "x, y, z")
        w = jnp.concatenate([w, jnp.broadcast_to(wc, (3,))])
    q_ref = wp = None
    if posture is not None:
        q_ref = _per_target(posture, (robot.nq,), N, batched, "posture", fn, dtype)
        if not is_traced(q_ref):
            for r in np.asarray(q_ref):
                check_q(robot, r, what="posture", fn=fn)
        if posture_weight is None:
            posture_weight = DEFAULT_POSTURE_WEIGHT
        wp = _weights(posture_weight, (), (robot.nv,), "posture_weight", fn, dtype, "per v entry")
        if jnp.ndim(wp) == 0:  # the base is placed by the targets, not pulled
            wp = jnp.where(jnp.asarray(_free_velocities(robot)), 0.0, wp).astype(dtype)
    task = _Task(frames=frames, com=c is not None, posture=q_ref is not None)
    rows = jnp.broadcast_to(w, (N, task.rows))
    goals = _Goals(
        T=T,
        com=c,
        q_ref=q_ref,
        w=rows,
        wp=None if wp is None else jnp.broadcast_to(wp, (N, robot.nv)),
    )
    return task, goals, batched


def _as_float(x: Any, fn: str, what: str, dtype) -> Any:
    """``x`` as a float array (host numpy unless traced), refused when concretely non-finite."""
    x = x if is_traced(x) else np.asarray(x, dtype=np.float64)
    if not is_traced(x) and not np.issubdtype(x.dtype, np.number):
        raise JaxkinError(f"{fn}: {what} must hold numbers.")
    refuse_nonfinite(x, what, fn)
    return x


def _per_target(x, shape, N, batched, what, fn, dtype) -> jax.Array:
    """``x`` of ``shape`` (the same for every target) or ``(N, *shape)``, as (N, *shape)."""
    x = _as_float(x, fn, what, dtype)
    if tuple(np.shape(x)) == shape:
        return jnp.broadcast_to(jnp.asarray(x, dtype), (N, *shape))
    if batched and tuple(np.shape(x)) == (N, *shape):
        return jnp.asarray(x, dtype)
    want = f"{shape}" + (f" or {(N, *shape)} (one per target)" if batched else "")
    raise ShapeError(f"{fn}: {what} must have shape {want}, got {tuple(np.shape(x))}.")


def _weights(x, short, full, what, fn, dtype, meaning) -> jax.Array:
    """Weights of shape ``short`` (broadcast) or ``full``, finite and >= 0."""
    x = _as_float(x, fn, what, dtype)
    if tuple(np.shape(x)) not in (short, full):
        raise ShapeError(
            f"{fn}: {what} must have shape {short} or {full} ({meaning}), got {tuple(np.shape(x))}."
        )
    if not is_traced(x) and np.any(x < 0):
        raise JaxkinError(f"{fn}: {what} must be >= 0 (0 turns a row off), got {x.tolist()}.")
    return jnp.asarray(x, dtype)


def _free_velocities(robot: Robot) -> np.ndarray:
    """(nv,) bool: the velocity entries of free joints (floating bases)."""
    mask = np.zeros(robot.nv, dtype=bool)
    for kind, vi in zip(robot.kinds, robot.v_index, strict=True):
        if kind == "free":
            mask[vi : vi + 6] = True
    return mask


def _check_settings(fn: str, method: str, max_steps, num_seeds, patience, lanes=None) -> None:
    """Refuse an unknown method and counts that are not integers >= 1 (booleans included)."""
    if method not in METHODS:
        raise JaxkinError(f"{fn}: method must be one of {METHODS}, got {method!r}.")
    for name, val, lo in (
        ("max_steps", 1 if max_steps is None else max_steps, 1),
        ("num_seeds", 1 if num_seeds is None else num_seeds, 1),
        ("patience", patience, 1),
        ("lanes", 1 if lanes is None else lanes, 1),
    ):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < lo:
            raise JaxkinError(f"{fn}: {name} must be an integer >= {lo}, got {val!r}.")


def _check_q0(robot: Robot, q0: Any, batched: bool, N: int, fn: str):
    """``q0`` as (dof,) or, for a batch, (N, dof); refused when concrete and not finite."""
    q0 = jnp.asarray(q0) if hasattr(q0, "shape") else np.asarray(q0, dtype=float)
    if not (batched and tuple(q0.shape) == (N, robot.nq)):
        q0 = check_q(robot, q0, what="q0", fn=fn)
    refuse_nonfinite(q0, "q0", fn)
    return q0


def _check_seeds(robot: Robot, seeds: Any, num_seeds: int | None, N: int, fn: str):
    """``(seeds, num_seeds)`` checked: seeds (S, dof) or (N, S, dof), not with num_seeds; no
    seeds at all (S == 0) becomes ``(None, 1)``."""
    if seeds is None:
        return seeds, num_seeds
    shape = tuple(jnp.shape(seeds))
    if not (
        (len(shape) == 2 and shape[1] == robot.nq)
        or (len(shape) == 3 and shape[0] == N and shape[2] == robot.nq)
    ):
        raise ShapeError(
            f"{fn}: seeds must have shape (S, {robot.nq}) (the same extra starts for every "
            f"target) or ({N}, S, {robot.nq}), got {shape}."
        )
    if num_seeds is not None:
        raise JaxkinError(f"{fn}: give seeds= or num_seeds=, not both.")
    seeds = jnp.asarray(seeds) if hasattr(seeds, "shape") else np.asarray(seeds, dtype=float)
    if seeds.shape[-2] == 0:
        return None, 1
    return seeds, num_seeds


def _num_starts(seeds: Any, num_seeds: int | None, method: str) -> int:
    """Starts per target: ``q0`` and the given seeds, else ``num_seeds``, else the default."""
    if seeds is not None:
        return 1 + int(seeds.shape[-2])
    if num_seeds is not None:
        return int(num_seeds)
    return DEFAULT_NUM_SEEDS if method == "lm" else 1


_POOL = 4096
"""Random starts drawn per call (more if ``num_seeds`` asks for more), shared out among the
targets (:func:`_start_fn`)."""


def _pool(robot, seeds, key, n, S, dtype, method="lm"):
    """The (P, dof) starts after ``q0`` (see :func:`_start_fn`); for one start nothing is read
    from it: None for optax, zeros of the usual shape for LM (so that ``num_seeds=1`` shares the
    compiled solver of the default ``num_seeds``). Given seeds are laid out one row per start
    and target (``n (S - 1)`` rows, the rows :func:`_start_fn` reads), then padded with zeros to
    the random pool's size: calls with and without ``seeds=`` share one compiled solver."""
    if seeds is not None:
        xp = jnp if is_traced(seeds) else np  # host-side when concrete: no eager compiles
        rows = xp.broadcast_to(xp.asarray(seeds, dtype), (n, S - 1, robot.nq))
        rows = xp.pad(rows.reshape(-1, robot.nq), ((0, max(_POOL - n * (S - 1), 0)), (0, 0)))
        return rows if xp is jnp else jax.device_put(rows)
    # A fixed size: the sampler compiles once per robot size, whatever the batch.
    size = max(_POOL, S - 1)
    if S == 1:
        return None if method == "optax" else jnp.zeros((size, robot.nq), dtype)
    return sampling.sample_configurations(robot, size, 0 if key is None else key, dtype=dtype)


def _lanes(n: int) -> int:
    """Default number of LM workers for n targets: all of them up to 64, then n / 8 (at least
    64): enough to fill the vector units, few enough to stay busy through the tail."""
    return n if n <= 64 else max(64, -(-n // 8))


def _failure_message(result: np.ndarray, residual: np.ndarray, kept: bool) -> str | None:
    """The IKError message, or None when every target converged; ``kept``: the error carries
    the solution (an eager call)."""
    result = np.atleast_1d(np.asarray(result))
    residual = np.atleast_1d(np.asarray(residual))
    failed = np.flatnonzero(result != RESULTS.converged)
    if failed.size == 0:
        return None
    counts = {RESULTS(c).name: int(np.sum(result == c)) for c in np.unique(result[failed])}
    i = int(failed[0])
    return (
        f"jk.solve_ik: {failed.size} of {result.size} target(s) not reached ({counts}); first: "
        f"target {i}, residual {float(residual[i]):.3g}: {RESULTS.message(int(result[i]))}. "
        + (
            "Every target's solution is kept on the error (sol.converged says which were "
            "reached): except jk.IKError as e: sol = e.solution; or pass throw=False to get it "
            "returned, with the result codes (sol.result, jk.ik.RESULTS)."
            if kept
            else "Pass throw=False to get the solutions and the result codes (sol.result, "
            "jk.ik.RESULTS) instead."
        )
    )


def _raise_if_failed(sol: IKSolution) -> None:
    if not is_traced((sol.result, sol.residual)):
        msg = _failure_message(np.asarray(sol.result), np.asarray(sol.residual), kept=True)
        if msg:
            raise IKError(msg, solution=sol)
        return

    def check(result, residual):
        msg = _failure_message(result, residual, kept=False)
        if msg:
            raise IKError(msg)

    jax.debug.callback(check, sol.result, sol.residual)
