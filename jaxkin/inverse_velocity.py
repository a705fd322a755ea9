"""Inverse velocity: joint velocities for a desired twist, and resolved-rate motion control.

Given a Jacobian ``J`` (m, dof) and a task velocity ``v`` (m,) (for the geometric Jacobian of
:func:`jaxkin.geometric_jacobian`: a twist ``[v; omega]`` in the Jacobian's reference), find
``qd`` (dof,) with ``J qd ~= v``:

* :func:`pinv_velocity`: ``qd = J^+ v``, the minimum-norm least-squares solution, singular values
  below ``rcond * sigma_max`` treated as zero (``rcond`` has no default: the cut decides how
  large ``qd`` may get near a singularity);
* :func:`damped_least_squares`: ``qd = J^T (J J^T + lambda^2 I)^-1 v`` (Nakamura & Hanafusa,
  Wampler), the minimiser of ``|J qd - v|^2 + lambda^2 |qd|^2``. Its gain along each singular
  direction is ``sigma / (sigma^2 + lambda^2) <= 1 / (2 lambda)``, so ``|qd| <= |v| / (2 lambda)``
  for any J, singular or not. :func:`adaptive_damping` gives the classic damping that is zero
  away from singularities and grows as the smallest singular value falls below a threshold;
* both take ``joint_weights`` (minimise ``qd^T W_q qd`` instead of ``|qd|^2``) and
  ``task_weights`` (``W_x``-weighted task error), each a positive vector (diagonal weights) or a
  symmetric positive-definite matrix;
* :func:`null_space_velocity`: a primary task plus a secondary joint velocity projected into the
  primary task's null space, ``qd = J^# v + (I - J^# J) qd_0``;
* :func:`resolved_rate_control`: follow a Cartesian path of poses with ``lax.scan`` (jitted),
  ``qd = J^#(q) (V_d + K e)``, and report the tracking error at every step.

The kernels work on one Jacobian and one ``v``; batch with ``jax.vmap``. Values and gradients are
finite everywhere for ``lambda > 0``; :func:`pinv_velocity` is differentiable where the rank does
not change (JAX's ``pinv`` rule).

Non-finite input (NaN or inf in ``J``, ``v``, weights, damping, tolerances, configurations or
path poses) follows the one policy of :mod:`jaxkin.analysis` ("Non-finite input"): eagerly every
function here raises :class:`~jaxkin.JaxkinError` naming the argument; under ``jit``/``vmap``/
``grad`` its result (per item under ``vmap``) is NaN.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import (
    check_J,
    check_J_and_vector,
    check_path,
    check_q,
    finite_guard,
    is_traced,
    refuse_multi_dof,
    result_dtype,
)
from ._jacobian_pass import jacobian_pass
from ._jit import robot_jit
from .errors import JaxkinError, ShapeError
from .model import Robot
from .pose_errors import pose_error
from .spatial import safe_norm, safe_sqrt

__all__ = [
    "ResolvedRateResult",
    "adaptive_damping",
    "damped_least_squares",
    "null_space_projector",
    "null_space_velocity",
    "pinv_velocity",
    "pose_error",
    "resolved_rate_control",
]


# ----------------------------------------------------------------------------- validation
def _weight_factor(W: Any, n: int, what: str, fn: str, dtype):
    """``L`` with ``W = L L^T`` (lower Cholesky factor), or the sqrt of a diagonal; None if W is
    None. Returns ("diag", sqrt_w) or ("full", L)."""
    if W is None:
        return None
    shape = getattr(W, "shape", None)
    if shape is None:
        W = np.asarray(W, dtype=float)
        shape = W.shape
    W = jnp.asarray(W, dtype=dtype)
    if tuple(shape) == (n,):
        return "diag", jnp.sqrt(W)
    if tuple(shape) == (n, n):
        return "full", jnp.linalg.cholesky(W)
    raise ShapeError(
        f"{fn}: {what} must be a vector ({n},) of positive weights or a ({n}, {n}) symmetric "
        f"positive-definite matrix, got shape {tuple(shape)}."
    )


def _apply_weights(J, v, Wx, Wq):
    """Transform to the unweighted problem: J~ = Lx^T J Lq^-T, v~ = Lx^T v (see module doc).

    Minimising ``|J qd - v|^2_{W_x} + lambda^2 |qd|^2_{W_q}`` with ``W = L L^T`` equals the plain
    problem in ``y = Lq^T qd``; returns (J~, v~, back) with ``qd = back(y)``.
    """
    if Wx is not None:
        kind, L = Wx
        if kind == "diag":
            J, v = L[:, None] * J, L * v
        else:
            J, v = L.T @ J, L.T @ v
    back = lambda y: y  # noqa: E731
    if Wq is not None:
        kind, L = Wq
        if kind == "diag":
            J = J / L[None, :]
            back = lambda y: y / L  # noqa: E731
        else:
            # J Lq^-T: solve Lq X = J^T -> X = Lq^-1 J^T, J~ = X^T
            J = jax.scipy.linalg.solve_triangular(L, J.T, lower=True).T
            back = lambda y: jax.scipy.linalg.solve_triangular(L.T, y, lower=False)  # noqa: E731
    return J, v, back


# ----------------------------------------------------------------------------- pseudo-inverse
def pinv_velocity(
    J: Any,
    v: Any,
    *,
    rcond: float,
    joint_weights: Any = None,
    task_weights: Any = None,
) -> jax.Array:
    """``qd = J^+ v`` (dof,): the minimum-norm least-squares joint velocity for twist ``v`` (m,).

    Singular values below ``rcond * sigma_max`` are treated as zero (required: e.g. ``1e-6``;
    too small a cut lets ``|qd|`` explode near singularities, use :func:`damped_least_squares`
    there). With ``joint_weights`` ``W_q`` the solution minimises ``qd^T W_q qd`` among the
    ``W_x``-weighted least-squares solutions (``task_weights``); weights are positive vectors or
    SPD matrices. ``v`` is in the Jacobian's reference and row order (``[v; omega]``).
    Non-finite input: module doc (raises eagerly; NaN under a trace).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q = jnp.array([0.0, jnp.pi / 2])
    >>> J = jk.geometric_jacobian(robot, q)[:2]  # (v_x, v_y) rows
    >>> qd = jk.pinv_velocity(J, jnp.array([0.0, 1.0]), rcond=1e-6)  # the tip up at 1 m/s
    >>> qd.round(6).tolist(), (J @ qd).round(6).tolist()
    ([1.0, -1.0], [0.0, 1.0])
    """
    fn = "jk.pinv_velocity"
    hint = f"jax.vmap(lambda J, v: {fn}(J, v, rcond=rcond))(Js, vs)"
    J, v = check_J_and_vector(J, v, fn, batch_hint=hint)
    Wx = _weight_factor(task_weights, J.shape[0], "task_weights", fn, J.dtype)
    Wq = _weight_factor(joint_weights, J.shape[1], "joint_weights", fn, J.dtype)
    guard = finite_guard(
        fn, J=J, v=v, rcond=rcond, joint_weights=joint_weights, task_weights=task_weights
    )
    J, v = guard.clean(J), guard.clean(v)
    Jt, vt, back = _apply_weights(J, v, Wx, Wq)
    return guard(back(jnp.linalg.pinv(Jt, rtol=rcond) @ vt))


# ----------------------------------------------------------------------------- damped
def _dls_solve(J: jax.Array, v: jax.Array, lam2: jax.Array) -> jax.Array:
    """``J^T (J J^T + lam2 I)^-1 v`` via the smaller of the two equivalent SPD systems."""
    m, n = J.shape
    if m <= n:
        A = J @ J.T + lam2 * jnp.eye(m, dtype=J.dtype)
        return J.T @ _spd_solve(A, v)
    A = J.T @ J + lam2 * jnp.eye(n, dtype=J.dtype)
    return _spd_solve(A, J.T @ v)


def _spd_solve(A: jax.Array, b: jax.Array) -> jax.Array:
    return jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(A), True), b)


def damped_least_squares(
    J: Any,
    v: Any,
    *,
    damping: Any,
    joint_weights: Any = None,
    task_weights: Any = None,
) -> jax.Array:
    """Damped least squares ``qd = J^T (J J^T + lambda^2 I)^-1 v`` (dof,); ``lambda = damping``.

    Minimises ``|J qd - v|^2 + lambda^2 |qd|^2`` (with weights: ``|J qd - v|^2_{W_x} +
    lambda^2 qd^T W_q qd``). For ``lambda > 0`` it is defined and smooth for every J, singular
    included, and ``|qd| <= |v| / (2 lambda)`` (unweighted; checked as a hypothesis property).
    ``damping`` is in the units of J's singular values (m/s per rad/s for translational rows) and
    may be an array (e.g. from :func:`adaptive_damping`, or traced); ``damping = 0`` is the
    pseudo-inverse for a full-rank J and not defined at a singularity.

    Args:
      J: (m, dof) Jacobian (rows ``[v; omega]`` for a geometric one).
      v: (m,) desired task velocity in J's reference.
      damping: lambda >= 0, scalar.
      joint_weights, task_weights: positive vectors or SPD matrices (see the module doc).

    Non-finite input: module doc (raises eagerly; NaN under a trace).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, 1e-4]))[:2]  # nearly stretched out
    >>> v = jnp.array([1.0, 0.0])  # along the arm: out of reach
    >>> float(jnp.abs(jk.pinv_velocity(J, v, rcond=1e-12)).max()) > 1e3
    True
    >>> float(jnp.abs(jk.damped_least_squares(J, v, damping=0.1)).max()) < 10
    True
    """
    fn = "jk.damped_least_squares"
    hint = f"jax.vmap(lambda J, v: {fn}(J, v, damping=damping))(Js, vs)"
    J, v = check_J_and_vector(J, v, fn, batch_hint=hint)
    lam = jnp.asarray(damping, dtype=J.dtype)
    if lam.shape != ():
        raise ShapeError(f"{fn}: damping must be a scalar, got shape {lam.shape}.")
    Wx = _weight_factor(task_weights, J.shape[0], "task_weights", fn, J.dtype)
    Wq = _weight_factor(joint_weights, J.shape[1], "joint_weights", fn, J.dtype)
    guard = finite_guard(
        fn, J=J, v=v, damping=lam, joint_weights=joint_weights, task_weights=task_weights
    )
    J, v = guard.clean(J), guard.clean(v)
    if not is_traced(lam) and not float(lam) >= 0.0:
        raise JaxkinError(f"{fn}: damping must be >= 0, got {float(lam)}.")
    Jt, vt, back = _apply_weights(J, v, Wx, Wq)
    return guard(back(_dls_solve(Jt, vt, lam * lam)))


def adaptive_damping(J: Any, *, max_damping: float, threshold: float) -> jax.Array:
    """Singularity-adaptive damping (Nakamura & Hanafusa 1986; Chiaverini 1997); scalar.

    ``lambda = 0`` while the smallest singular value ``sigma_min`` of J (over its m rows) is at
    least ``threshold``, and ``lambda^2 = max_damping^2 (1 - (sigma_min / threshold)^2)`` below it,
    reaching ``max_damping`` at the singularity. Use it as
    ``damped_least_squares(J, v, damping=adaptive_damping(J, max_damping=0.05, threshold=0.1))``;
    then ``|qd| <= |v| * min(1 / sigma_min, 1 / (2 lambda))`` (exact solution away from
    singularities, bounded near them). Non-finite input: module doc (raises eagerly; NaN under a
    trace).
    """
    fn = "jk.adaptive_damping"
    hint = f"jax.vmap(lambda J: {fn}(J, max_damping=max_damping, threshold=threshold))(Js)"
    J = check_J(J, fn, batch_hint=hint)
    guard = finite_guard(fn, J=J, max_damping=max_damping, threshold=threshold)
    J = guard.clean(J)
    if not threshold > 0 or not max_damping >= 0:
        raise JaxkinError(
            "jk.adaptive_damping: threshold must be > 0 and max_damping >= 0, got "
            f"threshold={threshold}, max_damping={max_damping}."
        )
    m, n = J.shape
    s = jnp.linalg.svd(J, compute_uv=False)
    smin = s[-1] if m <= n else jnp.zeros((), J.dtype)
    ratio = jnp.minimum(smin / threshold, 1.0)
    lam2 = max_damping**2 * (1.0 - ratio * ratio)
    return guard(safe_sqrt(lam2))


# ----------------------------------------------------------------------------- null space
def _generalised_inverse(J, rcond, damping, fn):
    if (rcond is None) == (damping is None):
        raise JaxkinError(
            f"{fn}: give exactly one of rcond= (pseudo-inverse) or damping= (damped least "
            f"squares), got rcond={rcond!r}, damping={damping!r}."
        )
    if rcond is not None:
        return jnp.linalg.pinv(J, rtol=rcond)
    m, n = J.shape
    lam = jnp.asarray(damping, dtype=J.dtype)
    if m <= n:
        A = J @ J.T + lam * lam * jnp.eye(m, dtype=J.dtype)
        return J.T @ _spd_solve(A, jnp.eye(m, dtype=J.dtype))
    A = J.T @ J + lam * lam * jnp.eye(n, dtype=J.dtype)
    return _spd_solve(A, J.T)


def null_space_projector(J: Any, *, rcond: float | None = None, damping: Any = None) -> jax.Array:
    """``N = I - J^# J`` (dof, dof): joint velocities ``N qd_0`` leave ``J qd`` unchanged.

    ``J^#`` is the pseudo-inverse (``rcond=``, then N is the orthogonal projector onto the null
    space: ``J N = 0``, ``N^2 = N``) or the damped inverse (``damping=``: ``J N = O(lambda^2)``,
    not exactly a projector, but smooth through singularities). Give exactly one. Non-finite
    input: module doc (raises eagerly; NaN under a trace).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))[5:]  # omega_z only
    >>> N = jk.null_space_projector(J, rcond=1e-6)
    >>> (N @ jnp.array([1.0, 0.0])).round(6).tolist()  # the part of qd that keeps omega_z
    [0.5, -0.5]
    >>> (J @ N).round(6).tolist()
    [[0.0, 0.0]]
    """
    fn = "jk.null_space_projector"
    how = "rcond=rcond" if damping is None else "damping=damping"
    J = check_J(J, fn, batch_hint=f"jax.vmap(lambda J: {fn}(J, {how}))(Js)")
    guard = finite_guard(fn, J=J, rcond=rcond, damping=damping)
    J = guard.clean(J)
    Jp = _generalised_inverse(J, rcond, damping, fn)
    return guard(jnp.eye(J.shape[1], dtype=J.dtype) - Jp @ J)


def null_space_velocity(
    J: Any,
    v: Any,
    qd_secondary: Any,
    *,
    rcond: float | None = None,
    damping: Any = None,
) -> jax.Array:
    """Primary task plus a secondary motion in its null space (Liegeois 1977); (dof,).

    ``qd = J^# v + (I - J^# J) qd_secondary``: the primary twist ``v`` (m,) is tracked as by
    :func:`pinv_velocity` (``rcond=``) or :func:`damped_least_squares` (``damping=``); of the
    secondary joint velocity ``qd_secondary`` (dof,) (e.g. ``k * manipulability_gradient`` or a
    joint-limit avoidance gradient) only the part that does not disturb the task is added.
    Non-finite input: module doc (raises eagerly; NaN under a trace).
    """
    fn = "jk.null_space_velocity"
    how = "rcond=rcond" if damping is None else "damping=damping"
    hint = f"jax.vmap(lambda J, v: {fn}(J, v, qd_secondary, {how}))(Js, vs)"
    J, v = check_J_and_vector(J, v, fn, batch_hint=hint)
    qd0 = jnp.asarray(qd_secondary, dtype=J.dtype)
    if qd0.shape != (J.shape[1],):
        raise ShapeError(
            f"{fn}: qd_secondary must have shape ({J.shape[1]},) (one per joint), got {qd0.shape}."
        )
    guard = finite_guard(fn, J=J, v=v, qd_secondary=qd0, rcond=rcond, damping=damping)
    J, v, qd0 = guard.clean(J), guard.clean(v), guard.clean(qd0)
    Jp = _generalised_inverse(J, rcond, damping, fn)
    return guard(Jp @ v + qd0 - Jp @ (J @ qd0))


# ----------------------------------------------------------------------------- resolved rate
class ResolvedRateResult(NamedTuple):
    """Output of :func:`resolved_rate_control` for a path of N poses.

    ``q`` (N + 1, dof): joint values, ``q[0] = q0``, ``q[k + 1]`` after step k; ``qd`` (N, dof):
    the commanded joint velocities; ``position_error`` (N,) metres and ``orientation_error`` (N,)
    radians: the error of the pose reached after step k against the desired pose ``k``
    (``|p_d - p|`` and the angle of ``R_d R^T``); ``max_position_error`` and
    ``max_orientation_error``: their maxima.
    """

    q: jax.Array
    qd: jax.Array
    position_error: jax.Array
    orientation_error: jax.Array
    max_position_error: jax.Array
    max_orientation_error: jax.Array


def _path_twists(Ts: jax.Array, dt: jax.Array) -> jax.Array:
    """Feed-forward twists (N, 6) (world axes, at the frame origin) from successive poses."""

    def one(Ta, Tb):
        return pose_error(Ta, Tb) / dt

    V = jax.vmap(one)(Ts[:-1], Ts[1:])
    return jnp.concatenate([V, jnp.zeros_like(V[:1])], axis=0)  # hold the last pose


def _resolved_rate_impl(robot, q0, Ts, Vs, dt, gain, damping, *, frame, rcond, clip_to_limits):
    dtype = q0.dtype
    lo = robot.lower.astype(dtype)
    hi = robot.upper.astype(dtype)

    if Vs is None:
        Vs = _path_twists(Ts, dt)

    def pose(q):
        return jacobian_pass(robot, q, frame, None, "world_aligned")  # J and pose: one pass

    def step(q, x):
        Td, Vd = x
        g = pose(q)
        J = g.matrix()
        e = pose_error(g.pose(), Td)  # also the error of the pose reached by the step before
        V = Vd + gain * e
        if rcond is None:
            qd = _dls_solve(J, V, damping * damping)
        else:
            qd = jnp.linalg.pinv(J, rtol=rcond) @ V
        q_next = q + dt * qd
        if clip_to_limits:
            q_next = jnp.clip(q_next, lo, hi)
        return q_next, (q_next, qd, safe_norm(e[:3]), safe_norm(e[3:]))

    q_end, (qs, qds, ep, eo) = jax.lax.scan(step, q0, (Ts, Vs))
    # errors after step k: of q_{k+1} against T_path[k + 1] (the last pose for the last step);
    # the scan measured q_k against T_path[k], so shift by one and measure q_N once more
    e_end = pose_error(pose(q_end).pose(), Ts[-1])
    ep = jnp.concatenate([ep[1:], safe_norm(e_end[:3])[None]])
    eo = jnp.concatenate([eo[1:], safe_norm(e_end[3:])[None]])
    q = jnp.concatenate([q0[None], qs], axis=0)
    return ResolvedRateResult(q, qds, ep, eo, jnp.max(ep), jnp.max(eo))


_resolved_rate = robot_jit(_resolved_rate_impl, ("frame", "rcond", "clip_to_limits"))


def resolved_rate_control(
    robot: Robot,
    q0: Any,
    T_path: Any,
    dt: float,
    *,
    twists: Any = None,
    gain: float = 1.0 / 0.05,
    damping: float | None = 1e-3,
    rcond: float | None = None,
    frame: int | str | None = None,
    clip_to_limits: bool = True,
) -> ResolvedRateResult:
    """Resolved-rate motion control along a Cartesian path (Whitney 1969), jitted ``lax.scan``.

    At step ``k`` (time ``k dt``) with the robot at ``q_k``: the error ``e_k = pose_error(
    fk(q_k), T_path[k])`` (world axes), the command ``V = twists[k] + gain * e_k``, the joint
    velocity ``qd_k = J(q_k)^# V`` (damped least squares with ``damping``, or the pseudo-inverse
    with ``rcond`` when ``damping=None``), and ``q_{k+1} = q_k + dt qd_k`` (explicit Euler,
    clipped to finite joint limits unless ``clip_to_limits=False``; continuous joints are never
    clipped). The error is then measured between ``fk(q_{k+1})`` and ``T_path[k + 1]`` (the last
    pose for the last step).

    Args:
      robot: the robot; ``frame`` (default: the tip) is the controlled frame.
      q0: (dof,) start configuration.
      T_path: (N, 4, 4) desired poses ``T_world_frame`` at times ``0, dt, ..., (N-1) dt``.
      dt: the control period in seconds.
      twists: optional (N, 6) feed-forward twists ``[v; omega]`` (world axes, frame origin);
        default: from successive poses, ``pose_error(T_path[k], T_path[k+1]) / dt``, and zero
        for the last pose (the path ends there).
      gain: feedback gain in 1/s (default 20 = 1 / 0.05 s); ``gain * dt`` must be below 2 for a
        stable discrete loop, 1 being dead-beat.
      damping, rcond: the inverse used (see :func:`damped_least_squares`, :func:`pinv_velocity`).

    Returns a :class:`ResolvedRateResult` with the joint trajectory and the tracking errors.
    Non-finite input (``q0``, ``T_path``, ``twists``, ``dt``, ``gain``, ``damping``, ``rcond``):
    module doc (raises eagerly; every field NaN under a trace).
    """
    fn = "jk.resolved_rate_control"
    hint = f"jax.vmap(lambda q0: {fn}(robot, q0, T_path, dt))(q0s), one run per start"
    refuse_multi_dof(robot, fn, "integrates q + qd dt in a vector space")
    q0 = check_q(robot, q0, what="q0", fn=fn, batch_hint=hint)
    dtype = result_dtype(robot, q0)
    Ts = check_path(jnp.asarray(T_path, dtype=dtype), "T_path", fn)
    if not (isinstance(dt, (int, float)) and dt > 0):
        raise JaxkinError(f"{fn}: dt must be a positive number of seconds, got {dt!r}.")
    if damping is None and rcond is None:
        raise JaxkinError(f"{fn}: give damping= (damped least squares) or rcond= (pinv).")
    if damping is not None and rcond is not None:
        raise JaxkinError(f"{fn}: give either damping= or rcond=, not both.")
    dt_a = jnp.asarray(dt, dtype=dtype)
    if twists is None:
        Vs = None  # from the path, inside the jitted loop
    else:
        Vs = jnp.asarray(twists, dtype=dtype)
        if Vs.shape != (Ts.shape[0], 6):
            raise ShapeError(f"{fn}: twists must have shape ({Ts.shape[0]}, 6), got {Vs.shape}.")
    f = robot.frame_index(frame)
    guard = finite_guard(
        fn, q0=q0, T_path=Ts, twists=Vs, dt=dt, gain=gain, damping=damping, rcond=rcond
    )
    out = _resolved_rate(
        robot,
        guard.clean(q0.astype(dtype)),
        guard.clean(Ts),
        None if Vs is None else guard.clean(Vs),
        dt_a,
        jnp.asarray(gain, dtype=dtype),
        jnp.asarray(0.0 if damping is None else damping, dtype=dtype),
        frame=f,
        rcond=None if rcond is None else float(rcond),
        clip_to_limits=clip_to_limits,
    )
    return guard(out)
