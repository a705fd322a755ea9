"""Every MJCF arm and hand of jk.robots.mjcf_names() (dm-control, gymnasium-robotics: the test
extra) against MuJoCo: the original file compiled by MuJoCo (meshes and all), every body and
site pose of ``mj_kinematics`` and the point Jacobians of ``mj_jac`` at the tool frame (or a
fingertip) and a frame half-way down, to 1e-12 * max(1, reach), at random configurations within
the ranges. The Franka Kitchen's burner knobs are coupled to their burners by linear joint
equalities (multiplier 174): the coupling is honoured (tests/_mjcf_oracle.py maps the columns)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from _mjcf_oracle import check, jacobian_frames, sample

import jaxkin as jk
from jaxkin.robots import mjcf as zoo

NAMES = sorted(zoo.MODELS)


def test_every_model_is_installed():
    """dm-control and gymnasium-robotics are in the test extra: every model is listed."""
    assert jk.robots.mjcf_names() == NAMES
    assert not set(NAMES) & set(jk.robots.names())


@pytest.mark.parametrize("name", NAMES)
def test_model_matches_mujoco(name):
    robot = jk.robots.load(name, dtype=np.float64)
    m = mujoco.MjModel.from_xml_path(str(zoo.path(name)))
    frames = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(1, m.nbody)] + [
        mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, s) for s in range(m.nsite)
    ]
    k = 1 if robot.dof > 20 else 2  # the hands: one fingertip (each costs a compile)
    n = check(m, robot, sample(robot, 2, seed=5), jac_frames=jacobian_frames(robot, frames, k))
    assert n >= robot.dof  # every moving body (and more) compared


def test_tool_frames_and_parts():
    expect = {
        "mjcf/jaco_arm": (6, "wristsite"),
        "mjcf/manipulator": (4, "grasp"),
        "mjcf/reacher": (2, "finger"),
        "mjcf/fetch": (11, "robot0:grip"),
        "mjcf/franka_kitchen": (7, "end_effector"),
    }
    for name, (dof, tool) in expect.items():
        robot = jk.robots.load(name)
        assert robot.dof == dof and robot.frame_names[robot.tip_frame] == tool, name
    for name, dof in (("mjcf/shadow_hand", 24), ("mjcf/adroit_hand", 24), ("mjcf/jaco_hand", 3)):
        robot = jk.robots.load(name)
        assert robot.dof == dof and not robot.has_default_frame, name
    entry = jk.robots.info("mjcf/fetch")
    assert "gymnasium-robotics" in entry.source and entry.source.startswith(
        str(zoo.path("mjcf/fetch"))
    )
    assert entry.parameters == {"tip": None, "base": None}


def test_kitchen_couplings_are_honoured():
    robot = jk.robots.load("mjcf/franka_kitchen", tip="knob 1", base="ovenroot")
    assert robot.joint_names == ("bottom_right_burner",)  # knob_Joint_1 follows it
    path = zoo.path("mjcf/franka_kitchen")
    robot = jk.load_mjcf(path, base="ovenroot", dtype=np.float64)
    m = mujoco.MjModel.from_xml_path(str(path))
    check(m, robot, sample(robot, 2, seed=6), jac_frames=["knob 1"])


def test_unknown_and_missing():
    with pytest.raises(jk.UnknownRobotError, match="Did you mean 'mjcf/fetch'"):
        jk.robots.load("mjcf/fetchh")
    with pytest.raises(jk.JaxkinError, match="no parameter"):
        jk.robots.load("mjcf/fetch", scale=2)


def test_cli_loads_mjcf_names(capsys):
    from jaxkin.cli import main

    assert main(["jacobian", "mjcf/reacher"]) == 0
    out = capsys.readouterr().out
    assert "mjcf/reacher (2 joints), frame finger" in out
