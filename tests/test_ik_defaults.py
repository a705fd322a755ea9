"""``jk.solve_ik`` with default arguments reaches what a TRAC-IK user expects, and its caches are
keyed by the robot's value.

TRAC-IK, from one user seed with internal random restarts, solves 99.7% of random reachable Panda
targets at 1e-5. Here: 200 random reachable targets (random configurations within the limits,
then ``jk.fk``) per arm, one start at the middle of the limits, ``jk.solve_ik(robot, T, q0)``
with nothing else but ``throw=False``; at most one failure in 200 (>= 99.5%) at the default
tolerance. Every solution is checked independently of the solver: numpy on ``jk.fk``'s pose
(position error and the rotation angle of ``R* R^T``, both <= tol) and the joint limits.
"""

from __future__ import annotations

import functools
import pickle

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE

import jaxkin as jk
from jaxkin.ik import RESULTS

N_TARGETS = 200
TOL = 1e-10  # solve_ik's default tolerance in float64
SLACK = 1e-14  # rounding of the numpy recomputation

# Explicit tips: erd's default frames of these files are fingers or a frame beside the chain.
ARMS = {
    "panda": lambda: jk.robots.load("erd/panda", tip="panda_hand"),
    "ur5": lambda: jk.robots.load("erd/ur5_robot", tip="tool0"),
    "ur10": lambda: jk.robots.load("erd/ur10_robot", tip="tool0"),
    "kinova": lambda: jk.robots.load("erd/kinova", tip="j2s6s200_end_effector"),
    "niryo_one": lambda: jk.robots.load("niryo_one"),
}
DOF = {"panda": 7, "ur5": 6, "ur10": 6, "kinova": 6, "niryo_one": 6}


def _solve(robot: jk.Robot, T, q0, **kw):
    """``jk.solve_ik(robot, T, q0, throw=False, **kw)`` inside a jit compiled with the tests'
    FAST_COMPILE options (the same operations, no fast-math; on a UR5 the same compile time as
    the solver's own options within noise, see tests/test_ik.py's ``_solve``). ``seeds`` is an
    argument of the jit, the other options part of its key. Not for the tests of the eager
    entry point (its cache, throw=True)."""
    arrays = sorted(k for k in ("seeds",) if k in kw)
    static = tuple(sorted((k, v) for k, v in kw.items() if k not in arrays))
    return _fast_solver(robot, static, tuple(arrays))(T, q0, *(kw[k] for k in arrays))


@functools.cache
def _fast_solver(robot: jk.Robot, static: tuple, names: tuple):
    def run(T, q0, *arrays):
        kw = dict(static) | dict(zip(names, arrays, strict=True))
        return jk.solve_ik(robot, T, q0, throw=False, **kw)

    return jax.jit(run, compiler_options=FAST_COMPILE)


def _load(name: str) -> jk.Robot:
    if name != "niryo_one" and "erd/panda" not in jk.robots.erd_names():
        pytest.skip("example-robot-data is not installed")
    robot = ARMS[name]()
    assert robot.dof == DOF[name], (name, robot.dof, robot.joint_names)
    return robot


def _poses(robot: jk.Robot, qs) -> np.ndarray:
    return np.stack([np.asarray(jk.fk(robot, q)) for q in np.asarray(qs)])


def _pose_errors(T: np.ndarray, T_target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position error (m) and rotation angle of ``R_target R^T`` (rad), numpy only."""
    dp = np.linalg.norm(T[..., :3, 3] - T_target[..., :3, 3], axis=-1)
    M = T_target[..., :3, :3] @ np.swapaxes(T[..., :3, :3], -1, -2)
    axis = np.stack(
        [M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], -1
    )
    s = 0.5 * np.linalg.norm(axis, axis=-1)
    c = 0.5 * (np.trace(M, axis1=-2, axis2=-1) - 1.0)
    return dp, np.arctan2(s, c)


def _reached(robot: jk.Robot, q: np.ndarray, T_target: np.ndarray, tol: float = TOL) -> np.ndarray:
    """Per solution: pose within tol (checked on jk.fk with numpy) and joints within limits."""
    dp, dw = _pose_errors(_poses(robot, q), T_target)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    within = np.all((q >= lo) & (q <= hi), axis=-1)
    return (dp <= tol + SLACK) & (dw <= tol + SLACK) & within


def _targets(robot: jk.Robot, n: int, key: int):
    q_star = np.asarray(jk.sample_configurations(robot, n, jax.random.key(key)))
    return q_star, _poses(robot, q_star)


def _mid_limits(robot: jk.Robot) -> np.ndarray:
    lo, hi = jk.sampling_bounds(robot)  # finite: continuous joints count as [-pi, pi]
    return 0.5 * (np.asarray(lo) + np.asarray(hi))


@pytest.mark.parametrize("name", list(ARMS))
def test_default_call_reaches_random_reachable_targets(name):
    robot = _load(name)
    _, T = _targets(robot, N_TARGETS, 1)
    q0 = _mid_limits(robot)
    # defaults only; the Panda and the Niryo One through the eager entry point (their solvers
    # serve test_num_seeds_1_is_exactly_one_start and test_an_ik_error_keeps_the_batch below),
    # the others inside a jit compiled with FAST_COMPILE (see _solve)
    eager = name in ("panda", "niryo_one")
    sol = jk.solve_ik(robot, T, q0, throw=False) if eager else _solve(robot, T, q0)
    sol = jax.tree_util.tree_map(np.asarray, sol)
    ok = _reached(robot, sol.q, T)
    failures = int(np.sum(~ok))
    assert failures <= 1, (name, failures, np.bincount(sol.result, minlength=len(RESULTS)))
    # honest flags: converged exactly where the independent check says so, codes as documented
    np.testing.assert_array_equal(sol.converged, ok)
    assert np.all(sol.result[ok] == RESULTS.converged)
    assert np.all(np.isin(sol.result[~ok], [RESULTS.max_steps_reached, RESULTS.stalled]))
    assert np.all(sol.residual[ok] <= TOL)
    # a bounded budget, restarts included
    assert np.all(sol.seed < jk.ik.DEFAULT_NUM_SEEDS) and np.all(sol.seed >= 0)
    assert np.all(sol.steps <= jk.ik.DEFAULT_NUM_SEEDS * 30)


def test_an_ik_error_keeps_the_batch():
    """With throw=True one unreachable target of 200 raised an IKError that carried nothing:
    the other solutions were lost. The error now keeps the whole IKSolution. (The batch of the
    niryo_one case above: its solver is already compiled, the call costs milliseconds.)"""
    robot = _load("niryo_one")
    _, T = _targets(robot, N_TARGETS, 1)
    T[7, :3, 3] = [5.0, 0.0, 0.0]  # beyond the arm's reach
    q0 = _mid_limits(robot)
    with pytest.raises(jk.IKError, match=r"except jk.IKError as e: sol = e.solution") as info:
        jk.solve_ik(robot, T, q0)
    error = info.value
    sol = jax.tree_util.tree_map(np.asarray, error.solution)
    assert isinstance(error.solution, jk.IKSolution) and sol.q.shape == (N_TARGETS, 6)
    assert int(sol.result[7]) == RESULTS.unreachable and not sol.converged[7]
    ok = _reached(robot, sol.q, T)
    np.testing.assert_array_equal(sol.converged, ok)
    assert np.sum(ok) >= N_TARGETS - 2  # 199 reachable targets, at most one failure (above)
    quiet = jk.solve_ik(robot, T, q0, throw=False)  # the same answer as throw=False
    np.testing.assert_array_equal(np.asarray(quiet.q), sol.q)
    # an ordinary exception: args, pickling (solution included)
    assert isinstance(error, ValueError) and error.args == (str(error),)
    again = pickle.loads(pickle.dumps(error))
    assert type(again) is jk.IKError and str(again) == str(error)
    np.testing.assert_array_equal(np.asarray(again.solution.q), sol.q)
    assert jk.IKError("plain").solution is None


@pytest.mark.parametrize("n_begun", [0, 1, 5, jk.ik.START_SLOTS, jk.ik.START_SLOTS + 1, 20])
def test_placing_starts_gathered_or_for_every_lane_gives_the_same_values(n_begun):
    """``_place`` evaluates the starts of the lanes that begin one (gathered) where at most
    ``START_SLOTS`` do, else every lane's: the lanes' configurations are the same either way, and
    the lanes that do not begin keep theirs."""
    B, n = 20, 3
    rng = np.random.default_rng(n_begun)
    begun = np.zeros(B, bool)
    begun[rng.permutation(B)[:n_begun]] = True
    q = rng.normal(size=(B, n))
    lane = jk.ik._idle_lanes(B, n, 7, np.float64)._replace(
        q=jnp.asarray(q), job=jnp.asarray(rng.integers(0, 7, B), jnp.int32)
    )
    calls = []

    def starts(job, seed):  # vmapped: one row per lane given
        calls.append(job.shape[0])
        return jnp.stack([job * 1.0, seed * 2.0, job + 0.5], axis=1)

    placed = jax.jit(lambda lane, begun: jk.ik._place(lane, begun, starts))(lane, begun)
    want = np.where(begun[:, None], np.asarray(starts(lane.job, lane.seed)), q)
    np.testing.assert_array_equal(np.asarray(placed.q), want)
    np.testing.assert_array_equal(np.asarray(placed.best_q), np.where(begun[:, None], want, 0.0))
    assert calls[:2] == [jk.ik.START_SLOTS, B]  # traced: the gathered branch and the full one


def test_answers_do_not_depend_on_the_lanes():
    """The queue runs the last targets' remaining starts side by side (several lanes on one
    target); the answer is still the one of trying the starts in turn: the converged start
    with the smallest index, its configuration the same up to rounding (the loop compiled for
    another number of lanes rounds differently: about 1e-10 rad here, the size of tol)."""
    robot = _load("panda")
    _, T = _targets(robot, N_TARGETS, 5)
    q0 = _mid_limits(robot)
    # 15 explicit starts per target after q0 (random ones depend on the target's index)
    seeds = np.asarray(jk.sample_configurations(robot, N_TARGETS * 15, jax.random.key(6)))
    seeds = seeds.reshape(N_TARGETS, 15, robot.dof)

    one = _solve(robot, T, q0, seeds=seeds, lanes=1)  # one start after another
    one = jax.tree_util.tree_map(np.asarray, one)
    ok = one.converged
    assert 0 < np.sum(~ok) < 5  # a few targets fail all 16 starts
    # The 10 hardest solved targets and the failed ones on 64 lanes: their starts run side by
    # side, starts beyond the winning one are abandoned (their steps still count). The rest of
    # the batch are targets reached at their start (the pose of q0: their lanes free at once),
    # so that it is the batch of the default call above, whose compiled solver (the eager entry
    # point, 64 lanes) serves calls with seeds= too.
    hard = np.argsort(-np.where(ok, one.seed, -1), kind="stable")[:10]
    assert one.seed[hard].min() >= 2, one.seed[hard]
    idx = np.concatenate([hard, np.flatnonzero(~ok)])
    m = idx.size
    at_q0 = np.repeat(_poses(robot, [q0]), N_TARGETS - m, 0)
    par = jk.solve_ik(
        robot,
        np.concatenate([T[idx], at_q0]),
        q0,
        seeds=np.concatenate([seeds[idx], seeds[: N_TARGETS - m]]),
        lanes=64,
        throw=False,
    )
    assert np.all(np.asarray(par.steps)[m:] == 0) and np.all(np.asarray(par.converged)[m:])
    par = jax.tree_util.tree_map(lambda x: np.asarray(x)[:m], par)
    np.testing.assert_array_equal(par.converged, ok[idx])
    np.testing.assert_array_equal(par.seed[:10], one.seed[hard])
    np.testing.assert_allclose(par.q[:10], one.q[hard], rtol=0, atol=1e-8)
    # (a failed start's length in a local minimum can move by a few steps with the rounding)
    assert np.all(par.steps[:10] >= one.steps[hard]) and np.any(par.steps[:10] > one.steps[hard])
    # a failed target's answer is its best start (two starts can end in one local minimum,
    # their residuals equal up to rounding, so which of them is reported may differ)
    np.testing.assert_allclose(par.residual[10:], one.residual[~ok], rtol=1e-9)


def test_num_seeds_1_is_exactly_one_start():
    robot = _load("panda")
    _, T = _targets(robot, N_TARGETS, 2)
    q0 = _mid_limits(robot)
    for max_steps in (30, 7):  # max_steps is traced: one compile for both
        sol = jk.solve_ik(robot, T, q0, num_seeds=1, max_steps=max_steps, throw=False)
        sol = jax.tree_util.tree_map(np.asarray, sol)
        assert np.all(sol.seed == 0)
        assert np.all(sol.steps <= max_steps), sol.steps.max()
        ok = _reached(robot, sol.q, T)
        np.testing.assert_array_equal(sol.converged, ok)
        assert np.all(np.isin(sol.result[~ok], [RESULTS.max_steps_reached, RESULTS.stalled]))
    # one start does fail on some of these targets (the defaults' restarts are what reach them)
    assert 0 < np.sum(~ok) < N_TARGETS


def test_explicit_seeds_are_the_only_starts():
    planar = jk.robots.load("two_link_planar", dtype=np.float64)
    T = np.eye(4)
    T[:3, 3] = [1.0, 0.5, 0.3]  # within reach but out of the arm's plane: every start stalls
    q0 = np.array([0.1, 0.2])
    seeds = np.array([[1.0, -0.5], [-2.0, 1.0]])
    # (6 lanes: the starts of one target side by side; the eager entry point: with seeds= or
    # without, and in the next test, one compiled solver)
    sol = jk.solve_ik(planar, T, q0, seeds=seeds, lanes=6, max_steps=200, throw=False)
    assert int(sol.result) == RESULTS.stalled and int(sol.seed) in (0, 1, 2)
    assert int(sol.steps) <= 3 * 200
    # while the default keeps restarting (64 starts), within its bound
    many = jk.solve_ik(planar, T, q0, lanes=6, max_steps=200, throw=False)
    assert int(many.result) == RESULTS.stalled
    assert 3 * 200 < int(many.steps) <= jk.ik.DEFAULT_NUM_SEEDS * 200


def test_equal_failed_starts_report_the_first():
    """Starts that end in the same local minimum, run side by side on several lanes: the
    reported start is the first of them, as if they had been tried in turn."""
    planar = jk.robots.load("two_link_planar", dtype=np.float64)
    T = np.eye(4)
    T[:3, 3] = [1.0, 0.5, 0.3]  # out of the arm's plane: every start stalls
    q0 = np.array([0.1, 0.2])
    # three equal starts (q0 and two copies) on six lanes (the solver of the test above)
    sol = jk.solve_ik(planar, T, q0, seeds=np.tile(q0, (2, 1)), lanes=6, max_steps=200, throw=False)
    assert int(sol.result) == RESULTS.stalled and int(sol.seed) == 0


# A small spatial arm (z, y, y axes, then a tool offset), written to a file by the test.
ARM_URDF = """<robot name="arm3">
  <link name="l0"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="l0"/><child link="l1"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0.1 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/>
  </joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="1"/>
  </joint>
  <joint name="tool" type="fixed"><parent link="l3"/><child link="tip"/>
    <origin xyz="0.3 0 0"/>
  </joint>
</robot>
"""


def test_cache_is_keyed_by_the_robots_value(tmp_path):
    path = tmp_path / "arm3.urdf"
    path.write_text(ARM_URDF)
    a = jk.load_urdf(path, dtype=np.float64)
    b = jk.load_urdf(str(path), dtype=np.float64)
    assert a is not b and a == b and a.dof == 3
    # a changed link parameter: the second link lengthened by 5 cm
    xyz = a.params["xyz"]
    i = a.joint_names.index("j3")
    c = a.replace(params={**a.params, "xyz": xyz.at[i, 0].add(0.05)})
    assert c != a and np.asarray(a.params["xyz"])[i, 0] == 0.4

    jitted = jk.ik._solve_batch.get_jitted()
    q_star = np.asarray(jk.sample_configurations(a, 8, jax.random.key(4)))
    T_a = _poses(a, q_star)
    T_c = _poses(c, q_star)
    q0 = _mid_limits(a)
    before = jitted._cache_size()
    sol_a = jk.solve_ik(a, T_a, q0, lanes=1)  # (one lane: a cheaper compile, same keys)
    assert jitted._cache_size() == before + 1
    assert np.all(_reached(a, np.asarray(sol_a.q), T_a))
    # an equal robot from the same file: no new compile, the same answers
    sol_b = jk.solve_ik(b, T_a, q0, lanes=1)
    assert jitted._cache_size() == before + 1
    np.testing.assert_array_equal(np.asarray(sol_b.q), np.asarray(sol_a.q))
    # the changed robot compiles once and solves for itself, not for the cached one
    sol_c = jk.solve_ik(c, T_c, q0, lanes=1)
    assert jitted._cache_size() == before + 2
    q_c = np.asarray(sol_c.q)
    assert np.all(_reached(c, q_c, T_c))
    dp_old, _ = _pose_errors(_poses(a, q_c), T_c)
    assert np.all(dp_old > 1e-3)  # on the old robot these answers miss: the test discriminates
    # and the old robot's entry still answers for the old robot
    sol_a2 = jk.solve_ik(jk.load_urdf(path, dtype=np.float64), T_a, jnp.asarray(q0), lanes=1)
    assert jitted._cache_size() == before + 2
    np.testing.assert_array_equal(np.asarray(sol_a2.q), np.asarray(sol_a.q))
