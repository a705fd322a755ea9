"""The Robot pytree under JAX transformations, precision, and errors for bad input."""

import logging
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE
from hypothesis import given

import jaxkin as jk
import jaxkin.testing as jkt

ROWS = [
    dict(a=0.0, alpha=math.pi / 2, d=0.4, theta=0.0, joint="revolute", lower=-3, upper=3),
    dict(a=0.5, alpha=0.0, d=0.0, theta=0.2, joint="revolute", offset=0.1),
    dict(a=0.1, alpha=-math.pi / 2, d=0.2, theta=0.0, joint="prismatic", lower=0, upper=1),
    dict(a=0.0, alpha=math.pi / 2, d=0.3, theta=0.0, joint="revolute"),
]
Q = jnp.array([0.3, -0.7, 0.25, 1.1])


@pytest.fixture(params=["standard", "modified"])
def robot(request):
    return jk.Robot.from_dh(ROWS, convention=request.param, tool=np.eye(4), name="test_arm")


def _all_outputs(robot, q):
    return (
        jk.fk_all(robot, q),
        jk.geometric_jacobian(robot, q),
        jk.geometric_jacobian(robot, q, reference="local"),
        jk.analytical_jacobian(robot, q, "zyz", return_margin=True)[0],
        jk.twist(robot, q, 0.5 * q),
    )


def test_jit_equals_eager(robot):
    eager = _all_outputs(robot, Q)
    # the robot traced: the kernels over traced parameters (not the eager ones, constants folded)
    jitted = jax.jit(_all_outputs, compiler_options=FAST_COMPILE)(robot, Q)
    for a, b in zip(eager, jitted, strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-13)


def test_vmap_over_configurations_equals_loop(robot):
    qs = np.random.default_rng(0).uniform(-1, 1, size=(17, 4))
    # one compiled program for the batch (eagerly, vmap runs a hundred primitives op by op)
    batched = jax.jit(jax.vmap(lambda q: _all_outputs(robot, q)), compiler_options=FAST_COMPILE)(qs)
    for i in range(qs.shape[0]):
        single = _all_outputs(robot, qs[i])
        for a, b in zip(batched, single, strict=True):
            np.testing.assert_allclose(np.asarray(a[i]), np.asarray(b), rtol=0, atol=1e-13)


def test_vmap_over_a_stack_of_robots(robot):
    rng = np.random.default_rng(1)
    robots = [  # new values and their stack made on the host (no eager program per leaf)
        robot.replace(
            params={
                k: np.asarray(v) + 0.05 * rng.normal(size=v.shape) for k, v in robot.params.items()
            }
        )
        for _ in range(5)
    ]
    stacked = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *robots)
    # one compiled program for the stack (at top level, vmap runs the kernel op by op)
    Js = jax.jit(jax.vmap(lambda r: jk.geometric_jacobian(r, Q)), compiler_options=FAST_COMPILE)(
        stacked
    )
    with jax.disable_jit():  # each robot used once: op by op, not one compiled kernel per robot
        expected = [np.asarray(jk.geometric_jacobian(r, Q)) for r in robots]
    for i in range(len(robots)):
        np.testing.assert_allclose(np.asarray(Js[i]), expected[i], rtol=0, atol=1e-13)


def test_grad_with_respect_to_dh_parameters_matches_finite_differences(robot):
    target = jnp.array([0.2, 0.3, 0.4])

    def loss(r):
        p = jk.fk(r, Q)[:3, 3]
        J = jk.geometric_jacobian(r, Q)
        return jnp.sum((p - target) ** 2) + 0.1 * jnp.sum(J**2)

    g = jax.grad(loss)(robot)
    h = 1e-6
    # the robot traced: one compile for every perturbed robot
    loss_of = jax.jit(loss, compiler_options=FAST_COMPILE)
    for key in ("a", "alpha", "d", "theta"):
        assert g.params[key].shape == robot.params[key].shape
        value = np.asarray(robot.params[key])  # steps on the host: no program per update
        for i in range(robot.n_joints):
            e = h * np.eye(robot.n_joints)[i]
            plus = robot.replace(params={**robot.params, key: value + e})
            minus = robot.replace(params={**robot.params, key: value - e})
            fd = (loss_of(plus) - loss_of(minus)) / (2 * h)
            assert abs(float(g.params[key][i]) - float(fd)) < 1e-7, (key, i)
    # jacfwd with respect to the parameters works as well (forward mode)
    dT = jax.jit(jax.jacfwd(lambda r: jk.fk(r, Q)), compiler_options=FAST_COMPILE)(robot)
    assert dT.params["a"].shape == (4, 4, robot.n_joints)
    # and with respect to base and tool
    assert np.all(np.isfinite(np.asarray(g.base))) and np.all(np.isfinite(np.asarray(g.tool)))


def test_grad_with_respect_to_placement_parameters():
    robot = jk.robots.load("niryo_one")
    q = jnp.asarray(robot.configurations["zero"]) + 0.1

    def f(r):
        return jnp.sum(jk.fk(r, q)[:3, 3] ** 2)

    # robot traced: one compiled program for the gradient and every perturbed robot's value
    value_and_grad = jax.jit(jax.value_and_grad(f), compiler_options=FAST_COMPILE)
    g = value_and_grad(robot)[1]
    h = 1e-6

    def f_of(r):
        return value_and_grad(r)[0]

    for key in ("xyz", "rpy"):
        value = np.asarray(robot.params[key])  # steps on the host: no program per update
        for j in range(robot.n_joints):
            for k in range(3):
                e = np.zeros((robot.n_joints, 3))
                e[j, k] = h
                plus = robot.replace(params={**robot.params, key: value + e})
                minus = robot.replace(params={**robot.params, key: value - e})
                fd = f_of(plus) - f_of(minus)
                assert abs(float(g.params[key][j, k]) - float(fd) / (2 * h)) < 1e-7


def test_new_parameter_values_never_retrace(robot):
    traces = []

    @jax.jit(compiler_options=FAST_COMPILE)
    def jac(r, q):
        traces.append(1)
        return jk.geometric_jacobian(r, q)

    jac(robot, Q).block_until_ready()
    for s in (0.1, 0.2, 0.3):  # new values made on the host (no eager program per update)
        base = np.array(robot.base)
        base[0, 3] = s
        r2 = robot.replace(
            params={k: np.asarray(v) * (1 + s) for k, v in robot.params.items()}, base=base
        )
        jac(r2, np.asarray(Q) + s).block_until_ready()
    assert len(traces) == 1
    # a new dtype is a new trace (expected); a new topology too
    jac(robot.astype(np.float32), Q.astype(np.float32)).block_until_ready()
    assert len(traces) == 2


def test_robot_pytree_has_only_float_leaves(robot):
    leaves = jax.tree_util.tree_leaves(robot)
    assert leaves and all(jnp.issubdtype(x.dtype, jnp.floating) for x in leaves)
    assert hash(jax.tree_util.tree_structure(robot)) is not None


# --- float32 ------------------------------------------------------------------------------------
@given(jkt.robots_and_configurations(1, 8, dtype=np.float32))
def test_float32_within_float32_tolerance(robot_q):
    robot32, q = robot_q
    q32 = np.asarray(q, dtype=np.float32)
    robot64 = robot32.astype(np.float64)
    # The float32 Jacobian under test, its float64 references and the autodiff Jacobian in one
    # compiled program for this robot (the robot closed over, its constants folded, as in its
    # eager executable): op by op, the float32 kernel compiles ten primitives or so per example
    # (every new dof is a new shape), the float64 kernels every primitive again in float64, and
    # jacfwd's vmap over the dof about 20 per dof, several times the cost of one program.
    program = jax.jit(
        lambda q32, q64: (
            jk.geometric_jacobian(robot32, q32),
            jk.geometric_jacobian(robot64, q64),
            jk.fk_all(robot64, q64),
            jk.jacobian_fwd(robot32, q32),
        ),
        compiler_options=FAST_COMPILE,
    )
    J32, J64, Ts, Jf = program(q32, q32.astype(np.float64))
    assert J32.dtype == jnp.float32
    J64, Ts, Jf = (np.asarray(x) for x in (J64, Ts, Jf))
    reach = max(1.0, float(np.max(np.linalg.norm(Ts[:, :3, 3] - Ts[:1, :3, 3], axis=1))))
    eps32 = np.finfo(np.float32).eps
    tol = 4 * eps32 * (1 + float(np.max(np.abs(q)))) * reach * robot32.dof * 4
    np.testing.assert_allclose(np.asarray(J32), J64, rtol=0, atol=tol)
    # hand-built vs autodiff within float32 (tests/README.md: 1e-6 scaled by reach)
    np.testing.assert_allclose(np.asarray(J32), Jf, rtol=0, atol=1e-6 * reach * robot32.dof)


def test_float32_robot_and_float32_q_stay_float32():
    # the four-joint arm of this file: the dtype is the point, not the robot (a Puma's kernels
    # compile about twice as slowly)
    r = jk.Robot.from_dh(ROWS, dtype=np.float32)
    q = jnp.zeros(r.dof, dtype=jnp.float32)
    assert jk.fk(r, q).dtype == jnp.float32
    assert jk.geometric_jacobian(r, q).dtype == jnp.float32
    assert jk.analytical_jacobian(r, q, return_margin=True)[0].dtype == jnp.float32


class _Compiles(logging.Handler):
    """The programs JAX compiles while in use (``with _Compiles() as c: ...; c.names``)."""

    def __init__(self):
        super().__init__()
        self.names = []

    def emit(self, record):
        if record.getMessage().startswith("Compiling "):
            self.names.append(record.getMessage().split()[1])

    def __enter__(self):
        self._log = jax.log_compiles(True)
        self._log.__enter__()
        logging.getLogger("jax").addHandler(self)
        return self

    def __exit__(self, *exc):
        logging.getLogger("jax").removeHandler(self)
        self._log.__exit__(*exc)


def test_building_and_casting_a_robot_compiles_nothing():
    """A robot's numpy leaves reach JAX by device_put, and astype casts concrete leaves on the
    host: no program per leaf shape (jnp.array of numpy and jnp.asarray(x, dtype) compile one
    each, for every new robot size), and the same bits as XLA's convert (round to nearest,
    subnormals flushed to zero, overflow to inf)."""
    rows = [dict(ROWS[i % 4]) for i in range(7)]  # a size no other test builds
    rows[0]["a"] = 1e-39  # subnormal in float32
    rows[1]["d"] = 1e39  # beyond float32
    with _Compiles() as compiles:
        robot = jk.Robot.from_dh(rows, dtype=np.float64)
        robot32 = robot.astype(np.float32)
        again = robot32.astype(np.float64)
    assert compiles.names == []
    assert robot32.dtype == np.float32 and again.dtype == np.float64
    for name in ("a", "d"):  # XLA's casts, compiled: the same bits
        for src, dst in ((robot, robot32), (robot32, again)):
            xla = jnp.asarray(src.params[name], dst.dtype)
            np.testing.assert_array_equal(np.asarray(dst.params[name]), np.asarray(xla))
    assert float(robot32.params["a"][0]) == 0.0 and np.isinf(robot32.params["d"][1])


def test_float64_request_with_x64_off_warns_loudly():
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.warns(jk.JaxkinPrecisionWarning, match="jax_enable_x64"):
            r = jk.Robot.from_dh(ROWS, dtype=np.float64)
        assert r.dtype == np.float32
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            r = jk.Robot.from_dh(ROWS)  # default dtype: no warning
            assert r.dtype == np.float32
            J = jk.geometric_jacobian(r, np.zeros(4, dtype=np.float32))
            assert J.dtype == jnp.float32
    finally:
        jax.config.update("jax_enable_x64", True)


# --- bad input: a clear jaxkin error naming what is wrong ----------------------------------------
@pytest.mark.parametrize(
    "q, match",
    [
        (np.zeros(3), r"shape \(4,\).*got shape \(3,\).*joint1"),
        (np.zeros(5), r"shape \(4,\).*got shape \(5,\)"),
        (np.zeros((10, 4)), r"got shape \(10, 4\).*jax\.vmap"),
        (np.zeros(4, dtype=complex), "complex"),
        ("abc", "must"),
        ([0.0, 1.0, "x", 2.0], "sequence of numbers"),
    ],
)
def test_bad_q_raises_shape_error(robot, q, match):
    for fn in (jk.fk, jk.fk_all, jk.geometric_jacobian, jk.analytical_jacobian):
        with pytest.raises(jk.ShapeError, match=match):
            fn(robot, q)


def test_bad_qd_and_point_and_frame_and_reference(robot):
    with pytest.raises(jk.ShapeError, match="qd must have shape"):
        jk.twist(robot, Q, np.zeros(3))
    with pytest.raises(jk.ShapeError, match="point must have shape"):
        jk.geometric_jacobian(robot, Q, point=np.zeros(4))
    with pytest.raises(jk.ModelError, match=r"no frame 'flange'.*link1"):
        jk.fk(robot, Q, frame="flange")
    with pytest.raises(jk.ModelError, match="out of range"):
        jk.fk(robot, Q, frame=99)
    with pytest.raises(jk.JaxkinError, match="reference must be one of"):
        jk.geometric_jacobian(robot, Q, reference="body")
    with pytest.raises(jk.JaxkinError, match="representation must be one of"):
        jk.analytical_jacobian(robot, Q, representation="quaternion")
    with pytest.raises(jk.ShapeError, match="jaxkin Robot"):
        jk.fk("not a robot", Q)


def _row(**changes):
    row = dict(a=0.1, alpha=0.2, d=0.3, theta=0.4, joint="revolute")
    row.update(changes)
    return {k: v for k, v in row.items() if v is not None}


@pytest.mark.parametrize(
    "rows, match",
    [
        ([_row(a=None)], r"DH row 0 is missing key 'a'"),
        ([_row(), _row(joint=None)], r"DH row 1 is missing key 'joint'"),
        ([_row(d=float("nan"))], r"DH row 0, key 'd' must be finite, got nan"),
        ([_row(alpha=float("inf"))], r"key 'alpha' must be finite"),
        ([_row(theta="x")], r"key 'theta' must be a number, got 'x'"),
        ([_row(joint="spherical")], r"unknown joint kind 'spherical'.*'revolute' or 'prismatic'"),
        ([_row(lower=1.0, upper=0.0)], r"lower limit 1.0 is above upper limit 0.0"),
        ([_row(lower=float("nan"))], r"'lower' is NaN"),
        ([_row(lenght=1.0)], r"unknown key\(s\) \['lenght'\]"),
        ([_row(name="j"), _row(name="j")], r"duplicate joint name 'j'"),
        ([], r"non-empty sequence"),
        (_row(), r"non-empty sequence"),
        (["not a mapping"], r"DH row 0 must be a mapping"),
    ],
)
def test_bad_dh_rows_raise_model_error(rows, match):
    with pytest.raises(jk.ModelError, match=match):
        jk.Robot.from_dh(rows)


def test_bad_convention_base_tool():
    with pytest.raises(jk.ModelError, match="convention must be 'standard' or 'modified'"):
        jk.Robot.from_dh(ROWS, convention="craig")
    with pytest.raises(jk.ModelError, match="base must be a 4x4"):
        jk.Robot.from_dh(ROWS, base=np.eye(3))
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(jk.ModelError, match="tool must be a homogeneous transform"):
        jk.Robot.from_dh(ROWS, tool=bad)
    with pytest.raises(jk.ModelError, match="dtype must be float32 or float64"):
        jk.Robot.from_dh(ROWS, dtype=np.int32)


def test_bad_joint_placements_raise_model_error():
    good = dict(name="j", type="revolute", child="l", axis=(0, 0, 1))
    with pytest.raises(jk.ModelError, match="joint 'j' has a zero axis"):
        jk.Robot.from_joints([{**good, "axis": (0, 0, 0)}])
    with pytest.raises(jk.ModelError, match="unknown type 'spherical'"):
        jk.Robot.from_joints([{**good, "type": "spherical"}])
    with pytest.raises(jk.ModelError, match="parent frame 'nowhere' is not defined"):
        jk.Robot.from_joints([{**good, "parent": "nowhere"}])
    with pytest.raises(jk.ModelError, match="frame 'l' already has a parent"):
        jk.Robot.from_joints([good, {**good, "name": "k"}])
    with pytest.raises(jk.ModelError, match="'xyz' must be finite"):
        jk.Robot.from_joints([{**good, "xyz": (0, float("inf"), 0)}])
    assert jk.Robot.from_joints([{**good, "type": "fixed"}]).dof == 0  # loads (test_zero_dof)


def test_unknown_robot_name():
    with pytest.raises(jk.UnknownRobotError, match=r"unknown robot 'nyrio_one'.*niryo_one"):
        jk.robots.load("nyrio_one")
    assert isinstance(jk.UnknownRobotError("x"), ValueError)


def test_named_configurations_and_repr():
    r = jk.robots.load("niryo_one")
    assert set(r.configurations) >= {"zero"}
    assert "niryo_one" in repr(r) and "dof=6" in repr(r)
    with pytest.raises(jk.ModelError, match="6 finite joint values"):
        r.with_configurations(bad=[0.0, 1.0])
