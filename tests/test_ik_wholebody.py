"""Whole-body inverse kinematics (issue 23 item 3): ``jk.solve_ik`` on floating-base and ball-joint
robots, several frames at once, weights, posture, the centre of mass.

Oracles: ``jk.fk`` (the forward kinematics, not the solver's Jacobian pass) at the returned
configuration; unit quaternions; ``jk.difference`` for the posture; for the implicit-function
derivative, that the frames follow the target's tangent (``d fk(q*(T)) = dT``).

Compiles: one Solo12 solve (four feet, a batch of 50, cached) and two solves of ``LEGS``, a small
free-floating robot with ball hips: every float64 batch goes through one jitted JVP of the solve
(weights, centre of mass and posture as data, the tangent along with the solution), and one
float32 solve of a single frame. Helpers (batched ``fk``) are jitted once per robot.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _legs import FEET, LEGS
from _sampling import random_q  # numpy: the sampler is not under test here
from _xla import FAST_COMPILE
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
from jaxkin.ik import RESULTS


def quaternion_norms(robot: jk.Robot, qs) -> np.ndarray:
    """|quaternion| of every free and ball joint, (N, n_joints)."""
    qs = np.atleast_2d(np.asarray(qs))
    out = []
    for j in robot.multi_dof_joints:
        qi = robot.q_index[j]
        s = slice(qi + 3, qi + 7) if robot.kinds[j] == "free" else slice(qi, qi + 4)
        out.append(np.linalg.norm(qs[:, s], axis=-1))
    return np.stack(out, axis=-1)


@functools.cache
def _fk_batch(robot: jk.Robot, frames: tuple):
    """One compiled ``vmap`` of ``jk.fk`` per robot and frames (op by op, a Solo12 pass under
    ``vmap`` dispatches hundreds of primitives)."""
    fk = jax.vmap(lambda q: jk.fk(robot, q, frame=list(frames)))
    return jax.jit(fk, compiler_options=FAST_COMPILE)


def fk_frames(robot, qs, frames):
    return np.asarray(_fk_batch(robot, tuple(frames))(np.asarray(qs)))


def on_host(tree):
    """A solution's arrays as numpy (the assertions' comparisons and reductions run in numpy: on
    JAX arrays each would compile a program of its own)."""
    return jax.tree_util.tree_map(np.asarray, tree)


def centres_of_mass(qs) -> np.ndarray:
    """``jk.center_of_mass`` of LEGS at each row (its eager kernel: one compile)."""
    return np.stack([np.asarray(jk.center_of_mass(LEGS, q)) for q in np.asarray(qs)])


def targets(robot, n, seed, frames):
    return fk_frames(robot, random_q(robot, n, seed), frames)


# ----------------------------------------------------------------------------- Solo12
@functools.cache
def solo_case():
    robot = jk.robots.load("erd/solo12", floating_base=True, dtype=np.float64)
    feet = list(robot.default_frames)
    T = targets(robot, 50, 11, feet)
    sol = jk.solve_ik(robot, T, jk.neutral(robot), frame=feet, throw=False)
    return robot, feet, T, on_host(sol)


def test_solo12_four_feet_all_converge_from_neutral_with_defaults():
    robot, feet, T, sol = solo_case()
    assert sol.q.shape == (50, robot.nq) and sol.position_error.shape == (50, 4)
    assert np.all(sol.converged), np.asarray(sol.result)
    assert np.all(sol.result == RESULTS.converged)
    # the forward kinematics at the answer (not the solver's own pass) puts every foot there
    Tq = fk_frames(robot, sol.q, feet)
    assert np.max(np.abs(Tq[..., :3, 3] - T[..., :3, 3])) < 1e-9
    assert np.max(np.abs(Tq[..., :3, :3] - T[..., :3, :3])) < 1e-9
    assert np.all(sol.residual <= 1e-10)
    np.testing.assert_allclose(quaternion_norms(robot, sol.q), 1.0, atol=1e-14)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    assert np.all((np.asarray(sol.q) >= lo) & (np.asarray(sol.q) <= hi))


def test_solo12_errors_per_foot():
    sol = solo_case()[-1]
    assert np.all(sol.position_error < 1e-10) and np.all(sol.orientation_error < 1e-10)
    assert sol.com_error is None and not np.any(sol.singular)


def test_throw_raises_with_every_solution_kept():
    """The same call as the fixture's (one compile), with one foot 5 m from the others."""
    robot, feet, T, _ = solo_case()
    far = T.copy()
    far[0, 1, :3, 3] += [0.0, -5.0, 0.0]
    with pytest.raises(jk.IKError, match=r"1 of 50 target\(s\) not reached") as info:
        jk.solve_ik(robot, far, jk.neutral(robot), frame=feet)
    sol = on_host(info.value.solution)
    assert not sol.converged[0] and np.all(sol.converged[1:])
    assert sol.result[0] in (RESULTS.stalled, RESULTS.max_steps_reached)


# ----------------------------------------------------------------------------- restarts
def _rotation(v) -> np.ndarray:
    """The rotation of the (non-zero) 4-vector ``v`` read as a quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(v) / np.linalg.norm(v)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


_quaternion = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
    lambda v: np.linalg.norm(v) > 0.1
)
_point = st.lists(st.floats(-1, 1), min_size=3, max_size=3).map(np.array)


@functools.cache
def _base_fit(k: int):
    """``jaxkin.ik._base_fit`` jitted (one compile per number of frames)."""

    def fit(R, p, T, w, i):
        goal = jk.ik._Goals(T=T, com=None, q_ref=None, w=w, wp=None)
        return jk.ik._base_fit(R, p, goal, i)

    return jax.jit(fit, compiler_options=FAST_COMPILE)


def _frames_and_targets(data, k: int, G: np.ndarray, t: np.ndarray):
    """k random frame poses, and their targets moved rigidly by ``(G, t)``."""
    R = np.stack([_rotation(data.draw(_quaternion)) for _ in range(k)])
    p = np.stack([data.draw(_point) for _ in range(k)])
    T = np.tile(np.eye(4), (k, 1, 1))
    T[:, :3, :3] = G @ R
    T[:, :3, 3] = p @ G.T + t
    return R, p, T


@settings(max_examples=25, deadline=None)
@given(st.sampled_from([1, 2, 4]), _quaternion, _point, st.data())
def test_restart_base_fit_recovers_a_rigid_motion_of_the_frames(k, g, t, data):
    """Targets that are the frames moved rigidly: the fit is that motion, whatever the number
    of frames (one frame: its axes fix the rotation)."""
    G = _rotation(g)
    R, p, T = _frames_and_targets(data, k, G, t)
    Rg, tg = _base_fit(k)(R, p, T, np.ones(6 * k), 0)
    np.testing.assert_allclose(np.asarray(Rg), G, atol=1e-9)
    np.testing.assert_allclose(np.asarray(tg), t, atol=1e-9)


@settings(max_examples=15, deadline=None)
@given(_quaternion, _point, st.data())
def test_restart_base_fit_without_position_rows_turns_about_the_frames_centroid(g, t, data):
    G = _rotation(g)
    R, p, T = _frames_and_targets(data, 4, G, t)
    w = np.tile([0.0, 0.0, 0.0, 1.0, 1.0, 1.0], 4)  # orientation rows only
    Rg, tg = map(np.asarray, _base_fit(4)(R, p, T, w, 0))
    np.testing.assert_allclose(Rg, G, atol=1e-9)
    c = p.mean(axis=0)
    np.testing.assert_allclose(Rg @ c + tg, c, atol=1e-12)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 1), st.data())
def test_restart_base_fit_falls_back_to_one_frame_where_the_fit_is_degenerate(i, data):
    """Two frames, position rows only: their origins fix no rotation about the line through
    them, so the fit is frame i's own alignment (onto a target that is no rigid motion)."""
    R, p, _ = _frames_and_targets(data, 2, np.eye(3), np.zeros(3))
    T = np.tile(np.eye(4), (2, 1, 1))
    T[:, :3, :3] = np.stack([_rotation(data.draw(_quaternion)) for _ in range(2)])
    T[:, :3, 3] = np.stack([data.draw(_point) for _ in range(2)])
    w = np.tile([1.0, 1.0, 1.0, 0.0, 0.0, 0.0], 2)
    Rg, tg = map(np.asarray, _base_fit(2)(R, p, T, w, i))
    want = T[i, :3, :3] @ R[i].T
    np.testing.assert_allclose(Rg, want, atol=1e-12)
    np.testing.assert_allclose(tg, T[i, :3, 3] - want @ p[i], atol=1e-12)


def test_restarts_of_a_floating_base_spread_from_mid_range():
    """Start s > 0 of a floating-base whole-body solve: q0's base, each revolute and prismatic
    joint at ``mid + a (row - mid)`` of its pool row, ``a = min(1, (s - 1) / RESTART_RAMP)``;
    the pool row as drawn from then on and for a fixed-base robot (every start brought within
    the limits: the Panda's neutral configuration is not)."""
    ramp = jk.ik.RESTART_RAMP
    for robot in (jk.robots.load("erd/solo12", floating_base=True), jk.robots.load("panda")):
        S = ramp + 3
        pool = jk.sample_configurations(robot, S - 1, key=5)
        q0 = jk.neutral(robot)
        start = jk.ik._start_fn(robot, q0, pool, 1, S, np.float64, keep_base=True)
        lo, hi = (np.asarray(b) for b in jk.sampling_bounds(robot))
        base = jk.ik._base_entries(robot)
        for s in range(S):
            got = np.asarray(start(jnp.int32(0), jnp.int32(s)))
            if s == 0:
                want = np.asarray(q0)
            elif base is None:
                want = np.asarray(pool[s - 1])
            else:
                a = min(1.0, (s - 1) / ramp)
                mid = (lo + hi) / 2
                want = np.where(base, q0, mid + a * (np.asarray(pool[s - 1]) - mid))
            want = np.clip(want, robot.lower, robot.upper)
            np.testing.assert_allclose(got, want, atol=1e-15, err_msg=f"{robot.name} start {s}")


# ----------------------------------------------------------------------------- LEGS
N = 12


@functools.cache
def legs_case():
    """A batch of two-feet targets of LEGS (the feet and the centre of mass of random
    configurations) and a posture."""
    qs, q_ref = legs_draw()[:N], legs_draw()[N]
    T = fk_frames(LEGS, qs, FEET)
    com = centres_of_mass(qs)
    return T, com, q_ref


@functools.cache
def legs_draw() -> np.ndarray:
    """N + 2 random configurations of LEGS from one numpy draw (nothing compiled): the N
    targets' configurations, the posture, and the float32 test's configuration."""
    return random_q(LEGS, N + 2, seed=3)


@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _solve_legs(T, T_dot, com, q_ref, weights, com_weight, posture_weight):
    def solve(T):
        sol = jk.solve_ik(
            LEGS,
            T,
            jk.neutral(LEGS),
            frame=FEET,
            weights=weights,
            com=com,
            com_weight=com_weight,
            posture=q_ref,
            posture_weight=posture_weight,
            throw=False,
        )
        return sol.q, sol

    # only q's tangent is returned: the other fields' tangents are not compiled
    _, dq, sol = jax.jvp(solve, (T,), (T_dot,), has_aux=True)
    return sol, dq


def solve_legs(T, weights=1.0, com_weight=0.0, posture_weight=0.0, T_dot=None):
    """Every LEGS batch solve: the centre-of-mass target and the posture term are always there,
    with weight 0 unless asked for (the weights are data: one compile serves them all), and the
    solution's tangent along ``T_dot`` (default 0) comes with it: ``(solution, dq)``."""
    _, com, q_ref = legs_case()
    T_dot = np.zeros_like(T) if T_dot is None else T_dot
    weights = np.broadcast_to(weights, (2, 6))
    return on_host(_solve_legs(T, T_dot, com, q_ref, weights, com_weight, posture_weight))


def test_ball_joints_and_a_floating_base_converge_with_unit_quaternions():
    T = legs_case()[0]
    sol, _ = solve_legs(T)
    assert np.all(sol.converged)
    assert sol.q.shape == (N, LEGS.nq) and sol.position_error.shape == (N, 2)
    Tq = fk_frames(LEGS, sol.q, FEET)
    np.testing.assert_allclose(Tq, T, atol=1e-9)
    np.testing.assert_allclose(quaternion_norms(LEGS, sol.q), 1.0, atol=1e-14)
    knees = np.asarray(sol.q)[:, [11, 16]]
    assert np.all((knees >= 0.0) & (knees <= 2.5))


def test_position_only_and_orientation_only_rows():
    T = legs_case()[0]
    position = np.array([[1.0, 1, 1, 0, 0, 0], [1.0, 1, 1, 0, 0, 0]])
    sol, _ = solve_legs(T, weights=position)
    assert np.all(sol.converged)
    Tq = fk_frames(LEGS, sol.q, FEET)
    np.testing.assert_allclose(Tq[..., :3, 3], T[..., :3, 3], atol=1e-9)
    assert np.all(sol.orientation_error == 0.0)  # rows with weight 0 are no target
    # left foot: orientation only; right foot: its pose, position rows weighted 10
    mixed = np.array([[0.0, 0, 0, 1, 1, 1], [10.0, 10, 10, 1, 1, 1]])
    sol, _ = solve_legs(T, weights=mixed)
    assert np.all(sol.converged)
    Tq = fk_frames(LEGS, sol.q, FEET)
    np.testing.assert_allclose(Tq[:, 0, :3, :3], T[:, 0, :3, :3], atol=1e-9)
    np.testing.assert_allclose(Tq[:, 1], T[:, 1], atol=1e-10)
    assert np.all(sol.position_error[:, 0] == 0.0)


def test_posture_pulls_toward_the_reference_without_stopping_the_targets():
    T, _, q_ref = legs_case()
    position = np.array([[1.0, 1, 1, 0, 0, 0], [1.0, 1, 1, 0, 0, 0]])
    free, _ = solve_legs(T, weights=position)
    pulled, _ = solve_legs(T, weights=position, posture_weight=1.0)
    assert np.all(free.converged) and np.all(pulled.converged)
    np.testing.assert_allclose(
        fk_frames(LEGS, pulled.q, FEET)[..., :3, 3], T[..., :3, 3], atol=1e-9
    )

    def gap(qs):  # the joints' distance to the posture (the base is not pulled)
        d = np.stack([np.asarray(jk.difference(LEGS, q, q_ref)) for q in np.asarray(qs)])
        return np.linalg.norm(d[:, 6:], axis=1)

    assert np.mean(gap(pulled.q)) < 0.7 * np.mean(gap(free.q))


def test_centre_of_mass_target_with_the_feet_positions():
    T, com, _ = legs_case()
    position = np.array([[1.0, 1, 1, 0, 0, 0], [1.0, 1, 1, 0, 0, 0]])
    sol, _ = solve_legs(T, weights=position, com_weight=1.0)
    assert np.all(sol.converged) and sol.com_error.shape == (N,)
    assert np.all(sol.com_error < 1e-10)
    c = centres_of_mass(sol.q)
    np.testing.assert_allclose(c, com, atol=1e-10)
    np.testing.assert_allclose(fk_frames(LEGS, sol.q, FEET)[..., :3, 3], T[..., :3, 3], atol=1e-9)


def test_refusals_name_the_argument():
    T = legs_case()[0]
    q0 = jk.neutral(LEGS)
    with pytest.raises(jk.ShapeError, match=r"T_target must have shape \(2, 4, 4\)"):
        jk.solve_ik(LEGS, T[0, 0], q0, frame=FEET)
    with pytest.raises(jk.ShapeError, match=r"weights must have shape \(6,\) or \(2, 6\)"):
        jk.solve_ik(LEGS, T[0], q0, frame=FEET, weights=np.ones(2))
    with pytest.raises(jk.JaxkinError, match=r"weights must be >= 0"):
        jk.solve_ik(LEGS, T[0], q0, frame=FEET, weights=-np.ones(6))
    with pytest.raises(jk.JaxkinError, match=r"method='lm' only"):
        jk.solve_ik(LEGS, T[0], q0, frame=FEET, method="optax")
    with pytest.raises(jk.ShapeError, match=r"posture must have shape \(17,\)"):
        jk.solve_ik(LEGS, T[0], q0, frame=FEET, posture=np.zeros(14))
    with pytest.raises(jk.ShapeError, match=r"com must have shape \(3,\) or \(12, 3\)"):
        jk.solve_ik(LEGS, T, q0, frame=FEET, com=np.zeros((2, 3)))
    with pytest.raises(jk.ModelError, match=r"no inertial data"):
        jk.solve_ik(jk.robots.load("ur5"), np.eye(4), np.zeros(6), com=np.zeros(3))


# ----------------------------------------------------------------------------- float32, one frame
def test_float32_single_frame_of_a_floating_robot():
    robot = LEGS.astype(np.float32)
    q = legs_draw()[N + 1].astype(np.float32)
    T = np.asarray(jk.fk(robot, q, frame="l_foot"))
    solve = jax.jit(
        lambda T: jk.solve_ik(robot, T, jk.neutral(robot), frame="l_foot", throw=False),
        compiler_options=FAST_COMPILE,
    )
    sol = on_host(solve(T))
    assert sol.converged and sol.q.dtype == np.float32 and sol.position_error.shape == ()
    assert sol.residual <= 1e-5
    Tq = np.asarray(jk.fk(robot, sol.q, frame="l_foot"))
    np.testing.assert_allclose(Tq, T, atol=2e-5)
    np.testing.assert_allclose(quaternion_norms(robot, sol.q), 1.0, atol=1e-6)


# ----------------------------------------------------------------------------- derivatives
def test_implicit_derivative_moves_the_frames_with_their_targets():
    """``d fk(q*(T)) / dT = dT``: the tangent of the solution moves both feet exactly as their
    targets move (12 rows, 14 velocity columns: full row rank), for every target of the batch
    (the shared LEGS solve: centre-of-mass rows and posture there with weight 0, which are no
    part of the residual the derivative follows)."""
    T = legs_case()[0]
    rng = np.random.default_rng(0)
    xi = rng.normal(size=(N, 2, 6))
    hat = np.zeros((N, 2, 4, 4))
    x, y, z = np.moveaxis(xi[..., 3:], -1, 0)
    hat[..., 0, 1], hat[..., 0, 2], hat[..., 1, 2] = -z, y, -x
    hat[..., 1, 0], hat[..., 2, 0], hat[..., 2, 1] = z, -y, x
    hat[..., :3, 3] = xi[..., :3]
    T_dot = T @ hat  # tangents of the targets (body-frame twists)
    sol, dq = solve_legs(T, T_dot=T_dot)
    assert np.all(sol.converged)
    np.testing.assert_allclose(fk_frames(LEGS, sol.q, FEET), T, atol=1e-9)
    dT = _fk_tangents(sol.q, dq)
    np.testing.assert_allclose(dT, T_dot, atol=1e-8)


@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _fk_tangents(qs, dqs):
    """``d fk(q) [dq]`` of both feet, (N, 2, 4, 4): forward-mode through ``jk.fk``."""

    def one(q, dq):
        return jax.jvp(lambda q: jk.fk(LEGS, q, frame=FEET), (q,), (dq,))[1]

    return jax.vmap(one)(qs, dqs)


def test_the_report_reuses_the_centre_of_mass_of_its_jacobian_pass(monkeypatch):
    """A solve with ``com=`` traces ``com_and_jacobian`` twice: in the loop's step and in the
    report, whose centre of mass (``com_error``) comes from the same pass as the Jacobian that
    flags singular rows (a second trace of it made every whole-body program larger). Tracing
    only, no compile; a small robot of this test's own (no cached trace)."""
    robot = jk.Robot.from_joints(
        [
            dict(name="root", type="free", child="body", inertial=dict(mass=2.0)),
            dict(
                name="hinge",
                type="revolute",
                parent="body",
                child="arm",
                axis=[0, 1, 0],
                lower=-2.0,
                upper=2.0,
                inertial=dict(mass=1.0, xyz=[0.3, 0, 0]),
            ),
            dict(name="tip", type="fixed", child="tip", xyz=[0.6, 0, 0]),
        ],
        name="com_traced_once",
    )
    calls = []
    com_and_jacobian = jk.ik.com_and_jacobian
    monkeypatch.setattr(
        jk.ik, "com_and_jacobian", lambda *a: calls.append(1) or com_and_jacobian(*a)
    )

    def solve(T):
        q0 = jk.neutral(robot)  # traced: no kernel compiled
        sol = jk.solve_ik(robot, T, q0, frame=["tip"], com=np.zeros(3), num_seeds=1, throw=False)
        return sol.com_error

    jax.make_jaxpr(solve)(np.eye(4)[None])
    assert len(calls) == 2
