"""The kernels' structure, guarded by counting operations (never the clock): float32 robots fold
their +-90 degree placements as float64 ones do, and one frame of a large tree traces only the
joints on its path. Results are checked against float64 and against independently built robots."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE, hlo_counts, jaxpr_counts, jaxpr_eqns

import jaxkin as jk
from jaxkin import _forward

EPS32 = float(np.finfo(np.float32).eps)


def _jacobians(robot):
    return jax.vmap(lambda q: jk.geometric_jacobian(robot, q))


# --- float32 folds like float64 ----------------------------------------------------------------
@pytest.mark.parametrize("name", ["panda", "ur5", "puma560"])
def test_float32_kernel_traces_the_float64_program(name):
    robot = jk.robots.load(name)
    counts = {}
    for dt in (np.float64, np.float32):
        c = jaxpr_counts(_jacobians(robot.astype(dt)), jnp.zeros((4, robot.dof), dt))
        counts[dt] = {k: c[k] for k in ("sin", "cos", "mul", "add", "sub", "neg")}
    assert counts[np.float32] == counts[np.float64], counts
    assert counts[np.float64]["sin"] == counts[np.float64]["cos"] == 1  # one stacked sin/cos


def test_float32_compiled_panda_kernel_has_the_float64_structure():
    """The compiled programs match op for op: before snapping in a dtype-aware way the float32
    Panda kernel had 27 fusions, 34 sin/cos and 189 multiplies against 22, 23 and 104."""
    robot = jk.robots.load("panda")
    counts = {}
    for dt in (np.float64, np.float32):
        c = hlo_counts(_jacobians(robot.astype(dt)), jnp.zeros((256, 7), dt))
        counts[dt] = {k: c[k] for k in ("sine", "cosine", "multiply", "add", "fusion")}
    assert counts[np.float32] == counts[np.float64], counts
    assert counts[np.float64]["sine"] + counts[np.float64]["cosine"] <= 2 * 7 + 12, counts


def test_snap_tolerance_by_dtype():
    assert _forward.snap_tolerance(np.float64) == _forward.SNAP
    tol32 = _forward.snap_tolerance(np.float32)
    # cos and sin of float32-rounded right angles up to 2 pi fall inside; real small angles don't
    for angle in (np.pi / 2, np.pi, 3 * np.pi / 2, 2 * np.pi, -np.pi / 2):
        a = float(np.float32(angle))
        assert min(abs(np.cos(a)), abs(abs(np.cos(a)) - 1)) <= tol32
        assert min(abs(np.sin(a)), abs(abs(np.sin(a)) - 1)) <= tol32
    assert np.sin(float(np.float32(1e-5))) > 10 * tol32


@pytest.mark.parametrize("name", ["panda", "ur5", "stanford"])
def test_float32_results_within_float32_tolerance_of_float64(name):
    """ORACLES.md: 4 eps32 (1 + max|q|) reach dof against the float64 result."""
    robot = jk.robots.load(name)
    r32 = robot.astype(np.float32)
    qs = np.random.default_rng(0).uniform(-np.pi, np.pi, (32, robot.dof))

    def kernel(r):
        return jax.jit(
            jax.vmap(lambda q: jk.jacobians.frame_jacobian(r, q)), compiler_options=FAST_COMPILE
        )

    J64, T64 = kernel(robot)(qs)
    J32, T32 = kernel(r32)(qs.astype(np.float32))
    assert J32.dtype == T32.dtype == jnp.float32
    reach = 1.0 + float(np.abs(np.asarray(T64)[:, :3, 3]).max())
    tol = 4 * EPS32 * (1 + np.pi) * reach * robot.dof
    np.testing.assert_allclose(np.asarray(J32, np.float64), np.asarray(J64), rtol=0, atol=tol)
    np.testing.assert_allclose(np.asarray(T32, np.float64), np.asarray(T64), rtol=0, atol=tol)


# --- one frame of a large tree -----------------------------------------------------------------
def _tree_specs(n, seed):
    rng = np.random.default_rng(seed)
    kinds = rng.choice(["revolute", "revolute", "prismatic", "fixed"], n)
    specs = []
    for j in range(n):
        specs.append(
            dict(
                name=f"j{j}",
                type=str(kinds[j]),
                parent="base" if j == 0 else f"l{rng.integers(0, j)}",
                child=f"l{j}",
                xyz=(0.2 * rng.normal(size=3)).tolist(),
                rpy=[float(rng.choice([0.0, np.pi / 2, rng.normal()])), 0.0, float(rng.normal())],
                axis=rng.normal(size=3).tolist(),
                lower=-1.0,
                upper=1.0,
            )
        )
    return specs


def _path_chain(specs, robot, frame):
    """The frame's path as a robot of its own (built from the same specs, the parent links
    renamed so they form a chain), and which q entries of the tree its joints are."""
    path = robot.ancestors(frame)
    chain = [dict(specs[j], parent="base" if i == 0 else None) for i, j in enumerate(path)]
    for c in chain[1:]:
        c.pop("parent")
    moving = [j for j in path if robot.kinds[j] != "fixed"]
    return jk.Robot.from_joints(chain), [robot.q_index[j] for j in moving]


@pytest.fixture(scope="module")
def tree():
    specs = _tree_specs(150, seed=3)
    return specs, jk.Robot.from_joints(specs)


def test_one_frame_of_a_tree_traces_only_its_ancestors(tree):
    _, robot = tree
    q = jnp.zeros(robot.dof)
    shallow = next(f for f in range(robot.n_frames) if 3 <= len(robot.ancestors(f)) < 6)
    scanned = [_forward.scan_joints(robot, f) is not None for f in (robot.n_frames - 1, shallow)]
    assert scanned == [True, False]  # both kinds of pass are exercised
    for frame in (robot.n_frames - 1, 60, shallow):
        path = robot.ancestors(frame)
        n_rev = sum(robot.kinds[j] == "revolute" for j in path)
        assert 0 < n_rev and len(path) < 40  # a random tree is shallow
        for fn, per_joint in (
            (lambda q, f=frame: jk.fk(robot, q, frame=f), 150),
            (lambda q, f=frame: jk.geometric_jacobian(robot, q, frame=f), 150),
            (lambda q, f=frame: jk.jacobian_fwd(robot, q, frame=f), 450),  # tangents too
        ):
            eqns = jaxpr_eqns(fn, q)
            if _forward.scan_joints(robot, frame) is None:
                # unrolled: every sin and cos evaluates the path's revolute angles, nothing else
                sizes = [e.invars[0].aval.size for e in eqns if e.primitive.name in ("sin", "cos")]
                assert sizes and set(sizes) == {n_rev}, sizes
            else:
                # scanned (a deep path of joints that do not fold): one step per path joint
                lengths = [e.params["length"] for e in eqns if e.primitive.name == "scan"]
                assert lengths and set(lengths) == {len(path)}, lengths
            assert len(eqns) < per_joint * len(path), len(eqns)


def test_one_frame_of_a_tree_equals_its_path_as_a_chain(tree):
    """fk and the Jacobian of a tree's frame equal those of its path built as a chain."""
    specs, robot = tree
    q = np.random.default_rng(5).uniform(-1, 1, robot.dof)
    frames = (robot.n_frames - 1, 60)

    def tree_kernels(q):
        return [
            (jk.fk(robot, q, frame=f), jk.geometric_jacobian(robot, q, frame=f)) for f in frames
        ]

    outs = jax.jit(tree_kernels, compiler_options=FAST_COMPILE)(q)
    for frame, (T, J) in zip(frames, outs, strict=True):
        chain, cols = _path_chain(specs, robot, frame)
        T_c, J_c = jax.jit(
            lambda qc, c=chain: (jk.fk(c, qc), jk.geometric_jacobian(c, qc)),
            compiler_options=FAST_COMPILE,
        )(q[cols])
        np.testing.assert_allclose(T, T_c, rtol=0, atol=1e-13)
        J = np.asarray(J)
        np.testing.assert_allclose(J[:, cols], J_c, rtol=0, atol=1e-13)
        assert np.all(J[:, np.setdiff1d(np.arange(robot.dof), cols)] == 0.0)


def test_tree_frame_under_jit_and_grad_over_the_robot(tree):
    """Traced leaves (jit over the robot, grad over its parameters) take the same path."""
    _, robot = tree
    q = jnp.asarray(np.random.default_rng(6).uniform(-1, 1, robot.dof))
    f = 60  # a short path: traced leaves fold nothing, so every entry is an op

    def kernel(r, q):
        grad = jax.grad(lambda r: jk.fk(r, q, frame=f)[0, 3])(r)
        return jk.geometric_jacobian(r, q, frame=f), grad

    J, grad = jax.jit(kernel, compiler_options=FAST_COMPILE)(robot, q)
    J_folded = jax.jit(
        lambda q: jk.geometric_jacobian(robot, q, frame=f), compiler_options=FAST_COMPILE
    )(q)
    np.testing.assert_allclose(J, J_folded, rtol=0, atol=1e-13)
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(grad))
    # only the path's parameters move the frame
    off_path = np.setdiff1d(np.arange(robot.n_joints), robot.ancestors(f))
    assert np.all(np.asarray(grad.params["xyz"])[off_path] == 0.0)
