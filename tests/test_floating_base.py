"""Floating bases, ball and planar joints: the configuration manifold against Pinocchio.

Oracles:

* example-robot-data robots loaded with ``floating_base=True`` against Pinocchio's
  ``buildModelFromUrdf(path, pin.JointModelFreeFlyer())``: every link frame's pose, and
  ``getFrameJacobian`` in LOCAL_WORLD_ALIGNED for the branch ends and a few other frames, and
  in LOCAL and WORLD too for a foot and the root link (1e-12 * max(1, reach));
  ``integrate``/``difference`` against ``pin.integrate``/``pin.difference``; ``jacobian_dot``
  against ``getFrameJacobianTimeVariation``. Pinocchio stores the quaternion (x, y, z, w) and
  visits siblings in its own order: joints are matched by name.
* URDF ``floating`` (below the root) and ``planar`` joints against Pinocchio's URDF parser.
* ``jacobian_fwd`` (autodiff of ``fk(integrate(q, v))`` at ``v = 0``) against the hand-built
  columns: independent of them (solo12).
* Hypothesis properties of ``integrate``/``difference`` on a small robot with every kind.

Each robot compiles one jitted ``vmap`` over all its configurations (robots closed over): solo12
(a quadruped) and simple_humanoid; a1, iCub and Talos (9 s, and 15 s and more of compile each)
run with ``JAXKIN_FULL_CORPUS=1`` only (CI's 20-minute budget). MuJoCo's free and ball joints:
tests/test_mjcf_free_ball.py.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sampling import random_q  # numpy: no sampler compiled per (n, nq); tested below
from _urdf_support import FULL_CORPUS
from _xla import FAST_COMPILE, sampler
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
from bench.peers import PinocchioLayout
from jaxkin.robots import example_robot_data as erd

pin = pytest.importorskip("pinocchio")

REFS = {"world_aligned": "LOCAL_WORLD_ALIGNED", "local": "LOCAL", "world": "WORLD"}
N = 12
ROBOTS = ["erd/solo12", "erd/simple_humanoid"] + (
    ["erd/a1", "erd/icub_reduced", "erd/talos_reduced"] if FULL_CORPUS else []
)
AUTODIFF_ROBOTS = ROBOTS[:1]  # jacobian_fwd through integrate is computed for these only


# ----------------------------------------------------------------------------- Pinocchio map
class PinMap(PinocchioLayout):
    """jaxkin (q, v) <-> Pinocchio (q, v) of a model whose joints have jaxkin's names: the
    bench's one mapping (``bench.peers.PinocchioLayout``, tested against Pinocchio's own
    kinematics in test_bench_peers.py), with the model kept."""

    def __init__(self, robot: jk.Robot, model) -> None:
        super().__init__(robot, model)
        self.model = model

    J = PinocchioLayout.columns_to_jaxkin  # a Pinocchio (6, nv) matrix in jaxkin's column order


def same_configuration(robot: jk.Robot, a, b) -> float:
    """Largest difference of two configurations, each quaternion compared up to sign."""
    a, b = np.array(a, dtype=float), np.array(b, dtype=float)
    for j in robot.multi_dof_joints:
        qi = robot.q_index[j]
        s = {"free": slice(qi + 3, qi + 7), "ball": slice(qi, qi + 4)}.get(robot.kinds[j])
        if s is not None and np.dot(a[s], b[s]) < 0:
            b[s] = -b[s]
    return float(np.max(np.abs(a - b)))


def test_same_configuration_compares_quaternions_up_to_sign():
    robot = jk.Robot.from_joints([dict(name="b", type="ball", child="l")])
    assert same_configuration(robot, [1.0, 0, 0, 0], [-1.0, 0, 0, 0]) == 0.0
    assert same_configuration(robot, [1.0, 0, 0, 0], [0.0, 1, 0, 0]) == 1.0


# ----------------------------------------------------------------------------- the kernel
def _frames(robot: jk.Robot) -> list[str]:
    """Branch ends (the feet, hands, head), the root link and a frame in the middle."""
    names = robot.frame_names
    picked = [*robot.default_frames, names[1], names[len(names) // 2]]
    return sorted(set(picked), key=names.index)


@functools.cache
def floating_case(name: str):
    """(robot, PinMap, qs, vs, out): everything jaxkin computes for ``name`` in one jit."""
    robot = jk.robots.load(name, floating_base=True, dtype=np.float64)
    model = pin.buildModelFromUrdf(str(erd.path(name)), pin.JointModelFreeFlyer())
    pmap = PinMap(robot, model)
    qs = random_q(robot, N, seed=7)
    vs = np.random.default_rng(7).uniform(-1.0, 1.0, (N, robot.nv))
    frames = _frames(robot)
    foot = robot.default_frames[0]  # a branch end

    def one(q, v):
        out = {
            "Ts": jk.fk_all(robot, q),
            "q1": jk.integrate(robot, q, v),
            "Jd": jk.jacobian_dot(robot, q, v, frame=foot, reference="local"),
        }
        if name in AUTODIFF_ROBOTS:  # the autodiff Jacobian's test (its own compile and trace)
            out["fwd"] = jk.jacobian_fwd(robot, q, frame=foot, reference="world")
        out["d"] = jk.difference(robot, q, out["q1"])
        # every reference for a foot and the root link, world_aligned for the others: one
        # multi-frame pass per reference (equal to single-frame calls bit for bit, as
        # test_multi_frame.py shows; a third of the program of one call per frame)
        ends = [foot, robot.frame_names[1]]
        for ref, fs in (("world_aligned", frames), ("local", ends), ("world", ends)):
            Js = jk.geometric_jacobian(robot, q, frame=fs, reference=ref)
            out.update({f"{f}/{ref}": Js[i] for i, f in enumerate(fs)})
        return out

    f = jax.jit(jax.vmap(one), compiler_options=FAST_COMPILE)
    out = jax.tree_util.tree_map(np.asarray, f(jnp.asarray(qs), jnp.asarray(vs)))
    return robot, pmap, qs, vs, out, frames


@pytest.mark.parametrize("name", ROBOTS)
def test_floating_base_poses_and_jacobians_match_pinocchio(name):
    robot, pmap, qs, _, out, frames = floating_case(name)
    model = pmap.model
    assert (robot.nq, robot.nv) == (model.nq, model.nv)
    assert robot.kinds[0] == "free" and robot.frame_names[0] == "universe"
    assert robot.joint_names[:7] == tuple(f"root_joint.{c}" for c in "x y z qw qx qy qz".split())
    data = model.createData()
    ids = {f: model.getFrameId(f, pin.BODY) for f in robot.frame_names[1:]}
    for k, q in enumerate(qs):
        qp = pmap.q(q)
        pin.computeJointJacobians(model, data, qp)
        pin.framesForwardKinematics(model, data, qp)
        Ts = out["Ts"][k]
        tol = 1e-12 * max(1.0, float(np.max(np.linalg.norm(Ts[:, :3, 3], axis=-1))))
        for i, f in enumerate(robot.frame_names[1:], start=1):
            np.testing.assert_allclose(Ts[i], data.oMf[ids[f]].homogeneous, atol=tol, err_msg=f)
        for f in frames:
            for ref, rf in REFS.items():
                if f"{f}/{ref}" not in out:
                    continue
                Jp = pmap.J(pin.getFrameJacobian(model, data, ids[f], getattr(pin, rf)))
                np.testing.assert_allclose(out[f"{f}/{ref}"][k], Jp, atol=tol, err_msg=(f, ref))
    assert sum(key.endswith("/local") for key in out) == 2  # a foot and the root link


@pytest.mark.parametrize("name", ROBOTS[:2])
def test_integrate_difference_and_jacobian_dot_match_pinocchio(name):
    robot, pmap, qs, vs, out, _ = floating_case(name)
    model = pmap.model
    data = model.createData()
    foot = model.getFrameId(robot.default_frames[0], pin.BODY)
    for k, (q, v) in enumerate(zip(qs, vs, strict=True)):
        q1p = pin.integrate(model, pmap.q(q), pmap.v(v))
        assert same_configuration(robot, pmap.q(out["q1"][k]), q1p) < 1e-12
        np.testing.assert_allclose(
            pmap.v(out["d"][k]), pin.difference(model, pmap.q(q), q1p), atol=1e-12
        )
        np.testing.assert_allclose(out["d"][k], v, atol=1e-12)  # difference inverts integrate
        pin.computeJointJacobiansTimeVariation(model, data, pmap.q(q), pmap.v(v))
        pin.updateFramePlacements(model, data)
        Jd = pmap.J(pin.getFrameJacobianTimeVariation(model, data, foot, pin.LOCAL))
        np.testing.assert_allclose(out["Jd"][k], Jd, atol=1e-11)


@pytest.mark.parametrize("name", AUTODIFF_ROBOTS)
def test_autodiff_jacobian_through_integrate_matches_the_hand_built_one(name):
    robot, _, _, _, out, _ = floating_case(name)
    np.testing.assert_allclose(out["fwd"], out[f"{robot.default_frames[0]}/world"], atol=1e-13)


def test_the_default_frame_of_a_floating_legged_robot_still_branches():
    robot = floating_case(ROBOTS[0])[0]
    with pytest.raises(jk.NoDefaultFrameError, match="no default frame"):
        jk.fk(robot, jk.neutral(robot))
    arm = jk.robots.load("erd/talos_left_arm", floating_base=True, dtype=np.float64)
    assert (arm.nq, arm.nv) == (13, 12)  # the chain to its tool frame, on a free root
    assert arm.frame_names[arm.tip_frame] == "wrist_left_ft_tool_link"


# ----------------------------------------------------------------------------- URDF joints
URDF = """<robot name="mixed">
  <link name="base"/><link name="a"/><link name="b"/><link name="c"/><link name="d"/>
  <joint name="yaw" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0.1 0.2 0.3" rpy="0.3 -0.2 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="float" type="floating"><parent link="a"/><child link="b"/>
    <origin xyz="0.4 0 0.1" rpy="0.5 0.1 -0.7"/></joint>
  <joint name="slide" type="planar"><parent link="b"/><child link="c"/>
    <origin xyz="0 0.3 0" rpy="-0.4 0.2 0.9"/><axis xyz="0 0 1"/></joint>
  <joint name="tip" type="fixed"><parent link="c"/><child link="d"/>
    <origin xyz="0.2 0.1 0.05" rpy="0 0.3 0"/></joint>
</robot>"""


@functools.cache
def urdf_case():
    robot = jk.load_urdf(URDF, dtype=np.float64)
    model = pin.buildModelFromXML(URDF)
    qs = random_q(robot, N, seed=3)
    vs = np.random.default_rng(3).uniform(-2.0, 2.0, (N, robot.nv))

    def one(q, v):
        out = {"Ts": jk.fk_all(robot, q), "q1": jk.integrate(robot, q, v)}
        out["d"] = jk.difference(robot, q, out["q1"])
        for ref in REFS:
            out[ref] = jk.geometric_jacobian(robot, q, reference=ref)
        return out

    f = jax.jit(jax.vmap(one), compiler_options=FAST_COMPILE)
    out = jax.tree_util.tree_map(np.asarray, f(qs, vs))
    return robot, PinMap(robot, model), qs, vs, out


def test_urdf_floating_and_planar_joints_match_pinocchio():
    robot, pmap, qs, vs, out = urdf_case()
    model = pmap.model
    assert robot.kinds == ("revolute", "free", "planar", "fixed")
    assert (robot.nq, robot.nv) == (model.nq, model.nv) == (12, 10)
    assert robot.frame_names[robot.tip_frame] == "d"
    data = model.createData()
    fid = model.getFrameId("d", pin.BODY)
    for k, (q, v) in enumerate(zip(qs, vs, strict=True)):
        qp = pmap.q(q)
        pin.computeJointJacobians(model, data, qp)
        pin.framesForwardKinematics(model, data, qp)
        for i, f in enumerate(robot.frame_names[1:], start=1):
            oMf = data.oMf[model.getFrameId(f, pin.BODY)].homogeneous
            np.testing.assert_allclose(out["Ts"][k][i], oMf, atol=1e-12, err_msg=f)
        for ref, rf in REFS.items():
            Jp = pmap.J(pin.getFrameJacobian(model, data, fid, getattr(pin, rf)))
            np.testing.assert_allclose(out[ref][k], Jp, atol=1e-12, err_msg=ref)
        q1p = pin.integrate(model, qp, pmap.v(v))
        assert same_configuration(robot, pmap.q(out["q1"][k]), q1p) < 1e-12
        np.testing.assert_allclose(pmap.v(out["d"][k]), pin.difference(model, qp, q1p), atol=1e-12)


# ----------------------------------------------------------------------------- properties
EVERY_KIND = jk.Robot.from_joints(
    [
        dict(name="root", type="free", child="body", xyz=[0.1, 0.0, 0.5]),
        dict(name="neck", type="ball", child="head", xyz=[0.0, 0.0, 0.3], rpy=[0.2, 0.0, 0.1]),
        dict(
            name="arm", type="revolute", parent="body", child="arm", xyz=[0.2, 0, 0], axis=[0, 1, 0]
        ),
        dict(name="cart", type="planar", child="cart", xyz=[0.3, 0, 0], rpy=[0.5, 0.4, 0.3]),
        dict(name="hand", type="fixed", child="hand", xyz=[0.1, 0.2, 0.0]),
    ],
    name="every_kind",
    dtype=np.float64,
    default_frames=["hand"],
)
ROBOT = EVERY_KIND


@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _round_trip(q, v, q1):
    v_back = jk.difference(ROBOT, q, jk.integrate(ROBOT, q, v))
    q1_back = jk.integrate(ROBOT, q, jk.difference(ROBOT, q, q1))
    return v_back, q1_back


h = 1e-6


@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _twist_and_fd(q, v):
    V = jk.twist(ROBOT, q, v, reference="world_aligned")
    Tp = jk.fk(ROBOT, jk.integrate(ROBOT, q, v, dt=h))
    Tm = jk.fk(ROBOT, jk.integrate(ROBOT, q, v, dt=-h))
    dp = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
    w = jk.spatial.log_so3(Tp[:3, :3] @ Tm[:3, :3].T) / (2 * h)
    return V, jnp.concatenate([dp, w])


def _unit(x):
    x = np.asarray(x, dtype=float)
    n = np.linalg.norm(x)
    return x / n if n > 1e-3 else np.eye(len(x))[0]


@st.composite
def configurations(draw):
    f = st.floats(-1.0, 1.0)
    t = [draw(f) for _ in range(3)]
    free = _unit([draw(f) for _ in range(4)])
    ball = _unit([draw(f) for _ in range(4)])
    arm = draw(st.floats(-3.0, 3.0))
    a = draw(st.floats(-np.pi, np.pi))
    xy = [draw(f) for _ in range(2)]
    return np.concatenate([t, free, ball, [arm], xy, [np.cos(a), np.sin(a)]])


@st.composite
def velocities(draw):
    """Rotation parts shorter than pi (the log returns angles in [0, pi])."""
    v = np.array([draw(st.floats(-2.0, 2.0)) for _ in range(ROBOT.nv)])
    for s in (slice(3, 6), slice(6, 9)):
        n = np.linalg.norm(v[s])
        if n > 3.0:
            v[s] *= 3.0 / n
    v[12] = np.clip(v[12], -3.0, 3.0)
    return v


@settings(max_examples=8, deadline=None)
@given(configurations(), velocities(), configurations())
def test_difference_inverts_integrate_both_ways(q, v, q1):
    v_back, q1_back = _round_trip(q, v, q1)
    np.testing.assert_allclose(v_back, v, atol=1e-10)
    assert same_configuration(ROBOT, q1_back, q1) < 1e-10


@settings(max_examples=6, deadline=None)
@given(configurations(), velocities())
def test_twist_is_the_velocity_along_integrate(q, v):
    V, fd = _twist_and_fd(q, v)
    np.testing.assert_allclose(V, fd, atol=1e-7)


def test_every_kind_layout_and_neutral():
    r = ROBOT
    assert (r.nq, r.nv, r.dof) == (16, 13, 13)
    assert r.q_index == (0, 7, 11, 12, -1) and r.v_index == (0, 6, 9, 10, -1)
    assert r.velocity_names[6:] == (
        "neck.wx",
        "neck.wy",
        "neck.wz",
        "arm",
        "cart.vx",
        "cart.vy",
        "cart.wz",
    )
    assert r.joint_kinds[:8] == ("free",) * 7 + ("ball",)
    q0 = np.asarray(jk.neutral(r))
    np.testing.assert_array_equal(q0, [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 1, 0])
    lo, hi = np.asarray(r.lower), np.asarray(r.upper)
    assert np.all(np.isinf(lo[:3])) and np.all(lo[3:7] == -1) and np.all(hi[3:7] == 1)
    assert jk.geometric_jacobian(r, q0).shape == (6, 13)
    np.testing.assert_allclose(jk.normalize(r, 2 * q0), q0, atol=0)


def test_sampled_configurations_lie_on_the_manifold():
    # jk.sample_configurations under one jit with the tests' compile options (its eager call
    # compiles the same draw with XLA's default passes: 4x the CPU seconds)
    qs = np.asarray(sampler(ROBOT, 200)(jax.random.key(1)))
    assert qs.shape == (200, 16)
    for s in (slice(3, 7), slice(7, 11), slice(14, 16)):
        np.testing.assert_allclose(np.linalg.norm(qs[:, s], axis=1), 1.0, atol=1e-12)
    assert np.all(np.abs(qs[:, :3]) <= 1.0) and np.all(np.abs(qs[:, 12:14]) <= 1.0)
    # uniform quaternions: no hemisphere or axis preferred
    assert abs(float(np.mean(qs[:, 3]))) < 0.15 and float(np.min(qs[:, 3])) < -0.5


def test_analytical_jacobian_and_hessian_work_along_the_tangent():
    q = random_q(ROBOT, 1, seed=5)[0]
    v = np.linspace(-1.0, 1.0, ROBOT.nv)

    @functools.partial(jax.jit, compiler_options=FAST_COMPILE)
    def all_four(q, v):
        return (
            jk.analytical_jacobian(ROBOT, q, "rotvec", return_margin=True)[0],
            jk.analytical_jacobian(ROBOT, q, "rotvec", method="jacfwd", return_margin=True)[0],
            jk.kinematic_hessian(ROBOT, q),
            jk.jacobian_dot(ROBOT, q, v),
        )

    Ja, Ja_fwd, H, Jd = all_four(q, v)
    assert Ja.shape == (6, 13) and H.shape == (13, 6, 13)
    np.testing.assert_allclose(Ja, Ja_fwd, atol=1e-12)
    np.testing.assert_allclose(np.einsum("k,kij->ij", v, H), Jd, atol=1e-12)


# ----------------------------------------------------------------------------- float32
def test_float32_floating_base():
    robot64, _, qs, vs, out64, _ = floating_case(ROBOTS[0])
    robot32 = robot64.astype(np.float32)
    foot = robot64.default_frames[0]
    f = robot64.frame_names.index(foot)

    def one(q, v):
        q1 = jk.integrate(robot32, q, v)
        return (
            jk.fk(robot32, q, frame=foot),
            jk.geometric_jacobian(robot32, q, frame=foot),
            q1,
            jk.difference(robot32, q, q1),
        )

    run = jax.jit(jax.vmap(one), compiler_options=FAST_COMPILE)
    out32 = run(qs[:4].astype(np.float32), vs[:4].astype(np.float32))
    assert all(x.dtype == np.float32 for x in out32)
    expect = (out64["Ts"][:4, f], out64[f"{foot}/world_aligned"][:4], out64["q1"][:4], vs[:4])
    for a, b in zip(out32, expect, strict=True):
        np.testing.assert_allclose(np.asarray(a, dtype=float), b, atol=2e-5)


# ----------------------------------------------------------------------------- failures
def test_zero_or_nonfinite_quaternions_raise_eagerly_and_give_nan_under_jit():
    q = np.asarray(jk.neutral(ROBOT))
    bad = q.copy()
    bad[7:11] = 0.0
    with pytest.raises(jk.JaxkinError, match=r"quaternion.*ball joint 'neck'.*is zero"):
        jk.fk(ROBOT, bad)
    with pytest.raises(jk.JaxkinError, match=r"free joint 'root'.*not finite"):
        jk.geometric_jacobian(ROBOT, np.where(np.arange(16) == 4, np.nan, q))
    with pytest.raises(jk.JaxkinError, match=r"\(cos, sin\) pair of planar joint 'cart'"):
        jk.integrate(ROBOT, np.where(np.arange(16) >= 14, 0.0, q), np.zeros(13))
    head = jax.jit(lambda q: jk.fk(ROBOT, q, frame="head"))(bad)
    assert np.all(np.isnan(np.asarray(head)[:3, :3]))  # the ball joint's rotation
    # a non-unit quaternion is the rotation of its unit multiple, as in MuJoCo
    q = random_q(ROBOT, 1, seed=2)[0]
    scaled = q.copy()
    scaled[3:7] *= 3.0
    scaled[7:11] *= 0.2
    np.testing.assert_allclose(jk.fk(ROBOT, scaled), jk.fk(ROBOT, q), atol=1e-15)


def test_wrong_lengths_name_nq_and_nv():
    with pytest.raises(jk.ShapeError, match=r"shape \(16,\).*nq = 16 coordinates, nv = 13"):
        jk.fk(ROBOT, np.zeros(13))
    with pytest.raises(jk.ShapeError, match=r"qd must have shape \(13,\).*'root.vx'"):
        jk.twist(ROBOT, jk.neutral(ROBOT), np.zeros(16))
    with pytest.raises(jk.ShapeError, match=r"v must have shape \(13,\)"):
        jk.integrate(ROBOT, jk.neutral(ROBOT), np.zeros(16))


def test_calibration_and_vector_space_tools_refuse_by_name():
    # jk.solve_ik solves these robots (tests/test_ik_wholebody.py); these still refuse them.
    q = jk.neutral(ROBOT)
    T = jk.fk(ROBOT, q)
    refused = [
        lambda: jk.calibrate(ROBOT, q[None], T[None], ["xyz"]),
        lambda: jk.identifiability(ROBOT, q[None], ["xyz"]),
        lambda: jk.manipulability_gradient(ROBOT, q),
        lambda: jk.resolved_rate_control(ROBOT, q, jnp.stack([T, T]), 0.1, damping=0.1),
        lambda: jk.to_urdf(ROBOT),
    ]
    for call in refused:
        with pytest.raises(jk.JaxkinError, match=r"'root' \(free\)|free, ball or planar"):
            call()


def test_builder_refusals():
    with pytest.raises(jk.ModelError, match="joint 'b' is ball but has a mimic"):
        jk.Robot.from_joints(
            [
                dict(name="a", type="revolute", child="l1"),
                dict(name="b", type="ball", child="l2", mimic={"joint": "a"}),
            ]
        )
    with pytest.raises(jk.ModelError, match="mimics joint 'b', which is ball"):
        jk.Robot.from_joints(
            [
                dict(name="b", type="ball", child="l1"),
                dict(name="a", type="revolute", child="l2", mimic={"joint": "b"}),
            ]
        )
    with pytest.raises(jk.ModelError, match="is free and takes no lower"):
        jk.Robot.from_joints([dict(name="f", type="floating", child="l", lower=-1.0)])
    with pytest.raises(jk.ModelError, match="planar with axis"):
        jk.Robot.from_joints([dict(name="p", type="planar", child="l", axis=[1, 0, 0])])
