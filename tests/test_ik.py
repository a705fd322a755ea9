"""Inverse kinematics: round trips q* -> fk -> solve_ik -> fk, result codes, throw=, limits.

The check of a solution is independent of the solver: numpy on ``jk.fk``'s pose, position error
``|p - p*|`` and the rotation angle of ``R* R^T`` (from its trace and skew part), both <= 1e-9
(tests/README.md: converged IK pose, float64), and the joints within their limits.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sampling import sample_configurations
from _xla import FAST_COMPILE

import jaxkin as jk
from jaxkin.ik import RESULTS

N_TARGETS = 300
SEEDS = jk.ik.DEFAULT_NUM_SEEDS


def _pose_errors(T: np.ndarray, T_target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    dp = np.linalg.norm(T[..., :3, 3] - T_target[..., :3, 3], axis=-1)
    M = T_target[..., :3, :3] @ np.swapaxes(T[..., :3, :3], -1, -2)
    s = 0.5 * np.linalg.norm(
        np.stack(
            [M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]],
            -1,
        ),
        axis=-1,
    )
    c = 0.5 * (np.trace(M, axis1=-2, axis2=-1) - 1.0)
    return dp, np.arctan2(s, c)


_fk_batch = jax.jit(jax.vmap(jk.fk, in_axes=(None, 0)), static_argnums=0)


def _solve(robot, T, q0, **kw):
    """``jk.solve_ik(robot, T, q0, throw=False, **kw)`` inside a jit compiled with the tests'
    FAST_COMPILE options (the same operations, no fast-math; a UR5 build of 16 targets, cold,
    with the suite's XLA flags: 2.8-3.1 CPU s against 2.9-3.3 with the solver's own options, the
    same within noise): for the tests of what the solver finds, not of how it is
    compiled (the eager entry point, its cache and throw=True are tested on their own below).
    ``key`` and ``seeds`` are arguments of the jit, the other options part of its key."""
    arrays = sorted(k for k in ("key", "seeds") if k in kw)
    static = tuple(sorted((k, v) for k, v in kw.items() if k not in arrays))
    return _fast_solver(robot, static, tuple(arrays))(T, q0, *(kw[k] for k in arrays))


@functools.cache
def _fast_solver(robot, static, names):
    def run(T, q0, *arrays):
        kw = dict(static) | dict(zip(names, arrays, strict=True))
        return jk.solve_ik(robot, T, q0, throw=False, **kw)

    return jax.jit(run, compiler_options=FAST_COMPILE)


@pytest.mark.parametrize("name", ["panda", "ur5", "niryo_one"])
def test_round_trip_random_reachable_targets(name):
    robot = jk.robots.load(name, dtype=np.float64)
    q_star = sample_configurations(robot, N_TARGETS, 1)
    q0 = sample_configurations(robot, N_TARGETS, 2)  # a random start, not the answer
    T_target = np.asarray(_fk_batch(robot, jnp.asarray(q_star)))
    # Default starts, on one lane: the answer does not depend on the lanes (test_ik_defaults.py
    # checks it, and runs the default lanes on five arms), and a one-lane solver compiles in
    # about two thirds of the time of a 64-lane one.
    sol = _solve(robot, T_target, q0, key=jax.random.key(3), lanes=1)
    sol = jax.tree_util.tree_map(np.asarray, sol)
    ok = sol.converged
    assert ok.mean() >= 0.99, (name, ok.mean(), np.bincount(sol.result))
    # independent check of every converged solution
    dp, dw = _pose_errors(np.asarray(_fk_batch(robot, jnp.asarray(sol.q))), T_target)
    assert np.all(dp[ok] <= 1e-9) and np.all(dw[ok] <= 1e-9), (dp[ok].max(), dw[ok].max())
    np.testing.assert_allclose(sol.position_error, dp, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(sol.orientation_error, dw, rtol=1e-6, atol=1e-14)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    assert np.all((sol.q >= lo) & (sol.q <= hi))
    assert np.all(sol.result[ok] == RESULTS.converged)
    assert np.all(np.isin(sol.result[~ok], [RESULTS.max_steps_reached, RESULTS.stalled]))
    assert np.all(np.isfinite(sol.q)) and np.all(np.isfinite(sol.residual))
    assert np.all((sol.seed >= 0) & (sol.seed < SEEDS))


@pytest.fixture(scope="module")
def ur5():
    return jk.robots.load("ur5", dtype=np.float64)


def test_started_at_the_solution_takes_no_step(ur5):
    q_star = np.array([0.3, -1.1, 1.2, -0.4, 0.9, 0.2])
    T = jk.fk(ur5, q_star)
    sol = jk.solve_ik(ur5, T, q_star)
    assert int(sol.steps) == 0 and bool(sol.converged)
    np.testing.assert_array_equal(np.asarray(sol.q), q_star)
    assert float(sol.residual) <= 1e-14


def test_started_at_a_singular_configuration(ur5):
    q_sing = np.zeros(6)  # q5 = 0: wrist singular (and the shoulder offset aligned)
    assert float(jk.manipulability(jk.geometric_jacobian(ur5, q_sing))) < 1e-12
    T = jk.fk(ur5, np.array([0.3, -1.1, 1.2, -0.4, 0.9, 0.2]))
    sol = jk.solve_ik(ur5, T, q_sing)
    assert bool(sol.converged) and np.all(np.isfinite(np.asarray(sol.q)))
    # and a target that is itself singular (q5 = 0), from elsewhere
    T_sing = jk.fk(ur5, np.array([0.3, -1.1, 1.2, -0.4, 0.0, 0.2]))
    sol = jk.solve_ik(ur5, T_sing, np.array([0.1, -1.0, 1.0, -0.2, 0.3, 0.0]))
    assert bool(sol.converged) and np.all(np.isfinite(np.asarray(sol.q)))


def test_unreachable_target_is_reported_not_looped(ur5):
    T_far = np.eye(4)
    T_far[:3, 3] = [3.0, 0.0, 0.5]  # the UR5 reaches about 0.95 m
    sol = jk.solve_ik(ur5, T_far, np.zeros(6), throw=False)
    assert int(sol.result) == RESULTS.unreachable
    assert int(sol.steps) == 0 and not bool(sol.converged)
    assert float(jk.ik.reach_bound(ur5)) < 3.0
    with pytest.raises(jk.IKError, match="unreachable"):
        jk.solve_ik(ur5, T_far, np.zeros(6))
    with pytest.raises(jk.IKError, match="throw=False"):
        jk.solve_ik(ur5, T_far, np.zeros(6), throw=True)


def test_unreachable_inside_the_callers_jit_and_vmap():
    """Codes with throw=False, a runtime error with throw=True. (A two-link arm: the solver is
    traced into the caller's program, a compile each, and any robot shows it.)"""
    planar = jk.robots.load("two_link_planar", dtype=np.float64)
    T_far = np.eye(4)
    T_far[:3, 3] = [3.0, 0.0, 0.0]  # the arm reaches 2 m
    assert float(jk.ik.reach_bound(planar)) < 3.0
    T_ok = jk.fk(planar, np.array([0.3, -0.5]))
    solve = jax.vmap(lambda T: jk.solve_ik(planar, T, jnp.zeros(2), throw=False).result)
    codes = jax.jit(solve, compiler_options=FAST_COMPILE)(jnp.stack([T_ok, jnp.asarray(T_far)]))
    np.testing.assert_array_equal(np.asarray(codes), [RESULTS.converged, RESULTS.unreachable])
    with pytest.raises(Exception, match="target unreachable"):
        jax.block_until_ready(
            jax.jit(
                lambda T: jk.solve_ik(planar, T, jnp.zeros(2)).q, compiler_options=FAST_COMPILE
            )(jnp.asarray(T_far))
        )


def test_stalled_when_the_pose_is_outside_the_workspace():
    planar = jk.robots.load("two_link_planar", dtype=np.float64)
    T = np.eye(4)
    T[:3, 3] = [1.0, 0.5, 0.3]  # within reach (2 m) but out of the arm's plane
    jitted = jk.ik._solve_batch.get_jitted()
    sol = jk.solve_ik(planar, T, np.array([0.1, 0.2]), throw=False, max_steps=200, num_seeds=1)
    size = jitted._cache_size()
    assert int(sol.result) == RESULTS.stalled
    assert int(sol.steps) < 200  # gave up early, did not loop to the budget
    # by default every restart stalls too, each well before its budget
    sol = jk.solve_ik(planar, T, np.array([0.1, 0.2]), throw=False, max_steps=200)
    assert jitted._cache_size() == size  # num_seeds is traced: the same solver
    assert int(sol.result) == RESULTS.stalled
    assert int(sol.steps) < jk.ik.DEFAULT_NUM_SEEDS * 200 // 2
    assert np.all(np.isfinite(np.asarray(sol.q)))
    # no configuration gets closer than the 0.3 m out of the arm's plane
    assert float(sol.position_error) >= 0.3 - 1e-12
    assert "stalled" in RESULTS.message(RESULTS.stalled)
    with pytest.raises(jk.IKError, match="stalled"):
        jk.solve_ik(planar, T, np.array([0.1, 0.2]), max_steps=200)


def test_continuous_joints_are_not_clipped_and_limits_hold():
    rows = [
        dict(a=0.4, alpha=0.0, d=0.1, theta=0.0, joint="revolute"),  # continuous
        dict(a=0.3, alpha=math.pi / 2, d=0.0, theta=0.0, joint="revolute", lower=-1, upper=1),
        dict(a=0.2, alpha=0.0, d=0.05, theta=0.0, joint="revolute"),  # continuous
    ]
    robot = jk.Robot.from_dh(rows, name="continuous", dtype=np.float64)
    q_star = np.array([4.0, 0.5, -5.0])  # continuous joints beyond +-pi
    T = np.asarray(jk.fk(robot, q_star))
    # (one lane, as in the round trips: a cheaper compile, the same answers)
    sol = _solve(robot, T[None].repeat(2, 0), np.stack([q_star + 0.05, q_star - 0.05]), lanes=1)
    assert np.all(np.asarray(sol.converged))
    np.testing.assert_allclose(np.asarray(sol.q), np.stack([q_star, q_star]), atol=1e-8)
    # a bounded joint asked past its limit stays at the limit
    T2 = np.asarray(jk.fk(robot, np.array([0.0, 1.4, 0.0])))
    sol = _solve(robot, T2[None].repeat(2, 0), np.zeros((2, 3)), lanes=1)
    assert np.all(np.asarray(sol.q)[:, 1] <= 1.0) and not np.any(np.asarray(sol.converged))


def test_optax_multistart_path():
    robot = jk.robots.load("puma560", dtype=np.float64)
    q_star = sample_configurations(robot, 12, 5)
    T = np.asarray(_fk_batch(robot, jnp.asarray(q_star)))
    q0 = sample_configurations(robot, 12, 6)
    q0[0] = q_star[0]  # started exactly at the solution: zero gradient, not NaN
    sol = _solve(robot, T, q0, method="optax", num_seeds=8, tol=1e-8, max_steps=200, patience=20)
    sol = jax.tree_util.tree_map(np.asarray, sol)
    # (steps counts the updates of all parallel starts; the answer comes from start 0)
    assert sol.seed[0] == 0 and sol.converged[0] and sol.residual[0] <= 1e-14
    np.testing.assert_array_equal(sol.q[0], q_star[0])
    assert np.all(np.isfinite(sol.q))
    # Projected L-BFGS gets caught at joint limits more often than LM (measured: 9 of 12 here;
    # LM reaches >= 99% in the round trips above); the path exists for custom optax losses.
    assert sol.converged.mean() >= 0.6, sol.residual
    dp, dw = _pose_errors(np.asarray(_fk_batch(robot, jnp.asarray(sol.q))), T)
    assert np.all(dp[sol.converged] <= 1e-8) and np.all(dw[sol.converged] <= 1e-8)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    assert np.all((sol.q >= lo) & (sol.q <= hi))


def test_float32():
    robot = jk.robots.load("panda", dtype=np.float32)
    q_star = sample_configurations(robot, 20, 8).astype(np.float32)
    T = np.asarray(_fk_batch(robot, jnp.asarray(q_star)))
    q0 = sample_configurations(robot, 20, 9).astype(np.float32)
    sol = _solve(robot, T, q0, num_seeds=8, lanes=1)  # one lane: see the round trips
    assert sol.q.dtype == jnp.float32
    assert np.mean(np.asarray(sol.converged)) >= 0.95  # default tol 1e-5 in float32
    ok = np.asarray(sol.converged)
    assert np.all(np.asarray(sol.residual)[ok] <= 1e-5)
    # the optax path in float32 (with x64 on: no float64 cotangent may leak into the loss)
    sol = _solve(robot, T[:4], q_star[:4] + 0.05, method="optax", tol=1e-4)
    assert sol.q.dtype == jnp.float32 and np.all(np.asarray(sol.converged))


def test_errors(ur5):
    with pytest.raises(jk.JaxkinError, match="method must be one of"):
        jk.solve_ik(ur5, np.eye(4), np.zeros(6), method="newton")
    with pytest.raises(jk.ShapeError, match=r"\(4, 4\)"):
        jk.solve_ik(ur5, np.eye(3), np.zeros(6))
    with pytest.raises(jk.JaxkinError, match="not a rigid transform"):
        jk.solve_ik(ur5, 2 * np.eye(4), np.zeros(6))
    with pytest.raises(jk.ShapeError, match=r"q0 must have shape \(6,\)"):
        jk.solve_ik(ur5, np.eye(4), np.zeros(5))
    with pytest.raises(jk.JaxkinError, match="num_seeds must be an integer"):
        jk.solve_ik(ur5, np.eye(4), np.zeros(6), num_seeds=0)
    with pytest.raises(jk.JaxkinError, match="NaN"):
        jk.solve_ik(ur5, np.eye(4), np.full(6, np.nan))
    with pytest.raises(jk.ShapeError, match=r"seeds must have shape \(S, 6\)"):
        jk.solve_ik(ur5, np.eye(4), np.zeros(6), seeds=np.zeros((3, 5)))
    with pytest.raises(jk.JaxkinError, match="seeds= or num_seeds="):
        jk.solve_ik(ur5, np.eye(4), np.zeros(6), seeds=np.zeros((3, 6)), num_seeds=4)


def test_new_target_values_and_starts_do_not_recompile(ur5):
    jitted = jk.ik._solve_batch.get_jitted()
    qs = sample_configurations(ur5, 8, 11)
    T = np.stack([np.asarray(jk.fk(ur5, q)) for q in qs])  # the eager fk of the tests above
    # one target (the solver of the tests above, or compiled here: at most once)
    before = jitted._cache_size()
    jk.solve_ik(ur5, T[0], qs[1], throw=False)
    assert jitted._cache_size() <= before + 1
    before = jitted._cache_size()
    for k in range(3):  # new targets, starts, tolerances and numbers of starts: no compile
        jk.solve_ik(ur5, T[k + 1], qs[k + 2], num_seeds=k + 2, tol=1e-10 * (k + 1), throw=False)
    assert jitted._cache_size() == before
    jk.solve_ik(ur5, T[:2], qs[0], num_seeds=2, throw=False)  # a new batch size compiles again
    assert jitted._cache_size() == before + 1


def test_explicit_seeds_are_tried_after_q0(ur5):
    q_star = np.array([0.3, -1.1, 1.2, -0.4, 0.9, 0.2])
    T = np.asarray(jk.fk(ur5, q_star))
    Ts = np.stack([T, T])
    bad = np.array([3.0, 3.0, -3.0, 3.0, -3.0, 3.0])  # far from q_star
    # explicit seeds share the compiled solver of random starts (two targets: compiled at most
    # once here, by the test above in a run of the file)
    jitted = jk.ik._solve_batch.get_jitted()
    jk.solve_ik(ur5, Ts, bad, throw=False)
    size = jitted._cache_size()
    # the same extra starts for every target (S, 6), or one set per target (N, S, 6): q_star is
    # the second start
    for seeds in (np.stack([q_star, bad]), np.stack([[q_star], [q_star]])):
        sol = jk.solve_ik(ur5, Ts, bad, seeds=seeds, max_steps=1, patience=1, throw=False)
        assert np.all(np.asarray(sol.converged)) and np.all(np.asarray(sol.seed) == 1)
    assert jitted._cache_size() == size
