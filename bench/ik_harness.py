"""The inverse-kinematics harness every IK benchmark shares: targets, the judge, the solvers.

:mod:`bench.ik`, :mod:`bench.ik_protocols`, :mod:`bench.ik_gradient` and :mod:`bench.ik_profile`
take their problems, their success criteria and their solver runners from here; each keeps only
its protocol (robots, targets, seeds, tolerances, solver arguments) and its rows.

* Targets: :func:`random_targets` (configurations drawn by ``jk.sample_configurations``, their
  ``jk.fk`` poses), :func:`target_poses`, :func:`sampling_middle` (the start at mid-limits).
* The judge: :class:`Judge` measures every answer with jaxkin's float64 fk against its target:
  position error (metres) and the rotation vector of ``R R_target^T`` (radians), both in base
  axes, the rotation angle, and whether every joint lies within its limits (1e-12 slack). A
  non-finite answer is judged failed (infinite error, not within limits).
  :meth:`Judge.success` is TRAC-IK's criterion (every component at most ``tol``),
  :meth:`Judge.norm_success` the norm criterion (position and angle at most their tolerances).
* Solvers: :func:`run_jaxkin` (one batched ``jk.solve_ik`` call, first call timed apart from
  the median of repeats), :func:`one_target_at_a_time` (a Python-loop peer under a time
  budget), :func:`run_pinocchio` (the DLS loop of Pinocchio's documentation),
  :func:`rtb_solver` (the Robotics Toolbox's ``ikine_LM``), :func:`pk_chain` / :func:`run_pk`
  (pytorch_kinematics' ``PseudoInverseIK``), and :func:`fk_disagreement` (how far a peer's model
  is from jaxkin's fk). Peers are imported on use: a missing one fails only its own runner.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk

from .report import first_and_repeats

# The arms of the gradient and profile benchmarks (bench.ik_protocols has its own, as URDF text).
ROBOTS: dict[str, Callable[[], jk.Robot]] = {
    "panda": lambda: jk.robots.load("erd/panda", tip="panda_hand"),
    "ur5": lambda: jk.robots.load("ur5"),
    "niryo_one": lambda: jk.robots.load("niryo_one"),
}
LIMIT_SLACK = 1e-12  # an answer this far outside a joint limit still counts as within it


# ---------------------------------------------------------------------------- targets
def random_targets(robot: jk.Robot, n: int, key: Any) -> tuple[jax.Array, jax.Array]:
    """``(qs, T)``: ``n`` configurations drawn with ``key`` and their poses (eager ``vmap``)."""
    qs = jk.sample_configurations(robot, n, key)
    return qs, jax.vmap(lambda q: jk.fk(robot, q))(qs)


def target_poses(robot: jk.Robot, qs: np.ndarray) -> np.ndarray:
    """The (N, 4, 4) poses of configurations ``qs`` (jitted ``vmap`` of ``jk.fk``), as NumPy."""
    return np.asarray(jax.jit(jax.vmap(lambda q: jk.fk(robot, q)))(jnp.asarray(qs)))


def sampling_middle(robot: jk.Robot) -> jax.Array:
    """The middle of ``jk.sampling_bounds`` (0 for an unbounded joint): the one start."""
    lo, hi = jk.sampling_bounds(robot)
    return jnp.asarray(0.5 * (np.asarray(lo) + np.asarray(hi)))


# ---------------------------------------------------------------------------- judge
class PoseErrors(NamedTuple):
    """Per answer: ``position`` (n, 3) and ``rotation`` (n, 3, the rotation vector of
    ``R R_target^T``) in base axes, ``angle`` (n,) of that rotation, ``within`` (n,) limits."""

    position: np.ndarray
    rotation: np.ndarray
    angle: np.ndarray
    within: np.ndarray


class Judge:
    """Answers judged against targets ``Ts`` with jaxkin's float64 fk (module doc)."""

    def __init__(self, robot: jk.Robot, Ts: np.ndarray):
        self.robot = robot
        self.Ts = Ts
        self._fk = jax.jit(jax.vmap(lambda q: jk.fk(robot, q)))
        self.lo = np.asarray(robot.lower)
        self.hi = np.asarray(robot.upper)

    def errors(self, qs: np.ndarray) -> PoseErrors:
        """The errors of answers ``qs`` (n, dof) to the first n targets; inf where not finite."""
        qs = np.asarray(qs, dtype=np.float64)
        Ts = self.Ts[: len(qs)]
        finite = np.all(np.isfinite(qs), axis=1)
        T = np.asarray(self._fk(jnp.asarray(np.where(finite[:, None], qs, 0.0))))
        dp = T[:, :3, 3] - Ts[:, :3, 3]
        M = T[:, :3, :3] @ np.swapaxes(Ts[:, :3, :3], 1, 2)
        v = 0.5 * np.stack(
            [M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0], M[:, 1, 0] - M[:, 0, 1]], 1
        )
        s = np.linalg.norm(v, axis=1)
        angle = np.arctan2(s, 0.5 * (np.trace(M, axis1=1, axis2=2) - 1))
        scale = np.where(s > 1e-300, angle / np.maximum(s, 1e-300), 1.0)
        dw = v * scale[:, None]
        for a in (dp, dw, angle):
            a[~finite] = np.inf
        slack = (qs >= self.lo - LIMIT_SLACK) & (qs <= self.hi + LIMIT_SLACK)
        within = finite & np.all(slack, axis=1)
        return PoseErrors(dp, dw, angle, within)

    def success(self, qs: np.ndarray, tol: float) -> np.ndarray:
        """Within the limits and every pose-error component at most ``tol`` (TRAC-IK's)."""
        e = self.errors(qs)
        err = np.abs(np.concatenate([e.position, e.rotation], 1))
        return e.within & np.all(err <= tol, axis=1)

    def norm_success(self, qs: np.ndarray, position: float, rotation: float) -> np.ndarray:
        """Within the limits, position error at most ``position`` (m) and rotation angle at
        most ``rotation`` (rad)."""
        e = self.errors(qs)
        return e.within & (np.linalg.norm(e.position, axis=1) <= position) & (e.angle <= rotation)


# ---------------------------------------------------------------------------- solvers
def run_jaxkin(robot: jk.Robot, Ts, q0, repeats: int, **kw) -> dict[str, Any]:
    """``jk.solve_ik(robot, Ts, q0=q0, throw=False, **kw)``, every target in one call: ``q``,
    ``own_converged`` (share of the solver's own flag) and :func:`first_and_repeats`' times."""

    def solve():
        return jax.block_until_ready(jk.solve_ik(robot, Ts, q0=q0, throw=False, **kw))

    timing = first_and_repeats(solve, repeats)
    sol = timing.pop("result")
    return dict(
        q=np.asarray(sol.q), own_converged=float(np.mean(np.asarray(sol.converged))), **timing
    )


Solve = Callable[[int, np.ndarray], tuple[np.ndarray, bool]]


def one_target_at_a_time(Ts: np.ndarray, dof: int, solve: Solve, budget_s: float) -> dict[str, Any]:
    """``solve(k, T) -> (q, own success flag)`` for each target ``Ts[k]`` in turn, until the
    targets or ``budget_s`` run out: ``q`` (NaN where not measured), ``own_converged`` over the
    measured targets, ``total_s`` extrapolated to every target and ``measured_targets``."""
    qs = np.full((len(Ts), dof), np.nan)
    own = np.zeros(len(Ts), bool)
    t0 = time.perf_counter()
    done = 0
    for k, T in enumerate(Ts):
        qs[k], own[k] = solve(k, T)
        done = k + 1
        if time.perf_counter() - t0 > budget_s:
            break
    elapsed = time.perf_counter() - t0
    return dict(
        q=qs,
        own_converged=float(own[:done].mean()),
        total_s=elapsed * len(Ts) / done,
        measured_targets=done,
    )


def run_pinocchio(model, fid, Ts, seeds, lo, hi, time_budget_s: float) -> dict[str, Any]:
    """The documentation example's loop (frame version), eps 1e-10, next start on failure:
    :func:`one_target_at_a_time`'s result and the total ``iterations``."""
    import pinocchio as pin

    data = model.createData()
    eps, it_max, dt, damp = 1e-10, 1000, 1e-1, 1e-12
    iterations = 0

    def dls(oMdes, q_start: np.ndarray) -> tuple[np.ndarray, bool]:
        nonlocal iterations
        q = q_start.copy()
        for _ in range(it_max):
            pin.framesForwardKinematics(model, data, q)
            iMd = data.oMf[fid].actInv(oMdes)
            err = pin.log(iMd).vector
            if np.linalg.norm(err) < eps:
                return q, True
            J = pin.computeFrameJacobian(model, data, q, fid)  # LOCAL
            J = -np.dot(pin.Jlog6(iMd.inverse()), J)
            v = -J.T.dot(np.linalg.solve(J.dot(J.T) + damp * np.eye(6), err))
            q = pin.integrate(model, q, v * dt)
            iterations += 1
        return q, False

    def solve(k: int, T: np.ndarray) -> tuple[np.ndarray, bool]:
        oMdes = pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())
        for q_start in seeds:
            q, success = dls(oMdes, q_start)
            if success and np.all((q >= lo) & (q <= hi)):
                return q, True
        return q, False

    out = one_target_at_a_time(Ts, model.nq, solve, time_budget_s)
    return dict(**out, iterations=iterations)


def rtb_solver(ets, **ikine_lm) -> Solve:
    """The Robotics Toolbox's ``ets.ikine_LM(T, **ikine_lm)`` as a :func:`one_target_at_a_time`
    solve: its answer and its own success flag."""

    def solve(k: int, T: np.ndarray) -> tuple[np.ndarray, bool]:
        sol = ets.ikine_LM(T, **ikine_lm)
        return sol.q, bool(sol.success)

    return solve


def pk_chain(urdf: str, tip: str):
    """The float64 pytorch_kinematics serial chain of ``urdf`` to the link ``tip``."""
    import pytorch_kinematics as pk
    import torch

    chain = pk.build_serial_chain_from_urdf(urdf.encode(), end_link_name=tip)
    return chain.to(dtype=torch.float64)


def run_pk(chain, Ts, seeds, lo, hi, *, max_iterations: int, tol: float) -> dict[str, Any]:
    """pytorch_kinematics' ``PseudoInverseIK`` (``retry_configs=seeds``, position and rotation
    tolerance ``tol``, ``early_stopping_any_converged``, joint limits ``lo``/``hi``), every target
    in one call: per target the first converged start's answer, else the smallest error's;
    ``own_converged`` and ``total_s``."""
    import pytorch_kinematics as pk
    import torch

    ik = pk.PseudoInverseIK(
        chain,
        retry_configs=torch.tensor(seeds, dtype=torch.float64),
        joint_limits=torch.tensor(np.stack([lo, hi], 1), dtype=torch.float64),
        max_iterations=max_iterations,
        pos_tolerance=tol,
        rot_tolerance=tol,
        early_stopping_any_converged=True,
    )
    target = pk.Transform3d(matrix=torch.tensor(Ts, dtype=torch.float64))
    t0 = time.perf_counter()
    sol = ik.solve(target)
    elapsed = time.perf_counter() - t0
    conv = sol.converged.numpy()
    err = (sol.err_pos + sol.err_rot).numpy()
    pick = np.where(conv.any(1), conv.argmax(1), err.argmin(1))
    q = sol.solutions.numpy()[np.arange(len(Ts)), pick]
    return dict(q=q, own_converged=float(conv.any(1).mean()), total_s=elapsed)


# ---------------------------------------------------------------------------- checks
def fk_disagreement(robot: jk.Robot, qs: np.ndarray, poses: np.ndarray) -> float:
    """Largest absolute difference of a peer's (N, 4, 4) ``poses`` of ``qs`` from jaxkin's fk."""
    reference = np.asarray(jax.vmap(lambda q: jk.fk(robot, q))(jnp.asarray(qs)))
    return float(np.abs(np.asarray(poses) - reference).max())
