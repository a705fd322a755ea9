"""jk.to_urdf: a robot written as URDF reads back (jaxkin's parser, Pinocchio's) with equal poses.

Round trips ``robot -> to_urdf -> load_urdf`` over random DH robots (both conventions, prismatic
joints, base and tool) and random trees (arbitrary axes, fixed joints) as hypothesis properties:
every frame of the original has the same pose in the reloaded robot (matched by name, 1e-12
times the reach) at random configurations, and joint names and limits survive. Every zoo robot is
also read by Pinocchio (urdfdom and its own joint algebra), whose frame placements must agree.
"""

from __future__ import annotations

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sampling import random_q
from _xla import FAST_COMPILE, op_by_op
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
from jaxkin import testing

_fk_all = jax.jit(
    jax.vmap(jk.fk_all, in_axes=(None, 0)), static_argnums=0, compiler_options=FAST_COMPILE
)


def _assert_same_poses(robot: jk.Robot, other: jk.Robot, qs: np.ndarray) -> None:
    """Every frame of ``robot`` has the same pose in ``other`` (frames and joints by name)."""
    perm = [robot.joint_names.index(n) for n in other.joint_names]
    assert sorted(perm) == list(range(robot.dof))
    Ta = np.asarray(_fk_all(robot, jnp.asarray(qs)))
    Tb = np.asarray(_fk_all(other, jnp.asarray(qs[:, perm])))
    idx = [other.frame_names.index(n) for n in robot.frame_names]
    reach = max(1.0, float(np.abs(Ta[..., :3, 3]).max()))
    np.testing.assert_allclose(Tb[:, idx], Ta, rtol=0, atol=1e-12 * reach)
    lo, hi = np.asarray(robot.lower)[perm], np.asarray(robot.upper)[perm]
    np.testing.assert_array_equal(np.asarray(other.lower), lo)
    np.testing.assert_array_equal(np.asarray(other.upper), hi)


@settings(max_examples=15)
@given(st.one_of(testing.dh_robots(1, 8, dtype=np.float64), testing.tree_robots(1, 8, np.float64)))
@op_by_op
def test_property_round_trip_through_urdf(robot):
    """Each example's two robots are used once: op by op, nothing compiled per example."""
    back = jk.load_urdf(jk.to_urdf(robot), dtype=np.float64)
    _assert_same_poses(robot, back, random_q(robot, 4, seed=0))


def test_zoo_robots_read_by_pinocchio():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        pin = pytest.importorskip("pinocchio")
    for name in jk.robots.names():
        robot = jk.robots.load(name, dtype=np.float64)
        xml = jk.to_urdf(robot, prismatic_limit=2.0)
        # one set of configurations (one shape) for both checks: the robot's kernel compiles once;
        # drawn by numpy (no sampler compiled per robot: the sampler is not under test here)
        qs = random_q(robot, 5, seed=2)
        _assert_same_poses(robot, jk.load_urdf(xml, dtype=np.float64), qs)
        model = pin.buildModelFromXML(xml)
        data = model.createData()
        pin_joints = [model.joints[model.getJointId(n)] for n in robot.joint_names]
        Ts = np.asarray(_fk_all(robot, jnp.asarray(qs)))
        for q, T in zip(qs, Ts, strict=True):
            q_pin = np.zeros(model.nq)
            for joint, value in zip(pin_joints, q, strict=True):
                if joint.nq == 2:  # continuous: (cos q, sin q)
                    q_pin[joint.idx_q : joint.idx_q + 2] = math.cos(value), math.sin(value)
                else:
                    q_pin[joint.idx_q] = value
            pin.framesForwardKinematics(model, data, q_pin)
            for f, frame in enumerate(robot.frame_names):
                M = data.oMf[model.getFrameId(frame)].homogeneous
                np.testing.assert_allclose(M, T[f], rtol=0, atol=1e-12, err_msg=(name, frame))


def test_mimic_joints_base_and_tool_survive():
    joints = [
        dict(name="lead", type="revolute", parent="root", child="a", xyz=(0.1, 0, 0.2),
             rpy=(0.3, 0.0, 0.0), axis=(0, 0, 1), lower=-1.0, upper=2.0),
        dict(name="follow", type="revolute", parent="a", child="b", xyz=(0.3, 0, 0),
             axis=(0, 1, 0), mimic={"joint": "lead", "multiplier": -0.5, "offset": 0.2}),
        dict(name="slide", type="prismatic", parent="b", child="c", xyz=(0, 0, 0.1),
             axis=(1, 0, 0), lower=0.0, upper=0.4),
    ]  # fmt: skip
    base = np.eye(4)
    base[:3, 3] = [0.5, -0.2, 0.1]
    tool = np.eye(4)
    tool[:3, 3] = [0.0, 0.0, 0.05]
    robot = jk.Robot.from_joints(joints, root="root", base=base, tool=tool, dtype=np.float64)
    xml = jk.to_urdf(robot)
    assert '<mimic joint="lead" multiplier="-0.5" offset="0"/>' in xml
    assert '<link name="world"/>' in xml  # the base placement
    back = jk.load_urdf(xml, dtype=np.float64)
    assert back.joint_names == ("lead", "slide") and back.dof == 2
    _assert_same_poses(robot, back, random_q(robot, 5, seed=3))


def test_continuous_joints_and_awkward_names():
    rows = [
        dict(a=0.3, alpha=math.pi / 2, d=0.1, theta=0.0, joint="revolute", name='j<1>&"'),
        dict(a=0.2, alpha=0.0, d=0.0, theta=0.5, joint="revolute", lower=-1.0, upper=1.0),
    ]
    robot = jk.Robot.from_dh(rows, dtype=np.float64)
    xml = jk.to_urdf(robot)
    assert 'type="continuous"' in xml
    back = jk.load_urdf(xml, dtype=np.float64)
    assert back.joint_names[0] == 'j<1>&"'
    assert np.isinf(np.asarray(back.lower)[0]) and np.isinf(np.asarray(back.upper)[0])
    _assert_same_poses(robot, back, np.array([[4.0, 0.5], [-5.0, -0.9]]))


def test_errors_name_the_joint_and_the_fix():
    prismatic = jk.Robot.from_dh(
        [dict(a=0.0, alpha=0.0, d=0.0, theta=0.0, joint="prismatic", name="slider")]
    )
    with pytest.raises(jk.ModelError, match=r"'slider'.*prismatic_limit=L"):
        jk.to_urdf(prismatic)
    assert 'lower="-0.5" upper="0.5"' in jk.to_urdf(prismatic, prismatic_limit=0.5)
    with pytest.raises(jk.ModelError, match="prismatic_limit must be a positive number"):
        jk.to_urdf(prismatic, prismatic_limit=-1.0)
    one_sided = jk.Robot.from_dh(
        [dict(a=0.1, alpha=0.0, d=0.0, theta=0.0, joint="revolute", lower=-1.0, name="half")]
    )
    with pytest.raises(jk.ModelError, match="'half' is bounded on one side only"):
        jk.to_urdf(one_sided)
    scaled = jk.robots.load("two_link_planar")
    scaled = scaled.replace(multiplier=jnp.asarray([2.0, 1.0], scaled.dtype))
    with pytest.raises(jk.ModelError, match=r"multiplier 2\.0; URDF can scale only mimic joints"):
        jk.to_urdf(scaled)
    with pytest.raises(jk.ModelError, match="concrete parameters"):
        jax.jit(lambda r: jk.to_urdf(r) and 0)(jk.robots.load("two_link_planar"))
    with pytest.raises(jk.ModelError, match="expects a jaxkin Robot"):
        jk.to_urdf("panda")


@pytest.mark.parametrize("bad", ["\x00", "\x01", "\x1b", "\ufffe", "\ud800"])
@pytest.mark.parametrize("where", ["robot", "joint", "frame"])
def test_names_xml_cannot_carry_are_refused_by_name(bad, where):
    name = f"link{bad}2"
    rows = [
        dict(a=0.3, alpha=0.0, d=0.0, theta=0.0, joint="revolute", name="j1"),
        dict(a=0.2, alpha=0.0, d=0.0, theta=0.0, joint="revolute", name="j2"),
    ]
    if where == "joint":
        rows[1]["name"] = name
        robot = jk.Robot.from_dh(rows)
    elif where == "robot":
        robot = jk.Robot.from_dh(rows, name=name)
    else:
        joints = [
            dict(name="j1", type="revolute", parent="base", child="l1", axis=(0, 0, 1)),
            dict(name="j2", type="revolute", parent="l1", child=name, xyz=(0.3, 0, 0)),
        ]
        robot = jk.Robot.from_joints(joints, root="base")
    with pytest.raises(jk.ModelError, match=rf"{where} name .*XML 1\.0 cannot carry"):
        jk.to_urdf(robot)


def test_tabs_and_newlines_in_names_survive_the_round_trip():
    rows = [dict(a=0.3, alpha=0.0, d=0.0, theta=0.0, joint="revolute", name="j\n1\t\r")]
    robot = jk.Robot.from_dh(rows, name="two\nlines", dtype=np.float64)
    back = jk.load_urdf(jk.to_urdf(robot), dtype=np.float64)
    assert back.joint_names == robot.joint_names and back.name == robot.name
