"""Mass and centre of mass (``jk.center_of_mass``, ``jk.com_jacobian``, ``robot.mass``).

Oracles:

* Pinocchio's ``centerOfMass``, ``jacobianCenterOfMass`` and ``computeTotalMass`` of the
  free-flyer model (``pin.JointModelFreeFlyer()``) of the same URDF, for a humanoid (the Unitree
  G1 of example-robot-data) and an arm (UR5), joints matched by name (1e-12).
* MuJoCo's ``subtree_com`` of the world body and ``mj_jacSubtreeCom`` for an MJCF model whose
  masses MuJoCo infers from primitive geoms (free joint's linear columns mapped from world to
  body axes, see :mod:`jaxkin.mjcf`), a static body included (1e-12).
* Autodiff of ``c(integrate(q, v))`` at ``v = 0`` and central differences, on a small robot with
  every joint kind (free, ball, planar, revolute, prismatic, mimic, fixed, tool).
* The derivative of ``c`` with respect to one frame's mass, ``(c_i - c) / M``, by hand.
"""

from __future__ import annotations

import functools
import pickle

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sampling import random_q
from _xla import FAST_COMPILE

import jaxkin as jk
from bench.peers import PinocchioLayout
from jaxkin.build import select
from jaxkin.robots import example_robot_data as erd
from jaxkin.urdf import URDFError

N = 4


# ----------------------------------------------------------------------------- Pinocchio
@functools.cache
def pinocchio_case(name: str):
    """(robot, model, qs, c, Jc): jaxkin's centre of mass and its Jacobian at ``N``
    configurations, one jitted vmap."""
    pin = pytest.importorskip("pinocchio")
    if name not in jk.robots.erd_names():
        pytest.skip("example-robot-data is not installed")
    robot = jk.load_urdf(erd.path(name), floating_base=True, dtype=np.float64)
    model = pin.buildModelFromUrdf(str(erd.path(name)), pin.JointModelFreeFlyer())
    qs = random_q(robot, N, seed=3)

    def both(q):
        return jk.center_of_mass(robot, q), jk.com_jacobian(robot, q)

    c, J = jax.jit(jax.vmap(both), compiler_options=FAST_COMPILE)(jnp.asarray(qs))
    return robot, model, qs, np.asarray(c), np.asarray(J)


@pytest.mark.parametrize("name", ["erd/g1_29dof_rev_1_0", "erd/ur5_robot"])
def test_center_of_mass_and_its_jacobian_match_pinocchio(name):
    pin = pytest.importorskip("pinocchio")
    robot, model, qs, c, J = pinocchio_case(name)
    data = model.createData()
    layout = PinocchioLayout(robot, model)  # the one jaxkin <-> Pinocchio (q, v) map
    assert robot.has_inertia
    np.testing.assert_allclose(float(robot.mass), pin.computeTotalMass(model), rtol=0, atol=1e-12)
    for k, q in enumerate(qs):
        qp = layout.q(q)
        np.testing.assert_allclose(c[k], pin.centerOfMass(model, data, qp), rtol=0, atol=1e-12)
        Jm = layout.columns_to_jaxkin(pin.jacobianCenterOfMass(model, data, qp))
        np.testing.assert_allclose(J[k], Jm, rtol=0, atol=1e-12)


def test_a_float32_robot_agrees_within_float32_rounding():
    robot, _, qs, c, J = pinocchio_case("erd/ur5_robot")
    r32, q32 = robot.astype(np.float32), qs[0].astype(np.float32)
    # one float32 program for both (not an eager kernel per function)
    both = jax.jit(lambda q: (jk.center_of_mass(r32, q), jk.com_jacobian(r32, q)),
                   compiler_options=FAST_COMPILE)  # fmt: skip
    c32, J32 = both(q32)
    assert c32.dtype == J32.dtype == np.float32 and r32.mass.dtype == np.float32
    np.testing.assert_allclose(c32, c[0], rtol=0, atol=2e-6)  # q rounded to float32 too
    np.testing.assert_allclose(J32, J[0], rtol=0, atol=2e-6)


# ----------------------------------------------------------------------------- MuJoCo
MJCF = """<mujoco model="body"><worldbody>
<body name="torso" pos="0 0 1"><freejoint name="root"/><geom type="box" size=".2 .1 .3"/>
  <body name="arm" pos=".3 0 .2" euler="10 20 30">
    <joint name="shoulder" type="ball" pos="0 0 .05"/>
    <geom type="capsule" fromto="0 0 0 .4 0 0" size=".04"/>
    <body name="fore" pos=".4 0 0">
      <joint name="elbow" axis="0 1 0" pos=".01 0 0"/><joint name="twist" axis="1 0 0"/>
      <geom type="cylinder" fromto="0 0 0 .3 .1 0" size=".03" density="500"/>
      <body name="hand" pos=".3 0 0"><joint name="slide" type="slide" axis="1 0 0"/>
        <inertial pos=".05 .01 0" mass=".5" fullinertia=".02 .02 .03 .001 .002 .003"/>
        <site name="palm" pos=".1 0 0"/></body></body></body>
  <body name="leg" pos="0 .1 -.3"><joint name="hip" axis="1 0 0"/>
    <geom type="sphere" size=".1" pos="0 0 -.2"/></body>
</body>
<body name="post" pos="1 1 0"><geom type="sphere" size=".2"/></body>
</worldbody></mujoco>"""


def test_mjcf_center_of_mass_and_jacobian_match_mujoco():
    mujoco = pytest.importorskip("mujoco")
    robot = jk.load_mjcf(MJCF, dtype=np.float64)
    m = mujoco.MjModel.from_xml_string(MJCF)
    d = mujoco.MjData(m)
    assert robot.has_inertia and robot.nq == m.nq and robot.nv == m.nv
    np.testing.assert_allclose(float(robot.mass), np.sum(m.body_mass), rtol=1e-15)
    bodies = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(1, m.nbody)]
    f = [robot.frame_names.index(b) for b in bodies]
    np.testing.assert_array_equal(np.asarray(robot.frame_mass)[f], m.body_mass[1:])
    np.testing.assert_array_equal(np.asarray(robot.frame_com)[f], m.body_ipos[1:])
    qs = random_q(robot, N, seed=5)
    both = jax.vmap(lambda q: (jk.center_of_mass(robot, q), jk.com_jacobian(robot, q)))
    c, J = jax.jit(both, compiler_options=FAST_COMPILE)(jnp.asarray(qs))
    for k, q in enumerate(qs):
        d.qpos[:] = q
        mujoco.mj_forward(m, d)
        jac = np.zeros((3, m.nv))
        mujoco.mj_jacSubtreeCom(m, d, jac, 0)
        jac[:, :3] = jac[:, :3] @ d.xmat[1].reshape(3, 3)  # qvel: world axes; v: body axes
        np.testing.assert_allclose(c[k], d.subtree_com[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(J[k], jac, rtol=0, atol=1e-12)


def test_mjcf_base_keeps_the_masses_below_it():
    pytest.importorskip("mujoco")
    whole = jk.load_mjcf(MJCF, dtype=np.float64)
    arm = jk.load_mjcf(MJCF, base="arm", dtype=np.float64)
    keep = ["arm", "fore", "hand"]
    expected = sum(float(whole.frame_mass[whole.frame_names.index(n)]) for n in keep)
    np.testing.assert_allclose(float(arm.mass), expected, rtol=1e-15)
    assert arm.frame_names[0] == "arm" and float(arm.frame_mass[0]) > 0.0


def test_mjcf_masses_inferred_from_a_mesh_are_not_guessed():
    pytest.importorskip("mujoco")
    mesh = '<asset><mesh name="m" vertex="0 0 0 1 0 0 0 1 0 0 0 1"/></asset>'
    body = '<body name="b"><joint name="j"/><geom type="mesh" mesh="m"/>{}</body>'
    xml = "<mujoco>{}<worldbody>{}</worldbody></mujoco>"
    inferred = jk.load_mjcf(xml.format(mesh, body.format("")))
    assert not inferred.has_inertia
    with pytest.raises(jk.ModelError, match="mesh geoms"):
        jk.center_of_mass(inferred, [0.0])
    given = jk.load_mjcf(
        xml.format(mesh, body.format('<inertial pos="0 0 0" mass="2" diaginertia="1 1 1"/>'))
    )
    assert given.has_inertia and float(given.mass) == 2.0


# ----------------------------------------------------------------------------- a small robot
def every_kind(dtype=np.float64) -> jk.Robot:
    """A robot with every joint kind, a mimic joint, a fixed frame and a tool, all massive."""

    def mass(m, xyz, rpy=(0.0, 0.0, 0.0)):
        return dict(mass=m, xyz=xyz, rpy=rpy, inertia=(0.1, 0.01, 0.0, 0.2, 0.0, 0.3))

    joints = [
        dict(name="free", type="free", child="pelvis", inertial=mass(5.0, [0.1, 0.0, 0.05])),
        dict(
            name="ball",
            type="ball",
            parent="pelvis",
            child="thigh",
            xyz=[0, 0.1, -0.1],
            inertial=mass(2.0, [0.0, 0.0, -0.2], (0.3, 0.2, 0.1)),
        ),
        dict(
            name="knee",
            type="revolute",
            child="shin",
            xyz=[0, 0, -0.4],
            axis=[0, 1, 0],
            lower=-2,
            upper=0.5,
            inertial=mass(1.5, [0.01, 0.0, -0.2]),
        ),
        dict(
            name="foot",
            type="fixed",
            child="sole",
            xyz=[0.05, 0, -0.4],
            rpy=[0.1, 0, 0],
            inertial=dict(mass=0.5, xyz=[0.05, 0, 0]),
        ),
        dict(
            name="slider",
            type="prismatic",
            parent="pelvis",
            child="rail",
            axis=[0, 0, 1],
            lower=-1,
            upper=1,
            inertial=mass(0.7, [0.0, 0.1, 0.0]),
        ),
        dict(
            name="turn",
            type="revolute",
            parent="rail",
            child="arm",
            axis=[1, 1, 0],
            inertial=mass(1.0, [0.2, 0.0, 0.0]),
        ),
        dict(
            name="twin",
            type="revolute",
            parent="rail",
            child="twin_arm",
            axis=[0, 0, 1],
            mimic={"joint": "turn", "multiplier": -0.5, "offset": 0.2},
            inertial=mass(0.8, [0.0, 0.2, 0.0]),
        ),
        dict(
            name="plane",
            type="planar",
            parent="arm",
            child="slab",
            xyz=[0.3, 0, 0],
            inertial=mass(0.6, [0.05, 0.05, 0.0]),
        ),
    ]
    root = dict(mass=3.0, xyz=[0.0, 0.0, 0.1])
    tool = np.eye(4)
    tool[:3, 3] = [0.0, 0.0, 0.1]
    return jk.Robot.from_joints(
        joints, root="ground", root_inertial=root, tool=tool, dtype=dtype, name="every_kind"
    )


def test_builder_keeps_each_frames_inertial_in_its_own_axes():
    robot = every_kind()
    assert robot.has_inertia and robot.frame_names[-1] == "tool"
    names = list(robot.frame_names)
    mass = dict(zip(names, np.asarray(robot.frame_mass), strict=True))
    assert mass["ground"] == 3.0 and mass["sole"] == 0.5 and mass["tool"] == 0.0
    np.testing.assert_allclose(float(robot.mass), 15.1, rtol=1e-15)
    thigh = names.index("thigh")
    r, p, y = 0.3, 0.2, 0.1
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx
    I = np.array([[0.1, 0.01, 0.0], [0.01, 0.2, 0.0], [0.0, 0.0, 0.3]])
    np.testing.assert_allclose(robot.frame_inertia[thigh], R @ I @ R.T, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(robot.frame_com[thigh], [0.0, 0.0, -0.2])


def test_com_jacobian_is_the_derivative_of_the_centre_of_mass():
    robot = every_kind()
    for q in random_q(robot, 2, seed=11):
        J = np.asarray(jk.com_jacobian(robot, q))
        assert J.shape == (3, robot.nv)
        h = 1e-6
        for v in np.eye(robot.nv):  # central differences along each velocity coordinate
            ahead = jk.center_of_mass(robot, jk.integrate(robot, q, h * v))
            behind = jk.center_of_mass(robot, jk.integrate(robot, q, -h * v))
            fd = (np.asarray(ahead) - np.asarray(behind)) / (2 * h)
            np.testing.assert_allclose(J @ v, fd, rtol=0, atol=1e-8)


def test_centre_of_mass_is_the_mass_weighted_mean_of_the_frames_centres():
    robot = every_kind()
    q = random_q(robot, 1, seed=2)[0]
    Ts = np.asarray(jk.fk_all(robot, q))
    m = np.asarray(robot.frame_mass)
    ci = Ts[:, :3, 3] + np.einsum("fij,fj->fi", Ts[:, :3, :3], np.asarray(robot.frame_com))
    c = np.asarray(jk.center_of_mass(robot, q))
    np.testing.assert_allclose(c, m @ ci / m.sum(), rtol=0, atol=1e-15)
    # d c / d m_i = (c_i - c) / M, through the robot's leaves
    g = jax.jit(
        jax.jacrev(lambda m: jk.center_of_mass(robot.replace(frame_mass=m), q)),
        compiler_options=FAST_COMPILE,
    )(robot.frame_mass)
    np.testing.assert_allclose(g, ((ci - c) / m.sum()).T, rtol=0, atol=1e-14)


def test_jit_vmap_over_configurations_and_over_a_stack_of_robots():
    robot = every_kind()
    qs = jnp.asarray(random_q(robot, 3, seed=4))
    both = jax.vmap(lambda q: (jk.center_of_mass(robot, q), jk.com_jacobian(robot, q)))
    c, J = jax.jit(both, compiler_options=FAST_COMPILE)(qs)
    for k in range(3):
        np.testing.assert_allclose(c[k], jk.center_of_mass(robot, qs[k]), rtol=0, atol=1e-14)
        np.testing.assert_allclose(J[k], jk.com_jacobian(robot, qs[k]), rtol=0, atol=1e-14)
    robot = jk.load_urdf(URDF.format(base=INERTIAL.format(m=2), a=INERTIAL.format(m=1)))
    heavier = robot.replace(frame_mass=robot.frame_mass.at[1].mul(3.0))
    stack = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), robot, heavier)
    cs = jax.jit(jax.vmap(jk.center_of_mass, in_axes=(0, None)), compiler_options=FAST_COMPILE)(
        stack, jnp.array([0.7])
    )
    qs = jnp.array([0.7])
    # the references: one program taking the robot as an argument (eagerly, each robot value
    # compiles its own kernel)
    one = jax.jit(jk.center_of_mass, compiler_options=FAST_COMPILE)
    np.testing.assert_allclose(cs[0], one(robot, qs), rtol=0, atol=1e-15)
    np.testing.assert_allclose(cs[1], one(heavier, qs), rtol=0, atol=1e-15)
    assert not np.allclose(cs[0], cs[1])
    np.testing.assert_allclose(stack.mass, [robot.mass, heavier.mass], rtol=1e-15)


def test_masses_are_part_of_the_robots_value():
    robot = every_kind()
    assert pickle.loads(pickle.dumps(robot)) == robot
    heavier = robot.replace(frame_mass=robot.frame_mass * 2.0)
    assert heavier != robot and hash(heavier) != hash(robot)
    assert robot.replace(frame_com=robot.frame_com + 1.0) != robot
    with pytest.raises(jk.ShapeError, match=rf"frame_mass must have shape \({robot.n_frames},\)"):
        robot.replace(frame_mass=np.ones(3))
    with pytest.raises(jk.ShapeError, match="frame_inertia"):
        robot.replace(frame_inertia=np.ones((robot.n_frames, 3)))
    r32 = robot.astype(np.float32)
    assert r32.frame_inertia.dtype == np.float32 and r32.has_inertia


# ----------------------------------------------------------------------------- errors
URDF = """<robot name="r">
  <link name="base">{base}</link>
  <link name="a">{a}</link>
  <joint name="j" type="revolute"><parent link="base"/><child link="a"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint>
</robot>"""
INERTIAL = (
    '<inertial><origin xyz="0.1 0 0" rpy="0 0 0.5"/><mass value="{m}"/>'
    '<inertia ixx="0.1" ixy="0.01" ixz="0" iyy="0.2" iyz="0" izz="0.3"/></inertial>'
)


def test_robots_without_masses_are_refused_with_the_fix():
    dh = jk.robots.load("two_link_planar")
    assert not dh.has_inertia and float(dh.mass) == 0.0
    np.testing.assert_array_equal(dh.frame_mass, np.zeros(dh.n_frames))
    assert dh.frame_inertia.shape == (dh.n_frames, 3, 3)
    with pytest.raises(jk.ModelError, match="Denavit-Hartenberg table has no masses"):
        jk.center_of_mass(dh, [0.0, 0.0])
    bare = jk.load_urdf(URDF.format(base="", a=""))
    with pytest.raises(jk.ModelError, match=r"no inertial data.*<inertial>.*has_inertia=True"):
        jk.com_jacobian(bare, [0.0])
    massless = jk.load_urdf(URDF.format(base="", a=INERTIAL.format(m=0)))
    assert massless.has_inertia
    with pytest.raises(jk.ModelError, match=r"total mass 0\.0 kg"):
        jk.center_of_mass(massless, [0.0])
    with pytest.raises(jk.ModelError, match="no inertial data"):  # inside a trace too
        jax.jit(lambda q: jk.center_of_mass(dh, q))(jnp.zeros(2))


def test_urdf_inertials_are_read_checked_and_written_back():
    robot = jk.load_urdf(URDF.format(base=INERTIAL.format(m=2), a=INERTIAL.format(m=1.5)))
    np.testing.assert_array_equal(robot.frame_mass, [2.0, 1.5])
    np.testing.assert_array_equal(robot.frame_com, [[0.1, 0, 0], [0.1, 0, 0]])
    Rz = np.array([[np.cos(0.5), -np.sin(0.5), 0], [np.sin(0.5), np.cos(0.5), 0], [0, 0, 1]])
    I = np.array([[0.1, 0.01, 0], [0.01, 0.2, 0], [0, 0, 0.3]])
    np.testing.assert_allclose(robot.frame_inertia[1], Rz @ I @ Rz.T, rtol=0, atol=1e-15)
    back = jk.load_urdf(jk.to_urdf(robot))
    assert back.has_inertia
    for leaf in ("frame_mass", "frame_com", "frame_inertia"):
        np.testing.assert_array_equal(getattr(back, leaf), getattr(robot, leaf), err_msg=leaf)
    with pytest.raises(URDFError) as e:
        jk.load_urdf(URDF.format(base="", a=INERTIAL.format(m=-1)))
    assert e.value.line == 3 and e.value.element == "<mass> of link 'a'"
    assert e.value.attribute == "value" and "negative" in str(e.value)
    with pytest.raises(URDFError, match=r"exceeds 1e\+06 kg in magnitude") as e:
        jk.load_urdf(URDF.format(base="", a=INERTIAL.format(m="2e9")))
    assert e.value.element == "<mass> of link 'a'"
    no_inertia = '<inertial><mass value="1"/></inertial>'
    with pytest.raises(jk.ModelError, match="<inertia> element is missing"):
        jk.load_urdf(URDF.format(base="", a=no_inertia))


def test_erd_arm_round_trips_through_to_urdf():
    if "erd/ur5_robot" not in jk.robots.erd_names():
        pytest.skip("example-robot-data is not installed")
    robot = jk.load_urdf(erd.path("erd/ur5_robot"))
    back = jk.load_urdf(jk.to_urdf(robot))
    assert back.frame_names == robot.frame_names
    for leaf in ("frame_mass", "frame_com", "frame_inertia"):
        np.testing.assert_array_equal(getattr(back, leaf), getattr(robot, leaf), err_msg=leaf)


def test_builder_refuses_bad_inertials():
    def build(**inertial):
        return jk.Robot.from_joints([dict(name="j", type="revolute", child="a", inertial=inertial)])

    with pytest.raises(jk.ModelError, match="mass must be >= 0"):
        build(mass=-1.0)
    with pytest.raises(jk.ModelError, match="must be finite"):
        build(mass=float("nan"))
    with pytest.raises(jk.ModelError, match="must be symmetric"):
        build(mass=1.0, inertia=[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]])
    with pytest.raises(jk.ModelError, match="unknown key"):
        build(mass=1.0, centre=[0, 0, 0])
    with pytest.raises(jk.ModelError, match="missing key 'mass'"):
        build(xyz=[0, 0, 0])
    with pytest.raises(jk.ModelError, match="both rpy and quat"):
        build(mass=1.0, rpy=[0, 0, 0], quat=[1, 0, 0, 0])
    quat = build(mass=1.0, quat=[np.cos(0.25), 0, 0, np.sin(0.25)], inertia=[1, 0, 0, 2, 0, 3])
    Rz = np.array([[np.cos(0.5), -np.sin(0.5), 0], [np.sin(0.5), np.cos(0.5), 0], [0, 0, 1]])
    np.testing.assert_allclose(
        quat.frame_inertia[1], Rz @ np.diag([1.0, 2, 3]) @ Rz.T, rtol=0, atol=1e-15
    )


def test_select_keeps_the_inertial_of_the_parts_root():
    a, b = dict(mass=1.0), dict(mass=2.0)
    specs = [
        dict(name="j1", type="revolute", parent="base", child="a", inertial=a),
        dict(name="j2", type="revolute", parent="a", child="b", inertial=b),
    ]
    whole = select(specs, "base", root_inertial=dict(mass=4.0))
    assert whole.root_inertial == dict(mass=4.0)
    part = select(specs, "base", base="a")
    assert part.root == "a" and part.root_inertial is a
    free = select(specs, "base", base="a", above=dict(name="root", type="free", parent="u"))
    assert free.root == "u" and free.root_inertial is None and free.joints[0]["inertial"] is a
    robot = jk.Robot.from_joints(free.joints, root=free.root, root_inertial=free.root_inertial)
    np.testing.assert_array_equal(robot.frame_mass, [0.0, 1.0, 2.0])


def test_a_long_chain_through_the_scanned_pass():
    from jaxkin.kinematics import uses_scan

    rng = np.random.default_rng(0)
    joints = [
        dict(
            name=f"j{i}",
            type="prismatic" if i % 3 == 0 else "revolute",
            child=f"l{i}",
            xyz=rng.normal(size=3) * 0.1,
            rpy=rng.normal(size=3),
            axis=rng.normal(size=3),
            inertial=dict(mass=float(rng.uniform(0.1, 1.0)), xyz=rng.normal(size=3) * 0.1),
        )
        for i in range(34)
    ]
    robot = jk.Robot.from_joints(joints, tool=np.eye(4))
    assert uses_scan(robot)
    q = rng.normal(size=robot.nq)
    Ts = np.asarray(jk.fk_all(robot, q))
    m = np.asarray(robot.frame_mass)
    ci = Ts[:, :3, 3] + np.einsum("fij,fj->fi", Ts[:, :3, :3], np.asarray(robot.frame_com))
    np.testing.assert_allclose(jk.center_of_mass(robot, q), m @ ci / m.sum(), rtol=0, atol=1e-14)
    J, h = np.asarray(jk.com_jacobian(robot, q)), 1e-6
    for k in (0, 1, robot.nq - 1):
        e = np.eye(robot.nq)[k]
        ahead, behind = jk.center_of_mass(robot, q + h * e), jk.center_of_mass(robot, q - h * e)
        fd = (np.asarray(ahead) - np.asarray(behind)) / (2 * h)
        np.testing.assert_allclose(J[:, k], fd, rtol=0, atol=1e-8)


# ----------------------------------------------------------------------------- the kernel
TWO_BODIES = """<mujoco model="two"><worldbody>
<body name="a" pos="0 0 1"><freejoint name="fa"/><geom type="box" size=".2 .1 .3"/>
  <body name="a1" pos=".2 .1 0" euler="10 0 20"><joint name="ha" axis="0 1 0"/>
    <geom type="capsule" fromto="0 0 0 0 0 -.3" size=".04"/></body></body>
<body name="b" pos="1 0 1"><freejoint name="fb"/><geom type="sphere" size=".1"/>
  <body name="b1" pos="0 .2 0"><joint name="hb" axis="1 0 0"/>
    <geom type="cylinder" fromto="0 0 0 0 .3 0" size=".03"/></body></body>
<body name="post" pos="1 1 0"><geom type="sphere" size=".2"/></body>
</worldbody></mujoco>"""


def test_kernel_folds_below_each_floating_base_and_takes_a_traced_robot():
    """Two floating bases (each one pass relative to it, rotated once), the robot's constants
    folded or traced (``jit`` over the robot), against MuJoCo."""
    mujoco = pytest.importorskip("mujoco")
    from jaxkin.com import com_and_jacobian

    robot = jk.load_mjcf(TWO_BODIES, dtype=np.float64)
    m = mujoco.MjModel.from_xml_string(TWO_BODIES)
    d = mujoco.MjData(m)
    q = jnp.asarray(random_q(robot, 1, seed=7)[0])
    program = jax.jit(lambda q: com_and_jacobian(robot, q)).lower(q).as_text()
    assert "scatter" not in program  # columns and subtree sums as folded scalars, not scattered

    def both(traced, q):  # one program: the robot's constants folded, and traced
        return com_and_jacobian(robot, q), com_and_jacobian(traced, q)

    d.qpos[:] = q
    mujoco.mj_forward(m, d)
    jac = np.zeros((3, m.nv))
    mujoco.mj_jacSubtreeCom(m, d, jac, 0)
    for jnt in np.nonzero(m.jnt_type == mujoco.mjtJoint.mjJNT_FREE)[0]:
        v, body = m.jnt_dofadr[jnt], m.jnt_bodyid[jnt]  # qvel: world axes; v: body axes
        jac[:, v : v + 3] = jac[:, v : v + 3] @ d.xmat[body].reshape(3, 3)
    for c, J in jax.jit(both, compiler_options=FAST_COMPILE)(robot, q):
        np.testing.assert_allclose(c, d.subtree_com[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(J, jac, rtol=0, atol=1e-12)


def test_centre_alone_is_the_centre_of_the_pass_with_its_jacobian():
    """``center_of_mass`` on a tree below floating bases stops the folded centre-and-Jacobian
    pass before the columns: the same centre bit for bit, compiled on its own."""
    from jaxkin.com import com_and_jacobian

    robot = jk.load_mjcf(TWO_BODIES, dtype=np.float64)
    qs = jnp.asarray(random_q(robot, 8, seed=7))
    alone = jax.jit(jax.vmap(lambda q: jk.center_of_mass(robot, q)), compiler_options=FAST_COMPILE)
    both = jax.jit(jax.vmap(lambda q: com_and_jacobian(robot, q)), compiler_options=FAST_COMPILE)
    np.testing.assert_array_equal(alone(qs), both(qs)[0])
