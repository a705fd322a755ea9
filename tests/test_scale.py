"""Speed and scale, guarded without timing: compile counts, HLO structure, chunked == unchunked ==
sharded, streaming to disk, long chains through lax.scan.

Where the robot is not the point (compile counts, chunking, streaming, sharding) it is a small one
(``scara``, four joints): a Panda's kernels compile several times slower and test nothing more.
The test's own programs are compiled as jaxkin compiles its own (:func:`compiled`).
"""

import itertools
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE

import jaxkin as jk
import jaxkin.testing as jkt
from jaxkin import _forward as kinematics
from jaxkin import _jit, batch

SMALL = "scara"  # revolute and prismatic joints


def compiled(f, **kwargs):
    """``jax.jit(f)`` with the compiler options of jaxkin's own executables (XLA's CPU fusion
    emitters off: these kernels compile two to three times faster, same tracing and caching)."""
    return jax.jit(f, compiler_options=_jit.compiler_options() or None, **kwargs)


def fast(f):
    """``jax.jit(f)`` with the suite's options for one-off test programs (``_xla.FAST_COMPILE``:
    the same numbers to rounding, a cheaper compile), where no bit-for-bit comparison with
    jaxkin's own executables is made."""
    return jax.jit(f, compiler_options=FAST_COMPILE)


def _chain(n, seed=0, convention="standard", prismatic=True):
    rng = np.random.default_rng(seed)
    kinds = rng.choice(["revolute", "prismatic"], n) if prismatic else ["revolute"] * n
    rows = [
        dict(
            a=0.1 * rng.normal(),
            alpha=float(rng.choice([0.0, np.pi / 2, -np.pi / 2, rng.normal()])),
            d=0.1 * rng.normal(),
            theta=rng.normal(),
            joint=str(k),
            lower=-np.pi if k == "revolute" else -0.5,
            upper=np.pi if k == "revolute" else 0.5,
        )
        for k in kinds
    ]
    return jk.Robot.from_dh(rows, convention=convention, tool=np.eye(4))


# --- compile counts ----------------------------------------------------------------------------
def test_kernel_compiles_once_per_shape_and_dtype_never_per_parameter_value():
    robot = jk.robots.load(SMALL)
    traces = []

    def kernel(r, qs):
        traces.append(qs.shape)
        return jax.vmap(lambda q: jk.geometric_jacobian(r, q))(qs)

    f = compiled(kernel)
    qs = np.zeros((64, 4))  # host arrays and host updates: no eager program per new value
    f(robot, qs).block_until_ready()
    rng = np.random.default_rng(0)
    tool = np.array(robot.tool)
    tool[2, 3] += 0.01
    for _ in range(5):  # new parameter values: same compiled kernel
        r2 = robot.replace(
            params={
                k: np.asarray(v) + 0.01 * rng.normal(size=v.shape) for k, v in robot.params.items()
            },
            tool=tool,
        )
        f(r2, qs + 0.1).block_until_ready()
    assert len(traces) == 1
    f(robot, np.zeros((65, 4))).block_until_ready()  # new shape: one more
    f(robot.astype(np.float32), qs.astype(np.float32)).block_until_ready()  # new dtype
    assert len(traces) == 3
    assert f._cache_size() == 3


def test_chunked_map_compiles_once_for_any_number_of_chunks():
    robot = jk.robots.load(SMALL)
    traces = []

    def fn(q):
        traces.append(1)
        return jk.geometric_jacobian(robot, q)

    qs = np.random.default_rng(1).uniform(-1, 1, (1003, 4))
    out = batch.chunked_map(fn, qs, chunk_size=128)
    assert len(traces) == 1
    expected = compiled(jax.vmap(lambda q: jk.geometric_jacobian(robot, q)))(qs)
    np.testing.assert_array_equal(out, np.asarray(expected))
    # the same function again (chunk shape and dtype too): its program is kept, nothing retraced
    again, stats = batch.chunked_map(fn, qs, chunk_size=128, return_stats=True)
    assert len(traces) == 1 and stats.n_chunks == 8
    np.testing.assert_array_equal(again, out)


# --- long chains -------------------------------------------------------------------------------
def _every_entry_point(robot):
    """Functions ``(q, qd) -> [outputs]`` that together call every kinematics entry point (fk,
    geometric Jacobians of two frames in every reference, twist, analytical Jacobian): three
    programs, not one (XLA compiles the three in about three quarters of the time)."""

    def jacobians(frame):
        point = [0.1, -0.2, 0.3]
        return lambda q, qd: [
            jk.geometric_jacobian(robot, q, frame=frame, point=point, reference=ref)
            for ref in jk.jacobians.REFERENCES
        ]

    def the_rest(q, qd):
        return [
            jk.fk_all(robot, q),
            jk.fk(robot, q, frame="link7"),
            jk.twist(robot, q, qd),
            jk.analytical_jacobian(robot, q, "zyz", return_margin=True)[0],
        ]

    return [the_rest, jacobians(None), jacobians("link7")]


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_scan_path_equals_unrolled_path(convention, monkeypatch):
    """An 8-joint chain whose placements do not fold is scanned by default (SCAN_MIN_UNFOLDED;
    and a 36-joint one by its length: test_long_chain_program_size_does_not_grow_with_length);
    lifting both thresholds unrolls it: the two passes agree. Each pass is traced afresh, in
    three programs (:func:`_every_entry_point`; eager calls would reuse the executables cached
    for the first pass: the robot is the same value, so the unrolled pass would never run). The
    scanned pass runs compiled (``lax.scan`` lowered is what is under test); the unrolled pass,
    the reference, runs op by op (``jax.disable_jit``: its primitives compile once per shape, for
    both conventions, instead of three programs each; the same operations' values)."""
    robot = _chain(8, seed=3, convention=convention)
    assert kinematics.uses_scan(robot)
    q = jnp.asarray(np.random.default_rng(2).uniform(-1, 1, robot.dof))
    qd = jnp.asarray(np.random.default_rng(3).uniform(-1, 1, robot.dof))
    outs = []
    defaults = (kinematics.SCAN_MIN_JOINTS, kinematics.SCAN_MIN_UNFOLDED)
    for joints, unfolded in (defaults, (10**9, 10**9)):  # scanned, then unrolled
        monkeypatch.setattr(kinematics, "SCAN_MIN_JOINTS", joints)
        monkeypatch.setattr(kinematics, "SCAN_MIN_UNFOLDED", unfolded)
        assert kinematics.uses_scan(robot) == (joints == defaults[0])
        scanned = joints == defaults[0]
        programs = [fast(every) for every in _every_entry_point(robot)]
        scans = sum(str(p.trace(q, qd).jaxpr).count(" scan[") for p in programs)
        assert (scans > 0) == scanned, scans  # the pass asked for was traced
        if scanned:
            outs.append([out for p in programs for out in p(q, qd)])
        else:
            with jax.disable_jit():
                outs.append([out for every in _every_entry_point(robot) for out in every(q, qd)])
    for a, b in zip(*outs, strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-12)


def test_scan_path_triangle_and_finite_differences():
    robot = _chain(33, seed=5)
    q = np.random.default_rng(4).uniform(-0.5, 0.5, robot.dof)
    jkt.assert_jacobian_consistent(robot, q, frame="link20")
    jkt.assert_jacobian_consistent(robot, q)


def test_long_chain_program_size_does_not_grow_with_length():
    """Compile time is bounded: the lowered program of a scanned chain is the same size for 50
    and 400 joints (the per-joint step is traced once)."""
    sizes = []
    for n in (50, 400):
        robot = _chain(n, seed=n, prismatic=False)
        # the robot as an argument; count operations (lines), not characters: per-joint
        # masks are constant arrays whose printed literal grows with n, the program does not
        lowered = jax.jit(jk.geometric_jacobian).lower(robot, jnp.zeros(n))
        sizes.append(len(lowered.as_text().splitlines()))
    assert sizes[1] == sizes[0], sizes


def test_three_thousand_joint_chain_runs():
    robot = _chain(3000, seed=7, prismatic=False)
    q = np.random.default_rng(8).uniform(-0.1, 0.1, 3000)
    J = fast(lambda q: jk.geometric_jacobian(robot, q))(q)
    assert J.shape == (6, 3000) and np.all(np.isfinite(np.asarray(J)))

    # the tip's column sums are the tip's velocity (linear, angular) for qd = 1: compare with
    # jvp, the velocity computed in the jvp's program
    def tip_velocity(q):
        T, Tdot = jax.jvp(lambda q: jk.fk(robot, q), (q,), (jnp.ones(3000),))
        return jnp.concatenate([Tdot[:3, 3], jk.spatial.vee(Tdot[:3, :3] @ T[:3, :3].T)])

    np.testing.assert_allclose(
        np.asarray(J).sum(axis=1), np.asarray(fast(tip_velocity)(q)), rtol=0, atol=1e-9
    )


# --- chunked, streamed, written to disk --------------------------------------------------------
def _kernel(robot):
    def fn(q, qd):
        J = jk.geometric_jacobian(robot, q)
        return {"J": J, "twist": J @ qd}

    return fn


def test_path_outputs_equal_in_memory_results(tmp_path):
    robot = jk.robots.load(SMALL)
    rng = np.random.default_rng(5)
    qs, qds = rng.uniform(-3, 3, (777, 4)), rng.uniform(-1, 1, (777, 4))
    fn = _kernel(robot)  # one function: the second call reuses the first one's program
    mem = batch.chunked_map(fn, qs, qds, chunk_size=100)
    npz = batch.chunked_map(fn, qs, qds, chunk_size=100, out=tmp_path / "r.npz")
    with np.load(npz) as z:
        for k in ("J", "twist"):
            np.testing.assert_array_equal(z[k], mem[k])
    d = batch.chunked_map(fn, qs, qds, chunk_size=64, out=tmp_path / "r_dir")
    np.testing.assert_array_equal(np.load(os.path.join(d, "J.npy"), mmap_mode="r"), mem["J"])
    assert sorted(os.listdir(tmp_path)) == ["r.npz", "r_dir"]  # no temporaries left


def test_path_output_is_atomic(tmp_path):
    calls = []

    def fn(q):
        calls.append(1)
        return q * 2.0

    class Boom(RuntimeError):
        pass

    def failing_feed(*a, **k):
        raise Boom

    original = batch._feed
    batch._feed = failing_feed
    try:
        with pytest.raises(Boom):
            batch.chunked_map(fn, np.ones((10, 2)), out=tmp_path / "x.npz")
    finally:
        batch._feed = original
    assert os.listdir(tmp_path) == []


def test_stream_map_equals_chunked_map_and_compiles_once():
    robot = jk.robots.load(SMALL)
    rng = np.random.default_rng(6)
    qs, qds = rng.uniform(-1, 1, (1000, 4)), rng.uniform(-1, 1, (1000, 4))
    traces = []

    def fn(q, qd):
        traces.append(1)
        return _kernel(robot)(q, qd)

    cuts = [0, 3, 250, 251, 700, 1000]
    gen = ((qs[a:b], qds[a:b]) for a, b in itertools.pairwise(cuts))
    parts = list(batch.stream_map(fn, gen, chunk_size=128))
    assert len(traces) == 1
    assert [p["J"].shape[0] for p in parts] == [128] * 7 + [104]
    whole = batch.chunked_map(_kernel(robot), qs, qds, chunk_size=128)
    np.testing.assert_array_equal(np.concatenate([p["J"] for p in parts]), whole["J"])
    np.testing.assert_array_equal(np.concatenate([p["twist"] for p in parts]), whole["twist"])


def test_bad_devices_argument():
    with pytest.raises(jk.JaxkinError, match="devices must be None, 'all'"):
        batch.chunked_map(lambda q: q, np.ones((3, 2)), devices="gpu")
    with pytest.raises(jk.JaxkinError, match="devices is empty"):
        batch.chunked_map(lambda q: q, np.ones((3, 2)), devices=[])


# --- sharded over several devices (host CPU devices in a subprocess) ---------------------------
SHARDED = textwrap.dedent(
    """
    import jax, numpy as np
    jax.config.update("jax_enable_x64", True)
    import jaxkin as jk
    from jaxkin import _jit, batch
    assert len(jax.devices()) == 4, jax.devices()
    robot = jk.robots.load("scara")  # small: what is tested is the sharding
    rng = np.random.default_rng(0)
    qs, qds = rng.uniform(-1, 1, (1001, 4)), rng.uniform(-1, 1, (1001, 4))
    def fn(q, qd):
        J = jk.geometric_jacobian(robot, q)
        return J, J @ qd
    one = batch.chunked_map(fn, qs, qds, chunk_size=250, devices=jax.devices()[:1])
    four = batch.chunked_map(fn, qs, qds, chunk_size=250)  # default: all 4 devices
    options = _jit.compiler_options() or None  # as jaxkin compiles: a cheaper compile
    ref = jax.jit(jax.vmap(fn), compiler_options=options)(qs, qds)
    for a, b, c in zip(one, four, ref):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(a, np.asarray(c), rtol=0, atol=1e-15)
    # the compiled chunk really is split over the 4 devices (chunked_map's own program above,
    # kept per function: traced, lowered and compiled again from JAX's caches)
    chunk = batch._chunking(250, len(qs), 4)[0]  # four's chunk: 204 rows, a multiple of 4
    traced = batch._trace(fn, [qs, qds], chunk, batch._mesh(None))
    shard = traced.lower().compile(options).input_shardings[0][0]
    assert len(shard.device_set) == 4, shard
    print("sharded ok")
    """
)


def test_sharded_equals_unsharded_on_four_host_devices():
    # the run's XLA_FLAGS (its quick compiles) kept: one and four devices compile alike
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=4"
    env = dict(os.environ, XLA_FLAGS=flags.strip())
    env["JAX_PLATFORMS"] = "cpu"
    res = subprocess.run(
        [sys.executable, "-c", SHARDED], env=env, capture_output=True, text=True, timeout=600
    )
    assert res.returncode == 0, res.stderr[-3000:]
    assert "sharded ok" in res.stdout
