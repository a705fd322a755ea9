"""The default frame (``frame=None``) is never one that some moving joint does not move.

``jk.load_urdf``: ``tip`` if given; the end of the chain of moving joints (fixed joints followed
down from the last moving link while there is exactly one child, and where they branch, into
``tool0``, ROS-Industrial's tool flange, if one of the children is); no default when the moving
joints branch, and then every function asked for it raises :class:`NoDefaultFrameError` (a
``jk.ModelError``) listing the candidate end frames and how to choose, eagerly and under ``jit``.
The zoo's ``erd/`` robots follow the same rule (``jk.robots.load("erd/ur5_robot")`` is
``jk.load_urdf`` of its file: ``tool0``), except the arms whose standard tool frame the rule cannot
give, which load as the chain to it (``jaxkin.robots.example_robot_data.TOOL_FRAMES``); DH robots
keep their last frame.

Every check of "moves" here is independent of the code under test: the path from a link to the
root is walked in the parsed file (``parse_urdf``), and for UR5 and Panda the Jacobian itself is
checked for zero columns at random configurations.
"""

from __future__ import annotations

import pickle

import jax
import numpy as np
import pytest

import jaxkin as jk
from jaxkin import NoDefaultFrameError
from jaxkin.robots import example_robot_data as erd
from jaxkin.urdf import MOVING_TYPES, parse_urdf


def joint(name, kind, parent, child, xyz="0 0 0.1", axis="0 0 1"):
    limit = '<limit lower="-2" upper="2" effort="1" velocity="1"/>' if kind != "fixed" else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}"/><axis xyz="{axis}"/>{limit}</joint>'
    )


def urdf(links, joints, name="r"):
    body = "".join(f'<link name="{n}"/>' for n in links) + "".join(joints)
    return f'<robot name="{name}">{body}</robot>'


# An arm of three revolute joints ending in a hand with two prismatic fingers.
ARM = [
    joint("j1", "revolute", "base", "l1"),
    joint("j2", "revolute", "l1", "l2", axis="0 1 0"),
    joint("j3", "revolute", "l2", "hand", axis="0 1 0"),
]
FINGERS = urdf(
    ["base", "l1", "l2", "hand", "finger_l", "finger_r"],
    [
        *ARM,
        joint("fl", "prismatic", "hand", "finger_l", xyz="0 0.02 0.05", axis="0 1 0"),
        joint("fr", "prismatic", "hand", "finger_r", xyz="0 -0.02 0.05", axis="0 -1 0"),
    ],
    name="two_fingers",
)


def path_joints(model, link: str) -> set[str]:
    """Names of the joints on the path from the root of ``model`` to ``link`` (the file's)."""
    parent = {j.child: j for j in model.joints}
    out = set()
    while link in parent:
        out.add(parent[link].name)
        link = parent[link].parent
    return out


def moving(model, joints=None) -> set[str]:
    return {j.name for j in (model.joints if joints is None else joints) if j.type in MOVING_TYPES}


# ----------------------------------------------------------------------------------- the rule
def test_branching_robot_loads_but_the_default_frame_raises_listing_candidates():
    robot = jk.load_urdf(FINGERS, dtype=np.float64)
    assert robot.dof == 5
    q = np.full(robot.dof, 0.3)
    listing = r"finger_l.*finger_r.*frame=.*tip="
    with pytest.raises(NoDefaultFrameError, match=listing) as info:
        jk.fk(robot, q)
    assert isinstance(info.value, jk.ModelError)
    assert info.value.candidates == ("finger_l", "finger_r")
    assert "tip='hand', where they branch" in str(info.value)
    qd = np.ones(robot.dof)
    for call in (
        lambda q: jk.geometric_jacobian(robot, q),
        lambda q: jk.twist(robot, q, qd),
        lambda q: jk.fk(robot, q),
    ):
        with pytest.raises(NoDefaultFrameError, match=listing):
            call(q)
        with pytest.raises(NoDefaultFrameError, match=listing):
            jax.jit(call)(q)  # static information: raised while tracing
    with pytest.raises(NoDefaultFrameError):
        _ = robot.tip_frame
    assert not robot.has_default_frame
    # what does not use the default frame works
    Ts = jk.fk_all(robot, q)
    for f in ("finger_l", "finger_r", "hand"):
        np.testing.assert_array_equal(jk.fk(robot, q, frame=f), Ts[robot.frame_index(f)])
    J = jk.geometric_jacobian(robot, q, frame="finger_l")
    assert J.shape == (6, 5) and np.all(np.asarray(J[:, 4]) == 0.0)  # fr does not move it
    # tip= chooses: the chain to it, whose end is the default
    left = jk.load_urdf(FINGERS, tip="finger_l", dtype=np.float64)
    assert left.joint_names == ("j1", "j2", "j3", "fl")
    assert left.frame_names[left.tip_frame] == "finger_l"
    np.testing.assert_allclose(jk.fk(left, q[:4]), Ts[robot.frame_index("finger_l")], atol=1e-15)
    # the error survives pickling (pytest-xdist, multiprocessing)
    e = pickle.loads(pickle.dumps(info.value))
    assert type(e) is NoDefaultFrameError and e.candidates == info.value.candidates


def test_chain_takes_the_fixed_leaf_off_the_last_moving_link():
    # flange -> tcp hang off the last moving link; a sensor on the base comes last in the file
    # (and in depth-first order) but no joint moves it.
    xml = urdf(
        ["base", "l1", "l2", "hand", "flange", "tcp", "sensor"],
        [
            *ARM,
            joint("flange_joint", "fixed", "hand", "flange"),
            joint("tcp_joint", "fixed", "flange", "tcp", xyz="0 0 0.1"),
            joint("sensor_joint", "fixed", "base", "sensor"),
        ],
    )
    robot = jk.load_urdf(xml, dtype=np.float64)
    assert robot.frame_names[-1] == "sensor"
    assert robot.frame_names[robot.tip_frame] == "tcp" and robot.frame_index(None) == 5
    assert robot.has_default_frame
    q = np.array([0.1, -0.4, 0.7])
    np.testing.assert_array_equal(jk.fk(robot, q), jk.fk(robot, q, frame="tcp"))
    assert np.all(np.any(np.asarray(jk.geometric_jacobian(robot, q)) != 0.0, axis=0))


def test_chain_whose_fixed_leaves_branch_takes_the_last_moving_link():
    xml = urdf(
        ["base", "l1", "l2", "hand", "tool_a", "tool_b", "tool_b_tip"],
        [
            *ARM,
            joint("a", "fixed", "hand", "tool_a"),
            joint("b", "fixed", "hand", "tool_b"),
            joint("b_tip", "fixed", "tool_b", "tool_b_tip"),
        ],
    )
    robot = jk.load_urdf(xml)
    assert robot.frame_names[robot.tip_frame] == "hand"
    # an unambiguous fixed chain is followed down to where it branches
    xml2 = xml.replace('<link name="base"/>', '<link name="base"/><link name="flange"/>')
    xml2 = xml2.replace('parent link="hand"', 'parent link="flange"').replace(
        "</robot>", joint("flange_joint", "fixed", "hand", "flange") + "</robot>"
    )
    robot2 = jk.load_urdf(xml2)
    assert robot2.frame_names[robot2.tip_frame] == "flange"


def test_where_fixed_frames_branch_tool0_is_followed():
    """REP 199's tool flange: where the last moving link carries several fixed frames and one is
    ``tool0``, the default goes down to it (and on, while the fixed chain below it is single)."""
    links = ["base", "l1", "l2", "hand", "ee_link", "tool0", "flange_frame"]
    fixed = [
        joint("ee", "fixed", "hand", "ee_link", xyz="0.1 0 0"),
        joint("tool0_joint", "fixed", "hand", "tool0", xyz="0 0 0.08"),
    ]
    robot = jk.load_urdf(urdf(links[:6], [*ARM, fixed[1], fixed[0]]), dtype=np.float64)
    assert robot.frame_names[-1] == "ee_link" and robot.frame_names[robot.tip_frame] == "tool0"
    q = np.array([0.2, -0.3, 0.9])
    np.testing.assert_array_equal(jk.fk(robot, q), jk.fk(robot, q, frame="tool0"))
    below = jk.load_urdf(
        urdf(links, [*ARM, *fixed, joint("tcp", "fixed", "tool0", "flange_frame")])
    )
    assert below.frame_names[below.tip_frame] == "flange_frame"
    # deeper: the fixed frames branch below a single fixed flange link
    on_flange = [f.replace('"hand"', '"flange"') for f in fixed]
    deep = urdf([*links[:6], "flange"], [*ARM, joint("fl", "fixed", "hand", "flange"), *on_flange])
    deep = jk.load_urdf(deep)
    assert deep.frame_names[deep.tip_frame] == "tool0" and deep.frame_names[-1] == "tool0"
    # the same branch without a tool0 is unchanged: the link where the fixed frames branch
    other = urdf([*links[:5], "tool1"], [*ARM, fixed[0], fixed[1].replace('"tool0"', '"tool1"')])
    other = jk.load_urdf(other)
    assert other.frame_names[other.tip_frame] == "hand"
    # where the moving joints branch, each candidate follows the same rule
    arms = urdf(
        [*links[:6], "l1b", "tool0b"],
        [
            *ARM,
            *fixed,
            joint("jb", "revolute", "l1", "l1b"),
            joint("jb_fixed", "fixed", "l1b", "tool0b"),
        ],
    )
    with pytest.raises(NoDefaultFrameError) as info:
        jk.fk(jk.load_urdf(arms), np.zeros(4))
    assert info.value.candidates == ("tool0", "tool0b")


def test_mimic_fingers_branch_too():
    # one q entry drives both fingers, but no frame is moved by both finger joints
    xml = FINGERS.replace(
        '<limit lower="-2" upper="2" effort="1" velocity="1"/></joint></robot>',
        '<limit lower="-2" upper="2" effort="1" velocity="1"/><mimic joint="fl"/></joint></robot>',
    )
    robot = jk.load_urdf(xml)
    assert robot.dof == 4
    with pytest.raises(NoDefaultFrameError, match=r"finger_l.*finger_r"):
        jk.fk(robot, np.zeros(4))


def test_two_loads_compare_equal_and_chains_keep_the_last_frame_stored_as_default():
    assert jk.load_urdf(FINGERS) == jk.load_urdf(FINGERS)
    assert jk.load_urdf(FINGERS) != jk.load_urdf(FINGERS, tip="finger_r")
    chain = jk.load_urdf(urdf(["base", "l1", "l2", "hand"], ARM))
    assert chain.default_frames == () and chain.tip_frame == chain.n_frames - 1


def test_zoo_dh_robots_keep_their_last_frame():
    for name in jk.robots.names():
        robot = jk.robots.load(name)
        assert robot.default_frames == () and robot.tip_frame == robot.n_frames - 1, name


def test_default_frames_argument_is_validated():
    spec = [{"name": "j", "type": "revolute", "child": "a"}]
    with pytest.raises(jk.ModelError, match="not a frame"):
        jk.Robot.from_joints(spec, default_frames=("nope",))
    with pytest.raises(jk.ModelError, match="sequence of frame names"):
        jk.Robot.from_joints(spec, default_frames="a")
    assert jk.Robot.from_joints(spec, default_frames=("base",)).tip_frame == 0


# ----------------------------------------------------------------------------------- erd
def no_zero_column(robot, frame=None, n=3):
    for q in np.asarray(jk.sample_configurations(robot, n, 7)):
        J = np.asarray(jk.geometric_jacobian(robot, q, frame=frame))
        assert np.all(np.any(J != 0.0, axis=0)), (robot.name, q, J)


def test_ur5_default_frame_is_moved_by_every_joint_and_the_same_by_path_and_by_name():
    path = erd.path("erd/ur5_robot")
    whole = jk.load_urdf(path, dtype=np.float64)  # issue 3: this defaulted to the leaf 'base'
    # issue 21: ee_link and tool0 both hang on wrist_3_link; tool0 (REP 199) is the default, by
    # path as by zoo name: one rule, the same robot (the zoo names it after its zoo name)
    assert whole.frame_names[whole.tip_frame] == "tool0"
    no_zero_column(whole)
    robot = jk.robots.load("erd/ur5_robot", dtype=np.float64)
    assert robot.dof == 6 and robot.frame_names[robot.tip_frame] == "tool0"
    assert robot == jk.load_urdf(path, dtype=np.float64, name="erd/ur5_robot")
    assert robot.frame_names == whole.frame_names and robot.default_frames == whole.default_frames
    q = np.asarray(jk.sample_configurations(robot, 1, 3))[0]
    np.testing.assert_array_equal(jk.fk(robot, q), jk.fk(whole, q))
    for name in ("erd/ur3_robot", "erd/ur10_robot", "erd/ur5_gripper", "erd/xarm7"):
        by_name = jk.robots.load(name)
        assert by_name == jk.load_urdf(erd.path(name), name=name), name
        assert by_name.frame_names[by_name.tip_frame] == ("link_eef" if "xarm" in name else "tool0")


def test_panda_is_a_7_dof_arm_with_its_tcp_as_default_frame():
    links = parse_urdf(erd.path("erd/panda")).link_names
    tcp = "panda_hand_tcp" if "panda_hand_tcp" in links else "panda_hand"
    robot = jk.robots.load("erd/panda", dtype=np.float64)
    assert robot.dof == 7 and robot.frame_names[robot.tip_frame] == tcp
    assert not any("finger" in n for n in robot.joint_names + robot.frame_names)
    no_zero_column(robot)
    assert jk.robots.load("erd/panda") == jk.robots.load("erd/panda")
    with pytest.raises(NoDefaultFrameError, match=r"panda_leftfinger.*panda_rightfinger"):
        jk.fk(jk.load_urdf(erd.path("erd/panda")), np.zeros(8))  # the whole file: fingers


def test_zoo_tool_frames_exist_and_are_moved_by_every_joint():
    for name, frames in erd.TOOL_FRAMES.items():
        if name not in erd.names():
            continue
        model = parse_urdf(erd.path(name))
        tool = next(f for f in frames if f in model.link_names)
        robot = jk.robots.load(name)
        assert robot.frame_names[robot.tip_frame] == tool, name
        assert set(robot.joint_names) == moving(model) & path_joints(model, tool), name
    # base= and tip= still choose
    arm = jk.robots.load("erd/panda", base="panda_link3")
    assert arm.frame_names[0] == "panda_link3" and arm.dof == 4
    assert jk.robots.load("erd/panda", tip="panda_link8").dof == 7


def test_every_erd_file_defaults_to_a_frame_every_moving_joint_moves_or_lists_candidates():
    chains = trees = 0
    for name in jk.robots.erd_names():
        try:
            robot = jk.load_urdf(erd.path(name))
        except jk.ModelError:
            continue  # not a loadable kinematic model (test_urdf_loading.ERD_UNLOADABLE)
        model = parse_urdf(erd.path(name))
        movers = moving(model)
        on_path = {f: path_joints(model, f) for f in robot.frame_names}
        moved_by_all = [f for f in robot.frame_names if movers <= on_path[f]]
        if moved_by_all:  # the moving joints form one chain
            chains += 1
            default = robot.frame_names[robot.tip_frame]
            assert movers <= on_path[default], name
            assert default in moved_by_all, name
            continue
        trees += 1
        with pytest.raises(NoDefaultFrameError) as info:
            jk.fk(robot, np.zeros(robot.dof))
        cands = info.value.candidates
        assert len(cands) >= 2, name
        for c in cands:
            assert repr(c) in str(info.value) or len(cands) > 30, name
            assert on_path[c] & movers, (name, c)  # some moving joint moves it...
            below = [f for f in robot.frame_names if c != f and on_path[c] < on_path[f]]
            assert not any(on_path[f] & movers - on_path[c] for f in below), (name, c)  # ...last
        # every moving joint moves some candidate
        assert movers <= set().union(*(on_path[c] for c in cands)), name
    assert chains >= 15 and trees >= 40, (chains, trees)
