"""Motion sequences (issue 23 item 5): ``jk.motion.retarget`` tracks a sequence of whole-body
targets, warm-started step by step, streamed in chunks through ``jaxkin.batch.chunked_scan``.

Oracles: the targets are ``jk.fk`` of a smooth joint trajectory (so every step is reachable) and
the answer is checked with ``jk.fk`` again (not the solver's Jacobian pass); the scanned run is
compared with :func:`jaxkin.motion.track_step` called in a Python loop, and the chunked run (to
disk) with the unchunked one; ``chunked_scan`` itself against ``lax.scan``.

Compiles: the small free-floating ``LEGS`` robot twice (the scan over chunks of 15 steps, every
LEGS run's chunk length, and one step) and the zoo's Panda (float64 and float32).
"""

from __future__ import annotations

import contextlib
import functools
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _legs import FEET, LEGS
from _xla import FAST_COMPILE

import jaxkin as jk
from jaxkin import batch, motion
from jaxkin.batch import chunked_scan
from jaxkin.ik import RESULTS

STEPS = 60


def smooth_trajectory(robot: jk.Robot, q0, n: int, seed: int, scale: float = 0.3):
    """(n, nq) configurations ``integrate(q0, v(t))``, ``v`` a sum of slow sines (within the
    limits), and the time steps' largest change ``|difference(q_t, q_{t+1})|``."""
    t = np.linspace(0.0, 1.5, n)
    V = np.random.default_rng(seed).normal(size=(4, robot.nv))
    vel = (np.sin(np.outer(t, [1.0, 2.0, 3.0, 4.0])) @ V * scale).astype(robot.dtype)
    if robot.multi_dof_joints:
        qs = kernels(robot).integrate(jnp.asarray(q0, robot.dtype), jnp.asarray(vel))
    else:  # scalar joints (the arms) add v: numpy, nothing to compile
        lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
        qs = np.clip(np.asarray(q0, robot.dtype) + vel, lo, hi)
    return qs, max_step(robot, qs)


@functools.cache
def kernels(robot: jk.Robot) -> types.SimpleNamespace:
    """The test's batched helpers for one robot, each jitted once (a fresh ``jax.jit`` per call
    would trace and lower again)."""
    lo, hi = robot.lower, robot.upper
    integrate = jax.vmap(lambda q0, v: jnp.clip(jk.integrate(robot, q0, v), lo, hi), (None, 0))
    jit = functools.partial(jax.jit, compiler_options=FAST_COMPILE)
    return types.SimpleNamespace(
        integrate=jit(integrate),
        gaps=jit(jax.vmap(lambda a, b: jk.difference(robot, a, b))),
        fk=jit(jax.vmap(lambda q: jk.fk(robot, q))),
        fk_frames=jit(jax.vmap(lambda q: jk.fk(robot, q, frame=FEET))),
    )


def max_step(robot: jk.Robot, qs) -> float:
    """The largest entry of ``difference(q_t, q_{t+1})`` over a sequence (n, nq): numpy's
    difference for a robot of scalar joints only (the arms), else ``jk.difference`` compiled."""
    qs = np.asarray(qs)
    if not robot.multi_dof_joints:
        return float(np.max(np.abs(np.diff(qs, axis=0))))
    return float(np.max(np.abs(np.asarray(kernels(robot).gaps(qs[:-1], qs[1:])))))


def fk_frames(robot, qs, frames):
    assert list(frames) == FEET
    return np.asarray(kernels(robot).fk_frames(jnp.asarray(qs)))


def fk_tip(robot, qs):
    return np.asarray(kernels(robot).fk(jnp.asarray(qs)))


def max_pose_error(Ta, Tb):
    return max(np.max(np.abs(Ta[..., :3, 3] - Tb[..., :3, 3])), np.max(np.abs(Ta - Tb)))


CHUNK = 15


@functools.cache
def legs_case():
    """The LEGS sequence, retargeted in four chunks of ``CHUNK`` steps: every LEGS run of this
    file has chunks of that length (one compiled scan, loaded from the run's compilation cache
    after the first)."""
    q0 = np.array(jk.neutral(LEGS))  # numpy: no eager scatter programs
    q0[[11, 16]] = 0.6  # knees bent: away from singular
    qs, gap = smooth_trajectory(LEGS, q0, STEPS, seed=1)
    frames = FEET  # 12 rows, 14 velocities: redundant
    T = fk_frames(LEGS, qs, frames)
    res = motion.retarget(LEGS, T, qs[0], frames, chunk_size=CHUNK)
    return qs, gap, frames, T, res


def test_floating_base_sequence_is_tracked_and_smooth():
    _, gap, frames, T, res = legs_case()
    assert res.q.shape == (STEPS, LEGS.nq) and res.position_error.shape == (STEPS, 2)
    assert np.all(res.converged), res.result
    assert np.all(res.result == RESULTS.converged)
    assert np.all(res.residual <= 1e-10)
    assert max_pose_error(fk_frames(LEGS, res.q, frames), T) < 1e-6  # independent fk
    for j in LEGS.multi_dof_joints:  # quaternions stay unit
        qi = LEGS.q_index[j]
        s = slice(qi + 3, qi + 7) if LEGS.kinds[j] == "free" else slice(qi, qi + 4)
        np.testing.assert_allclose(np.linalg.norm(res.q[:, s], axis=1), 1.0, atol=1e-12)
    # warm starts: a step needs a few iterations, and the motion has no jumps
    assert np.all(res.iterations <= 6)
    assert max_step(LEGS, res.q) < 2 * gap


def test_scan_equals_solving_step_by_step():
    """Every step of the chunked scan, across the chunks' boundaries (the carry), against
    track_step called in a loop."""
    qs, _, frames, T, res = legs_case()
    q = qs[0]
    for t in range(STEPS):
        step = motion.track_step(LEGS, q, T[t], frames)
        np.testing.assert_allclose(step.q, res.q[t], rtol=0, atol=1e-12)
        assert float(step.residual) == pytest.approx(float(res.residual[t]), abs=1e-12)
        assert int(step.iterations) == int(res.iterations[t])
        q = step.q


def test_chunked_run_equals_the_unchunked_one_and_writes_to_disk(tmp_path):
    """The first chunk's steps run alone (one chunk: unchunked), and the whole sequence in
    chunks of 16 (four of 15 rows) written to disk, against the chunked run in memory (which
    equals the step-by-step loop above)."""
    qs, _, frames, T, res = legs_case()
    alone = motion.retarget(LEGS, T[:CHUNK], qs[0], frames)
    np.testing.assert_allclose(alone.q, res.q[:CHUNK], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(alone.result, res.result[:CHUNK])
    path = motion.retarget(LEGS, T, qs[0], frames, chunk_size=16, out=tmp_path / "motion.npz")
    assert str(path).endswith("motion.npz")
    with np.load(path) as saved:
        assert set(saved.files) >= {"q", "residual", "converged", "result", "iterations"}
        np.testing.assert_allclose(saved["q"], res.q, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(saved["result"], res.result)
        np.testing.assert_allclose(saved["position_error"], res.position_error, atol=1e-12)


@contextlib.contextmanager
def jax_compiles():
    """The names of the JAX compile steps (trace, lowering, XLA compile) run inside the block."""
    events = []

    def listen(name, seconds, **kwargs):
        if name.startswith("/jax/core/compile/"):
            events.append(name)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        yield events
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)


def test_a_later_call_with_other_targets_and_settings_compiles_nothing():
    """The compiled scan is kept per robot, frames, iterations, chunk shape and dtype; targets,
    q0, weights and tolerances are its arguments. The second chunk's steps run again from the
    first chunk's last configuration equal the chunked run's, bit for bit."""
    qs, _, frames, T, res = legs_case()
    with jax_compiles() as events:
        rest = motion.retarget(LEGS, T[CHUNK : 2 * CHUNK], res.q[CHUNK - 1], frames)
        other = motion.retarget(
            LEGS, T[:CHUNK], qs[0], frames, weights=np.full(6, 2.0), tol=1e-9, damping=1e-3
        )
    assert events == []
    np.testing.assert_array_equal(rest.q, res.q[CHUNK : 2 * CHUNK])
    np.testing.assert_array_equal(rest.iterations, res.iterations[CHUNK : 2 * CHUNK])
    assert np.all(other.converged) and np.all(other.residual <= 1e-9), other.result


PLANAR3 = jk.Robot.from_joints(
    [
        dict(
            name=f"j{i}",
            type="revolute",
            child=f"link{i}",
            xyz=[0.3 if i else 0.0, 0.0, 0.0],
            axis=[0, 0, 1],
            lower=-2.5,
            upper=2.5,
            inertial=dict(mass=1.0 + i, xyz=[0.15, 0.0, 0.0]),
        )
        for i in range(3)
    ]
    + [dict(name="tip", type="fixed", child="tip", xyz=[0.3, 0.0, 0.0])],
    name="planar3",
    dtype=np.float64,
)
"""Three links of 0.3 m in a plane, masses 1, 2 and 3 kg at their middles."""


def planar3_com(q):
    """The centre of mass of :data:`PLANAR3` in numpy (the oracle): link i's centre lies 0.15 m
    along it, at the angle ``q_0 + ... + q_i``, from its joint."""
    q = np.atleast_2d(q)
    angle = np.cumsum(q, axis=1)
    along = np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # (n, 3, 2)
    joints = np.concatenate([np.zeros_like(along[:, :1]), np.cumsum(0.3 * along, axis=1)], 1)
    centres = joints[:, :3] + 0.15 * along
    mass = np.array([1.0, 2.0, 3.0])
    xy = np.einsum("l,nlk->nk", mass, centres) / mass.sum()
    return np.concatenate([xy, np.zeros_like(xy[:, :1])], axis=1)


def test_centre_of_mass_errors_are_those_of_the_returned_configurations():
    """The tip's position held and the centre of mass pulled along x (4 rows, 3 joints: no
    step converges), one iteration per step: each step reports the centre-of-mass error of the
    configuration it returns (against the numpy oracle); a NaN target's step is flagged and
    held."""
    n = 6
    q0 = np.array([0.3, 0.4, 0.5])
    com = planar3_com(q0) + np.outer(np.linspace(0.0, 0.05, n), [1.0, 0.0, 0.0])
    com[3, 1] = np.nan
    T = np.broadcast_to(np.asarray(jk.fk(PLANAR3, q0, frame="tip")), (n, 4, 4))
    w = [1.0, 1.0, 0.0, 0.0, 0.0, 0.0]
    res = motion.retarget(
        PLANAR3, T, q0, "tip", weights=w, com=com, com_weight=[1.0, 1.0, 0.0], iterations=1
    )
    ok = np.arange(n) != 3
    want = np.linalg.norm((com - planar3_com(res.q))[:, :2], axis=1)  # x and y rows only
    np.testing.assert_allclose(res.com_error[ok], want[ok], rtol=1e-12, atol=1e-15)
    assert np.all(res.com_error[ok][1:] > 1e-3)  # unconverged: the errors are real numbers
    assert np.all(res.result[ok][1:] == RESULTS.max_steps_reached)
    assert np.isnan(res.com_error[3]) and res.result[3] == RESULTS.nonfinite
    np.testing.assert_array_equal(res.q[3], res.q[2])


# ----------------------------------------------------------------------------- an arm
@functools.cache
def panda(dtype):
    return jk.robots.load("panda", dtype=dtype)


def arm_targets(robot, n, seed):
    q0 = np.asarray([0.0, -0.4, 0.0, -2.0, 0.0, 1.6, 0.8], robot.dtype)  # numpy: no program
    qs, gap = smooth_trajectory(robot, q0, n, seed, scale=0.5)
    return qs, gap, np.array(fk_tip(robot, qs))


def test_arm_sequence_is_tracked_and_a_nan_target_is_flagged_not_solved():
    robot = panda(np.float64)
    qs, gap, T = arm_targets(robot, 40, seed=2)
    T[20, 0, 3] = np.nan
    res = motion.retarget(robot, T, qs[0])  # one frame: (T, 4, 4) targets, (T,) errors
    assert res.position_error.shape == (40,)
    bad = np.zeros(40, bool)
    bad[20] = True
    assert res.result[20] == RESULTS.nonfinite and not res.converged[20]
    assert np.isnan(res.residual[20]) and np.isnan(res.position_error[20])
    np.testing.assert_array_equal(res.q[20], res.q[19])  # held, not a made-up answer
    assert np.all(res.converged[~bad]) and np.all(res.residual[~bad] <= 1e-10)
    Tq = fk_tip(robot, res.q)
    assert max_pose_error(Tq[~bad], T[~bad]) < 1e-6
    assert np.all(np.isfinite(res.q))
    steps = np.abs(np.diff(res.q, axis=0))
    assert steps.max() < 2 * gap  # redundant (7 dof): no jump between solutions


def test_float32_sequence_with_a_posture():
    robot = panda(np.float32)
    qs, _, T = arm_targets(robot, 30, seed=3)
    res = motion.retarget(robot, T.astype(np.float32), qs[0], posture=qs[0], posture_weight=0.2)
    assert res.q.dtype == np.float32
    assert np.all(res.converged), res.result
    Tq = fk_tip(robot, res.q)
    assert max_pose_error(Tq, T) < 1e-4


def test_arguments_are_checked():
    robot = panda(np.float64)
    T = np.broadcast_to(np.eye(4), (3, 4, 4))
    q0 = jnp.zeros(7)
    with pytest.raises(jk.ShapeError, match=r"T_targets must have shape \(T, 2, 4, 4\)"):
        motion.retarget(LEGS, T, jk.neutral(LEGS), FEET)
    with pytest.raises(jk.JaxkinError, match="smoothness must lie in"):
        motion.retarget(robot, T, q0, smoothness=2.0)
    with pytest.raises(jk.JaxkinError, match="iterations must be"):
        motion.retarget(robot, T, q0, iterations=0)
    with pytest.raises(jk.JaxkinError, match="posture_weight must lie in"):
        motion.retarget(robot, T, q0, posture=q0, posture_weight=-1.0)
    with pytest.raises(jk.ShapeError, match="posture"):
        motion.retarget(robot, T, q0, posture=jnp.zeros(3))
    arm = jk.robots.load("panda")  # a DH table: no masses, so no centre-of-mass target
    with pytest.raises(jk.ModelError, match="no inertial data"):
        motion.retarget(arm, np.zeros((3, 4, 4)), jk.neutral(arm), com=np.zeros((3, 3)))


# ----------------------------------------------------------------------------- chunked_scan
def test_chunked_scan_equals_lax_scan_and_carries_across_padded_chunks():
    def step(c, x, y):
        c = 0.5 * c + x * y
        return c, {"c": c, "x2": 2 * x}

    xs = np.arange(11.0)
    ys = np.cos(xs)
    want_c, want = jax.lax.scan(lambda c, xy: step(c, *xy), jnp.float64(1.0), (xs, ys))
    calls = []

    class Bar:
        def update(self, n):
            calls.append(n)

    c, got = chunked_scan(step, jnp.float64(1.0), xs, ys, chunk_size=4, progress=Bar())
    assert float(c) == pytest.approx(float(want_c), abs=1e-15)  # the padding did not move it
    np.testing.assert_allclose(got["c"], want["c"], atol=1e-15)
    np.testing.assert_array_equal(got["x2"], 2 * xs)
    assert calls == [4, 4, 3]  # 11 rows: chunks of 4, 4 and 4 (one padded row)
    init = jnp.float64(2.0)
    with jax_compiles() as events:  # the same step, shapes and dtypes: the kept program
        c2, again = chunked_scan(step, init, xs[::-1], ys, chunk_size=4)
    assert events == []
    want_c2, want2 = jax.lax.scan(lambda c, xy: step(c, *xy), init, (xs[::-1], ys))
    assert float(c2) == pytest.approx(float(want_c2), abs=1e-15)
    np.testing.assert_allclose(again["c"], want2["c"], atol=1e-15)


def test_kept_scans_are_bounded():
    """At most ``SCANNED_CACHE_SIZE`` compiled scans are kept, the least recently used dropped;
    an unhashable step is compiled afresh, not kept."""

    class Unhashable:
        __hash__ = None

        def __call__(self, c, x):
            return c + x, c

    batch._scanned_cache.clear()
    steps = [lambda c, x, k=k: (c + k * x, c) for k in range(batch.SCANNED_CACHE_SIZE + 1)]
    first = batch._scanned(steps[0])
    assert batch._scanned(steps[0]) is first
    for step in steps[1:]:
        batch._scanned(step)
    assert len(batch._scanned_cache) == batch.SCANNED_CACHE_SIZE
    assert steps[0] not in batch._scanned_cache and steps[-1] in batch._scanned_cache
    step = Unhashable()
    assert batch._scanned(step) is not batch._scanned(step)
    assert len(batch._scanned_cache) == batch.SCANNED_CACHE_SIZE
