"""What ``jk.load_urdf`` reads, checked against an independent numpy forward kinematics of the same
numbers: joint types, axes (non-unit, CAD residue, tiny and huge components: normalised in
float64), origin rpy (URDF's ``Rz(yaw) Ry(pitch) Rx(roll)``), the URDF defaults, limits, mimic
joints (folding, chains, leaders outside a selection), trees (zero columns off the path),
``tip``/``base`` selection, joint order and names, floating/planar refusal with its workaround,
encodings, dtypes, and the ``example-robot-data`` registry (``"erd/..."`` names; no shadowing).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import jaxkin as jk
from jaxkin.robots import example_robot_data as erd
from jaxkin.urdf import URDFError, URDFWarning, load_urdf, parse_urdf

TOL = 1e-12


# ----------------------------------------------------------------------------------- builders
def joint_xml(
    name,
    kind,
    parent,
    child,
    xyz=None,
    rpy=None,
    axis=None,
    limit=(-2.0, 2.0),
    mimic=None,
) -> str:
    parts = [f'  <joint name="{name}" type="{kind}">']
    parts.append(f'    <parent link="{parent}"/><child link="{child}"/>')
    if xyz is not None or rpy is not None:
        attrs = ""
        if xyz is not None:
            attrs += f' xyz="{xyz}"'
        if rpy is not None:
            attrs += f' rpy="{rpy}"'
        parts.append(f"    <origin{attrs}/>")
    if axis is not None:
        parts.append(f'    <axis xyz="{axis}"/>')
    if kind in ("revolute", "prismatic") and limit is not None:
        parts.append(f'    <limit lower="{limit[0]}" upper="{limit[1]}" effort="1" velocity="1"/>')
    if mimic is not None:
        leader, m, o = mimic
        parts.append(f'    <mimic joint="{leader}" multiplier="{m}" offset="{o}"/>')
    parts.append("  </joint>")
    return "\n".join(parts)


def robot_xml(links, joints, name="test_robot") -> str:
    body = [f'  <link name="{link}"/>' for link in links] + list(joints)
    return '<?xml version="1.0"?>\n<robot name="{}">\n{}\n</robot>\n'.format(name, "\n".join(body))


# ----------------------------------------------------------------------------------- numpy oracle
def rot_x(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)


def rot_y(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)


def rot_z(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=float)


def homogeneous(R=None, p=None):
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def rodrigues(axis, angle):
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def numpy_fk(model, values: dict[str, float]) -> dict[str, np.ndarray]:
    """T_root_link of every link from a URDFModel and joint values by joint name (independent
    of jaxkin's kernels: plain numpy, rpy as URDF defines it)."""
    T = {model.root: np.eye(4)}
    for j in model.depth_first():
        origin = homogeneous(rot_z(j.rpy[2]) @ rot_y(j.rpy[1]) @ rot_x(j.rpy[0]), j.xyz)
        v = values.get(j.name, 0.0)
        if j.type in ("revolute", "continuous"):
            motion = homogeneous(rodrigues(j.axis, v))
        elif j.type == "prismatic":
            motion = homogeneous(p=np.asarray(j.axis) * v)
        else:
            motion = np.eye(4)
        T[j.child] = T[j.parent] @ origin @ motion
    return T


def joint_values(model, robot, q) -> dict[str, float]:
    """Every moving joint's value from jaxkin's q (mimic joints resolved)."""
    index = {n: i for i, n in enumerate(robot.joint_names)}
    by_name = model.joint_map
    out = {}
    for j in model.joints:
        if j.type == "fixed":
            continue
        m, o, cur = 1.0, 0.0, j
        while cur.mimic is not None:
            m, o = m * cur.mimic.multiplier, m * cur.mimic.offset + o
            cur = by_name[cur.mimic.joint]
        if cur.name in index:
            out[j.name] = m * q[index[cur.name]] + o
    return out


def assert_matches_numpy(xml, q, robot=None, model=None):
    model = model or parse_urdf(xml)
    robot = robot or load_urdf(xml, dtype=np.float64)
    expected = numpy_fk(model, joint_values(model, robot, np.asarray(q, dtype=float)))
    Ts = np.asarray(jk.fk_all(robot, np.asarray(q, dtype=float)))
    for k, name in enumerate(robot.frame_names):
        np.testing.assert_allclose(Ts[k], expected[name], rtol=0, atol=TOL, err_msg=name)
    return robot, model


# ----------------------------------------------------------------------------------- axes
@pytest.mark.parametrize(
    ("axis", "unit"),
    [
        ("0 0 2", (0.0, 0.0, 1.0)),
        ("0 1 6.12323e-17", (0.0, 1.0, 6.12323e-17)),
        ("3 4 0", (0.6, 0.8, 0.0)),
        ("-0.0 0 -5", (-0.0, 0.0, -1.0)),
        ("1e-310 0 0", (1.0, 0.0, 0.0)),
        ("4e-320 3e-320 0", (0.8, 0.6, 0.0)),
        ("1e300 1e300 0", (math.sqrt(0.5), math.sqrt(0.5), 0.0)),
    ],
)
def test_axes_are_normalised_in_float64(axis, unit):
    xml = robot_xml(["a", "b"], [joint_xml("j", "revolute", "a", "b", axis=axis)])
    robot = load_urdf(xml, dtype=np.float64)
    got = np.asarray(robot.axis, dtype=np.float64)[0]
    np.testing.assert_allclose(got, unit, rtol=0, atol=2.3e-16)
    assert abs(np.linalg.norm(got) - 1.0) <= 2.3e-16
    assert parse_urdf(xml).joints[0].axis == tuple(got)


def test_cad_residue_axis_is_taken_as_written():
    # 6.12323e-17 = cos(pi/2) in float64: the axis is y to the last bit; nothing is rounded away.
    xml = robot_xml(["a", "b"], [joint_xml("j", "revolute", "a", "b", axis="0 1 6.12323e-17")])
    robot = load_urdf(xml, dtype=np.float64)
    assert np.asarray(robot.axis)[0].tolist() == [0.0, 1.0, 6.12323e-17]
    assert_matches_numpy(xml, [0.7], robot)


def test_random_non_unit_axes_match_numpy_fk():
    rng = np.random.default_rng(3)
    links = ["l0", "l1", "l2", "l3", "l4"]
    joints = []
    for i in range(4):
        axis = " ".join(repr(float(x)) for x in rng.normal(size=3) * 10 ** rng.uniform(-3, 3))
        xyz = " ".join(repr(float(x)) for x in rng.normal(size=3) * 0.3)
        rpy = " ".join(repr(float(x)) for x in rng.uniform(-math.pi, math.pi, 3))
        kind = ("revolute", "prismatic", "continuous", "revolute")[i]
        joints.append(joint_xml(f"j{i}", kind, links[i], links[i + 1], xyz, rpy, axis))
    xml = robot_xml(links, joints)
    robot = load_urdf(xml, dtype=np.float64)
    for q in rng.uniform(-2, 2, (3, 4)):
        assert_matches_numpy(xml, q, robot)


# ----------------------------------------------------------------------------------- origins
def test_origin_rpy_is_fixed_axis_roll_pitch_yaw():
    r, p, y = 0.3, -1.1, 2.5
    xml = robot_xml(
        ["a", "b", "c"],
        [
            joint_xml("f", "fixed", "a", "b", xyz="0.1 -0.2 0.3", rpy=f"{r} {p} {y}"),
            joint_xml("j", "revolute", "b", "c", axis="0 0 1"),
        ],
    )
    robot = load_urdf(xml, dtype=np.float64)
    T = np.asarray(jk.fk(robot, [0.0], frame="b"))
    expected = homogeneous(rot_z(y) @ rot_y(p) @ rot_x(r), [0.1, -0.2, 0.3])
    np.testing.assert_allclose(T, expected, rtol=0, atol=TOL)


def test_urdf_defaults():
    # No origin (identity), origin without rpy / without xyz, no axis (1 0 0), limit without
    # lower/upper (0, 0 per the URDF spec).
    xml = robot_xml(
        ["a", "b", "c", "d", "e"],
        [
            joint_xml("no_origin", "revolute", "a", "b"),
            joint_xml("xyz_only", "prismatic", "b", "c", xyz="0 0 0.5", axis="0 1 0"),
            joint_xml("rpy_only", "continuous", "c", "d", rpy="0 0 1.5707963267948966"),
            '  <joint name="bare_limit" type="revolute"><parent link="d"/><child link="e"/>'
            '<limit effort="1" velocity="1"/></joint>',
        ],
    )
    model = parse_urdf(xml)
    j = model.joint_map
    assert j["no_origin"].xyz == (0.0, 0.0, 0.0) and j["no_origin"].rpy == (0.0, 0.0, 0.0)
    assert j["no_origin"].axis == (1.0, 0.0, 0.0)
    assert j["xyz_only"].rpy == (0.0, 0.0, 0.0) and j["rpy_only"].xyz == (0.0, 0.0, 0.0)
    assert (j["bare_limit"].lower, j["bare_limit"].upper) == (0.0, 0.0)
    robot = load_urdf(xml, dtype=np.float64)
    np.testing.assert_array_equal(np.asarray(robot.lower), [-2.0, -2.0, -np.inf, 0.0])
    np.testing.assert_array_equal(np.asarray(robot.upper), [2.0, 2.0, np.inf, 0.0])
    assert_matches_numpy(xml, [0.4, 0.2, -2.0, 0.0], robot, model)
    # Revolute about the default x axis: the child's y axis turns towards z.
    T = np.asarray(jk.fk(robot, [0.5, 0.0, 0.0, 0.0], frame="b"))
    np.testing.assert_allclose(T[:3, :3], rot_x(0.5), rtol=0, atol=TOL)


def test_continuous_joint_is_one_unbounded_angle():
    xml = robot_xml(
        ["a", "b"], [joint_xml("c", "continuous", "a", "b", xyz="1 0 0", axis="0 0 1", limit=None)]
    )
    robot = load_urdf(xml, dtype=np.float64)
    assert robot.dof == 1 and robot.joint_kinds == ("revolute",)
    assert np.isneginf(robot.lower[0]) and np.isposinf(robot.upper[0])
    T1 = np.asarray(jk.fk(robot, [0.3]))
    T2 = np.asarray(jk.fk(robot, [0.3 + 4 * math.pi]))
    np.testing.assert_allclose(T1, T2, rtol=0, atol=1e-14)
    np.testing.assert_allclose(T1[:3, :3], rot_z(0.3), rtol=0, atol=TOL)
    J = np.asarray(jk.geometric_jacobian(robot, [0.3]))
    np.testing.assert_allclose(J[:, 0], [0, 0, 0, 0, 0, 1], rtol=0, atol=TOL)


def test_limits_are_kept():
    xml = robot_xml(
        ["a", "b", "c"],
        [
            joint_xml("r", "revolute", "a", "b", axis="0 0 1", limit=(-2.5, 1.25)),
            joint_xml("p", "prismatic", "b", "c", axis="0 0 1", limit=(0.01, 0.3)),
        ],
    )
    robot = load_urdf(xml, dtype=np.float64)
    assert np.asarray(robot.lower).tolist() == [-2.5, 0.01]
    assert np.asarray(robot.upper).tolist() == [1.25, 0.3]


# Files urdfdom loads (issue 21): lower > upper, how some simulators write "no limits", and a
# repeated identical <axis>. Pinocchio (through urdfdom) is the reference for the poses.
INVERTED = robot_xml(
    ["a", "b", "c", "d", "e"],
    [
        joint_xml("r", "revolute", "a", "b", "0 0 0.3", "0.1 0 0", "0 0 1", limit=(1.0, -1.0)),
        joint_xml("p", "prismatic", "b", "c", "0.2 0 0", None, "1 0 0", limit=(0.5, -0.5)),
        joint_xml("f", "fixed", "c", "d", "0 0.1 0", limit=(2, -2)),
        joint_xml("w", "revolute", "d", "e", "0 0 0.1", None, "0 1 0", limit=(-0.5, 0.5)),
    ],
).replace(  # a fixed joint's <limit>, inverted too: not read
    'type="fixed">', 'type="fixed"><limit lower="2" upper="-2" effort="1" velocity="1"/>'
)


def pinocchio_poses(xml: str, q) -> dict[str, np.ndarray]:
    """Every link's pose by Pinocchio (urdfdom's reading of the file) at q (revolute and
    prismatic joints only, in the file's depth-first order)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        pin = pytest.importorskip("pinocchio")
    model = pin.buildModelFromXML(xml)
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    return {f.name: data.oMf[i].homogeneous for i, f in enumerate(model.frames)}, model


def test_lower_above_upper_means_unbounded_with_one_warning_as_urdfdom_loads_it():
    with pytest.warns(URDFWarning) as record:
        robot = load_urdf(INVERTED, dtype=np.float64)
    assert len(record) == 1  # one warning for the file, naming every such joint and its line
    message = str(record[0].message)
    assert message.startswith("<string>: joint 'r' (line 12: 1.0 > -1.0), joint 'p' (line 18: ")
    assert "unbounded" in message and "Fix:" in message and "'w'" not in message
    assert "'f'" not in message  # a fixed joint's <limit> is not read
    assert record[0].filename == __file__  # it points at the caller's line, not into jaxkin
    assert np.all(np.isneginf(robot.lower[:2])) and np.all(np.isposinf(robot.upper[:2]))
    assert np.asarray(robot.lower[2]) == -0.5 and np.asarray(robot.upper[2]) == 0.5
    # urdfdom loads it too (keeping the inverted numbers, which no value satisfies), same poses
    q = [2.5, -0.8, 0.3]  # outside the written "limits": they mean none
    poses, model = pinocchio_poses(INVERTED, q)
    assert model.lowerPositionLimit.tolist()[:2] == [1.0, 0.5]
    assert model.upperPositionLimit.tolist()[:2] == [-1.0, -0.5]
    Ts = np.asarray(jk.fk_all(robot, q))
    for k, name in enumerate(robot.frame_names):
        np.testing.assert_allclose(Ts[k], poses[name], rtol=0, atol=TOL, err_msg=name)
    # a sampler and IK see an unbounded joint: samples are finite
    assert np.all(np.isfinite(np.asarray(jk.sample_configurations(robot, 4, 0))))


def test_limits_of_continuous_and_fixed_joints_are_ignored_silently():
    xml = INVERTED.replace('lower="1.0" upper="-1.0"', 'lower="-1.0" upper="1.0"').replace(
        'lower="0.5" upper="-0.5"', 'lower="0" upper="0.5"'
    )
    xml = xml.replace(
        '<joint name="w" type="revolute">', '<joint name="w" type="continuous">'
    ).replace('lower="-0.5" upper="0.5"', 'lower="3" upper="-3"')
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning: the docs say these limits are not read
        robot = load_urdf(xml, dtype=np.float64)
    assert np.isneginf(robot.lower[2]) and np.isposinf(robot.upper[2])
    assert robot.lower.tolist()[:2] == [-1.0, 0.0]
    with pytest.raises(URDFError, match="'abc' is not a number"):  # they must still be numbers
        load_urdf(xml.replace('lower="3"', 'lower="abc"'))


def test_identical_repeated_axes_load_with_one_warning():
    xml = INVERTED.replace('lower="1.0" upper="-1.0"', 'lower="-1.0" upper="1.0"').replace(
        'lower="0.5" upper="-0.5"', 'lower="0" upper="0.5"'
    )
    dup = xml.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 1"/>\n    <axis xyz="0 0 1.0"/>')
    dup = dup.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 1 0"/><axis xyz="0 1 0"/>')
    with pytest.warns(URDFWarning) as record:
        robot = load_urdf(dup, dtype=np.float64)
    assert len(record) == 1
    message = str(record[0].message)
    assert "joint 'r' (<axis> on lines 11, 12), joint 'w' (<axis> on lines 28, 28)" in message
    assert "as urdfdom takes the first" in message
    assert robot == load_urdf(xml, dtype=np.float64)
    q = [0.7, 0.2, -0.4]
    poses, _ = pinocchio_poses(dup, q)
    Ts = np.asarray(jk.fk_all(robot, q))
    for k, name in enumerate(robot.frame_names):
        np.testing.assert_allclose(Ts[k], poses[name], rtol=0, atol=TOL, err_msg=name)


# ----------------------------------------------------------------------------------- frames, tree
TREE = robot_xml(
    ["base", "torso", "l_arm", "l_hand", "l_tool", "r_arm", "r_hand", "head"],
    [
        # File order deliberately not depth-first: the right arm comes first, the head last.
        joint_xml("r_shoulder", "revolute", "torso", "r_arm", "0 -0.2 0.4", "0.1 0 0", "0 1 0"),
        joint_xml("waist", "continuous", "base", "torso", "0 0 0.5", None, "0 0 1", limit=None),
        joint_xml("l_shoulder", "revolute", "torso", "l_arm", "0 0.2 0.4", "-0.1 0 0", "0 1 0"),
        joint_xml("l_elbow", "revolute", "l_arm", "l_hand", "0.3 0 0", None, "0 0 1"),
        joint_xml("l_tool_mount", "fixed", "l_hand", "l_tool", "0.1 0 0", "0 1.5707963267948966 0"),
        joint_xml("r_slide", "prismatic", "r_arm", "r_hand", "0.3 0 0", None, "1 0 0", (0, 0.2)),
        joint_xml("neck", "revolute", "torso", "head", "0 0 0.6", None, "1 1 0"),
    ],
    name="two_arms",
)


def test_tree_order_names_and_frames():
    robot = load_urdf(TREE, dtype=np.float64)
    model = parse_urdf(TREE)
    # q order: depth-first from the root, siblings in file order.
    assert robot.joint_names == ("waist", "r_shoulder", "r_slide", "l_shoulder", "l_elbow", "neck")
    assert model.independent_joints == robot.joint_names
    assert robot.frame_names == (
        "base",
        "torso",
        "r_arm",
        "r_hand",
        "l_arm",
        "l_hand",
        "l_tool",
        "head",
    )
    assert robot.name == "two_arms" and model.root == "base"
    assert [link.line for link in model.links] == list(range(3, 11))
    # Joint names map to q entries and back.
    index = {n: i for i, n in enumerate(robot.joint_names)}
    assert [robot.joint_names[index[n]] for n in robot.joint_names] == list(robot.joint_names)
    rng = np.random.default_rng(0)
    for q in rng.uniform(-1, 1, (3, robot.dof)):
        assert_matches_numpy(TREE, q, robot, model)


def test_fixed_frames_are_kept_and_addressable():
    robot = load_urdf(TREE, dtype=np.float64)
    q = np.array([0.2, -0.3, 0.1, 0.4, -0.5, 0.6])
    T_hand = np.asarray(jk.fk(robot, q, frame="l_hand"))
    T_tool = np.asarray(jk.fk(robot, q, frame="l_tool"))
    mount = homogeneous(rot_y(math.pi / 2), [0.1, 0, 0])
    np.testing.assert_allclose(T_tool, T_hand @ mount, rtol=0, atol=TOL)
    J_hand = np.asarray(jk.geometric_jacobian(robot, q, frame="l_hand", reference="local"))
    J_tool = np.asarray(jk.geometric_jacobian(robot, q, frame="l_tool", point=[0, 0, 0]))
    assert J_hand.shape == J_tool.shape == (6, 6)


def test_tree_jacobian_has_exact_zero_columns_off_the_path():
    robot = load_urdf(TREE, dtype=np.float64)
    q = np.array([0.2, -0.3, 0.1, 0.4, -0.5, 0.6])
    on_path = {
        "l_tool": {"waist", "l_shoulder", "l_elbow"},
        "r_hand": {"waist", "r_shoulder", "r_slide"},
        "head": {"waist", "neck"},
        "torso": {"waist"},
        "base": set(),
    }
    for frame, joints in on_path.items():
        for ref in ("world_aligned", "local", "world"):
            J = np.asarray(jk.geometric_jacobian(robot, q, frame=frame, reference=ref))
            for i, name in enumerate(robot.joint_names):
                if name in joints:
                    assert np.any(J[:, i] != 0.0), (frame, name)
                else:
                    assert np.all(J[:, i] == 0.0), (frame, name, ref)


# ----------------------------------------------------------------------------------- tip / base
def test_tip_selects_the_chain_and_agrees_with_the_tree():
    tree = load_urdf(TREE, dtype=np.float64)
    chain = load_urdf(TREE, tip="l_tool", dtype=np.float64)
    assert chain.frame_names == ("base", "torso", "l_arm", "l_hand", "l_tool")
    assert chain.joint_names == ("waist", "l_shoulder", "l_elbow")
    assert chain.frame_names[chain.tip_frame] == "l_tool"
    q_tree = np.array([0.2, -0.3, 0.1, 0.4, -0.5, 0.6])
    q_chain = q_tree[[tree.joint_names.index(n) for n in chain.joint_names]]
    np.testing.assert_allclose(
        np.asarray(jk.fk(chain, q_chain)),
        np.asarray(jk.fk(tree, q_tree, frame="l_tool")),
        rtol=0,
        atol=TOL,
    )
    J_chain = np.asarray(jk.geometric_jacobian(chain, q_chain, reference="world"))
    J_tree = np.asarray(jk.geometric_jacobian(tree, q_tree, frame="l_tool", reference="world"))
    np.testing.assert_allclose(
        J_chain, J_tree[:, [tree.joint_names.index(n) for n in chain.joint_names]], atol=TOL
    )


def test_base_selects_the_subtree_with_its_frame_as_world():
    tree = load_urdf(TREE, dtype=np.float64)
    sub = load_urdf(TREE, base="torso", dtype=np.float64)
    assert sub.frame_names[0] == "torso" and "base" not in sub.frame_names
    assert "waist" not in sub.joint_names
    both = load_urdf(TREE, base="torso", tip="r_hand", dtype=np.float64)
    assert both.frame_names == ("torso", "r_arm", "r_hand")
    q_tree = np.array([0.2, -0.3, 0.1, 0.4, -0.5, 0.6])
    q_sub = q_tree[[tree.joint_names.index(n) for n in sub.joint_names]]
    T_torso = np.asarray(jk.fk(tree, q_tree, frame="torso"))
    for frame in sub.frame_names:
        np.testing.assert_allclose(
            np.asarray(jk.fk(sub, q_sub, frame=frame)),
            np.linalg.inv(T_torso) @ np.asarray(jk.fk(tree, q_tree, frame=frame)),
            rtol=0,
            atol=TOL,
        )


# ----------------------------------------------------------------------------------- mimic
MIMIC = robot_xml(
    ["a", "b", "c", "d", "e", "f"],
    [
        # The follower is listed before its leader, and chains: f_tip -> follower -> leader.
        joint_xml(
            "follower", "revolute", "b", "c", "0.2 0 0", None, "0 1 0", mimic=("leader", -1.5, 0.25)
        ),
        joint_xml("leader", "revolute", "a", "b", "0 0 0.3", None, "0 0 1"),
        joint_xml(
            "slide",
            "prismatic",
            "c",
            "d",
            "0.1 0 0",
            None,
            "1 0 0",
            (0, 0.1),
            ("leader", 0.02, 0.01),
        ),
        joint_xml("free", "revolute", "d", "e", "0 0 0.1", None, "1 0 0"),
        joint_xml(
            "f_tip", "continuous", "e", "f", "0.1 0 0", None, "0 0 1", None, ("follower", 2.0, -0.5)
        ),
    ],
)


def _without_mimic(xml: str) -> str:
    import re

    return re.sub(r"\s*<mimic [^>]*/>", "", xml)


def test_mimic_joints_fold_into_their_leader():
    robot = load_urdf(MIMIC, dtype=np.float64)
    model = parse_urdf(MIMIC)
    assert robot.joint_names == ("leader", "free") and robot.dof == 2
    assert model.independent_joints == ("leader", "free")
    free = load_urdf(_without_mimic(MIMIC), dtype=np.float64)
    names = free.joint_names
    rng = np.random.default_rng(1)
    for q in rng.uniform(-1, 1, (4, 2)):
        assert_matches_numpy(MIMIC, q, robot, model)
        lead = q[0]
        fol = -1.5 * lead + 0.25
        values = {
            "leader": lead,
            "free": q[1],
            "follower": fol,
            "slide": 0.02 * lead + 0.01,
            "f_tip": 2.0 * fol - 0.5,
        }
        q_free = np.array([values[n] for n in names])
        frames = ["c", "f"]  # both frames in one call: one program per robot and reference
        np.testing.assert_allclose(
            np.asarray(jk.fk(robot, q, frame=frames)),
            np.asarray(jk.fk(free, q_free, frame=frames)),
            rtol=0,
            atol=TOL,
        )
        for ref in ("world_aligned", "local", "world"):
            Js = np.asarray(jk.geometric_jacobian(robot, q, frame=frames, reference=ref))
            Jfs = np.asarray(jk.geometric_jacobian(free, q_free, frame=frames, reference=ref))
            for J, Jf in zip(Js, Jfs, strict=True):
                # d/d q_leader = sum over joints driven by it of (d value / d q_leader) * column
                col = {n: Jf[:, names.index(n)] for n in names}
                expected_leader = (
                    col["leader"]
                    - 1.5 * col["follower"]
                    + 0.02 * col["slide"]
                    + 2.0 * -1.5 * col["f_tip"]
                )
                np.testing.assert_allclose(J[:, 0], expected_leader, rtol=0, atol=TOL)
                np.testing.assert_allclose(J[:, 1], col["free"], rtol=0, atol=TOL)


def test_mimic_leader_outside_the_selection_still_drives_it():
    # Chain to "d" skips nothing; the chain from base "b" leaves the leader (a -> b) out.
    sub = load_urdf(MIMIC, base="b", tip="d", dtype=np.float64)
    assert sub.frame_names == ("b", "c", "d")
    assert sub.joint_names == ("leader",)  # the q entry is the leader's value
    assert sub.q_index == (0, 0)
    np.testing.assert_allclose(np.asarray(sub.multiplier), [-1.5, 0.02])
    np.testing.assert_allclose(np.asarray(sub.offset), [0.25, 0.01])
    np.testing.assert_allclose(np.asarray(sub.lower), [-2.0])  # the leader's limits
    full = load_urdf(MIMIC, dtype=np.float64)
    q = np.array([0.7, -0.2])
    T_b = np.asarray(jk.fk(full, q, frame="b"))
    np.testing.assert_allclose(
        np.asarray(jk.fk(sub, q[:1], frame="d")),
        np.linalg.inv(T_b) @ np.asarray(jk.fk(full, q, frame="d")),
        rtol=0,
        atol=TOL,
    )


def test_mimic_on_a_fixed_joint_is_ignored_like_urdfdom():
    xml = robot_xml(
        ["a", "b", "c"],
        [
            joint_xml("j", "revolute", "a", "b", axis="0 0 1"),
            joint_xml("f", "fixed", "b", "c", "0.1 0 0", mimic=("j", 2.0, 0.0)),
        ],
    )
    robot = load_urdf(xml, dtype=np.float64)
    assert robot.joint_names == ("j",) and robot.kinds == ("revolute", "fixed")
    with pytest.raises(URDFError, match="mimics joint 'nope', which does not exist"):
        load_urdf(xml.replace('mimic joint="j"', 'mimic joint="nope"'))


def test_from_joints_mimic_api():
    joints = [
        dict(name="a", type="revolute", child="l1", axis=(0, 0, 1)),
        dict(
            name="b",
            type="revolute",
            child="l2",
            xyz=(0.1, 0, 0),
            mimic=dict(joint="a", multiplier=2.0, offset=0.1),
        ),
    ]
    robot = jk.Robot.from_joints(joints, dtype=np.float64)
    assert robot.joint_names == ("a",) and robot.q_index == (0, 0)
    assert np.asarray(robot.multiplier).tolist() == [1.0, 2.0]
    assert np.asarray(robot.offset).tolist() == [0.0, 0.1]
    bad = [
        ({"joint": "zz"}, "mimics joint 'zz', which is not a joint of this robot"),
        ({"joint": "b"}, r"mimic joints form a cycle \(b -> b\)"),
        ({"joint": "a", "multiplier": float("nan")}, "must be finite"),
        ({"joint": "a", "gain": 2}, "unknown key"),
        ("a", "must be a mapping"),
        ({}, "needs 'joint'"),
    ]
    for mimic, message in bad:
        spec = [joints[0], {**joints[1], "mimic": mimic}]
        with pytest.raises(jk.ModelError, match=message):
            jk.Robot.from_joints(spec)
    cyc = [
        dict(name="a", type="revolute", child="l1", mimic={"joint": "b"}),
        dict(name="b", type="revolute", child="l2", mimic={"joint": "a"}),
        dict(name="c", type="revolute", child="l3"),
    ]
    with pytest.raises(jk.ModelError, match=r"cycle \(a -> b -> a\)"):
        jk.Robot.from_joints(cyc)
    fixed_leader = [
        dict(name="a", type="fixed", child="l1"),
        dict(name="b", type="revolute", child="l2", mimic={"joint": "a"}),
        dict(name="c", type="revolute", child="l3"),
    ]
    with pytest.raises(jk.ModelError, match="which is fixed"):
        jk.Robot.from_joints(fixed_leader)
    with pytest.raises(jk.ModelError, match="fixed but has a mimic"):
        jk.Robot.from_joints(
            [
                dict(name="a", type="fixed", child="l1", mimic={"joint": "c"}),
                dict(name="c", type="revolute", child="l3"),
            ]
        )


# ----------------------------------------------------------------------------------- floating
FLOATING = robot_xml(
    ["world", "pelvis", "thigh"],
    [
        '  <joint name="root_joint" type="floating"><parent link="world"/>'
        '<child link="pelvis"/></joint>',
        joint_xml("hip", "revolute", "pelvis", "thigh", "0 0.1 -0.1", None, "0 1 0"),
    ],
)


def test_floating_loads_as_a_free_joint():
    robot = load_urdf(FLOATING, dtype=np.float64)  # tests/test_floating_base.py checks it
    assert (robot.nq, robot.nv, robot.kinds[0]) == (8, 7, "free")


def test_planar_off_the_xy_plane_is_refused_by_name_never_welded():
    kind = "planar"  # without <axis>: normal 1 0 0, not the joint frame's xy plane
    xml = FLOATING.replace('type="floating"', f'type="{kind}"')
    with pytest.raises(URDFError) as info:
        load_urdf(xml)
    e = info.value
    assert (e.attribute, e.value, e.line) == ("axis", "1 0 0", 6)
    assert "joint 'root_joint'" in str(e) and "base='pelvis'" in str(e)
    # The description keeps it (for tools that handle it themselves) ...
    assert parse_urdf(xml).joint_map["root_joint"].type == kind
    # ... and the documented workaround loads what hangs below it.
    robot = load_urdf(xml, base="pelvis", dtype=np.float64)
    assert robot.frame_names == ("pelvis", "thigh") and robot.joint_names == ("hip",)
    # A selection that avoids the joint is fine too.
    assert load_urdf(xml, base="pelvis", tip="thigh").dof == 1


# ----------------------------------------------------------------------------------- sources
def test_sources_path_str_bytes_and_encodings(tmp_path):
    xml = robot_xml(
        ["a", "Glied_ä"], [joint_xml("Gelenk_ö", "revolute", "a", "Glied_ä", axis="0 0 1")]
    )
    path = tmp_path / "r.urdf"
    path.write_bytes(xml.encode("utf-8"))
    latin = xml.replace('<?xml version="1.0"?>', '<?xml version="1.0" encoding="ISO-8859-1"?>')
    sources = [
        path,
        str(path),
        xml,
        "\n  " + xml,
        xml.encode("utf-8"),
        b"\xef\xbb\xbf" + xml.encode("utf-8"),  # UTF-8 byte order mark
        bytearray(xml.encode("utf-8")),
        latin.encode("latin-1"),
        latin,  # already decoded: the declaration is moot
        xml.replace('<?xml version="1.0"?>', '<?xml version="1.0" encoding="UTF-16"?>').encode(
            "utf-16"
        ),
    ]
    for source in sources:
        robot = load_urdf(source)
        assert robot.joint_names == ("Gelenk_ö",), type(source)
        assert robot.frame_names == ("a", "Glied_ä")


def test_dtype_and_name():
    robot = load_urdf(TREE, dtype=np.float32, name="mine")
    assert robot.dtype == np.float32 and robot.name == "mine"
    assert all(np.asarray(x).dtype == np.float32 for x in (robot.axis, robot.lower, robot.base))
    assert load_urdf(TREE, dtype=np.float64).dtype == np.float64


def test_load_urdf_is_exported():
    assert jk.load_urdf is load_urdf
    assert issubclass(URDFError, jk.ModelError) and issubclass(URDFError, ValueError)


# ----------------------------------------------------------------------------------- registry

# Files of example-robot-data 6.0 that are not loadable kinematic models, and why.
ERD_UNLOADABLE = {
    "erd/ur3": "the robot has no <link>",  # an empty xacro output; use erd/ur3_robot
    "erd/alex_psyonic_hands": "mimics joint 'index_q1', which does not exist",
}


def test_erd_names_do_not_shadow_the_zoo():
    names = jk.robots.erd_names()
    assert len(names) >= 60
    assert {"erd/panda", "erd/ur3_robot", "erd/ur5_robot", "erd/ur10_robot", "erd/kinova"} <= set(
        names
    )
    assert all(n.startswith("erd/") for n in names) and len(set(names)) == len(names)
    assert "erd/anymal_b_simple/anymal" in names and "erd/anymal_c_simple/anymal" in names
    assert not any(n.startswith("erd/") for n in jk.robots.names())
    assert jk.robots.load("panda").parameterisation == "dh_modified"  # still the zoo's
    robot = jk.robots.load("erd/panda", dtype=np.float64)
    assert robot.parameterisation == "placement" and robot.name == "erd/panda"
    # the zoo loads the arm to its TCP (the default frame); the whole file has the finger too
    assert robot.dof == 7 and robot.frame_names[robot.tip_frame] == "panda_hand_tcp"
    whole = jk.load_urdf(erd.path("erd/panda"), dtype=np.float64)
    assert whole.dof == 8 and whole.joint_names[-1] == "panda_finger_joint1"
    entry = jk.robots.info("erd/panda")
    assert entry.source.startswith(str(erd.path("erd/panda")))
    assert "example-robot-data" in entry.description
    assert entry.parameters == {"tip": None, "base": None, "floating_base": False}
    hand = jk.robots.load("erd/panda", tip="panda_hand")
    assert hand.frame_names[-1] == "panda_hand" and hand.dof == 7


def test_every_erd_file_loads_or_says_why():
    loaded = 0
    for name in jk.robots.erd_names():
        if name in ERD_UNLOADABLE:
            with pytest.raises(jk.ModelError, match=ERD_UNLOADABLE[name]):
                jk.robots.load(name)
        else:
            robot = jk.robots.load(name)
            zero_dof = name in ("erd/quadrotor_base", "erd/iris_simple")  # test_zero_dof
            assert (robot.dof == 0) == zero_dof
            assert robot.frame_names[0] == parse_urdf(erd.path(name)).root
            loaded += 1
    assert loaded >= 60
    with pytest.raises(jk.ModelError, match=r"erd/ur3_robot"):
        jk.robots.load("erd/ur3")  # the message points to the loadable siblings


def test_unknown_erd_name():
    with pytest.raises(jk.UnknownRobotError, match=r"Did you mean 'erd/panda'"):
        jk.robots.load("erd/pandaa")
    with pytest.raises(jk.JaxkinError, match="no parameter"):
        jk.robots.load("erd/panda", scale=2)


def test_erd_registry_without_the_package(monkeypatch):
    monkeypatch.setattr(erd, "_index", lambda: {})
    assert jk.robots.erd_names() == []
    with pytest.raises(jk.UnknownRobotError, match="pip install example-robot-data"):
        jk.robots.load("erd/panda")


def test_erd_registry_from_an_environment_folder(tmp_path, monkeypatch):
    (tmp_path / "x_description" / "urdf").mkdir(parents=True)
    (tmp_path / "x_description" / "urdf" / "two_arms.urdf").write_text(TREE)
    monkeypatch.setenv(erd.ENV, str(tmp_path))
    erd.robots_dir.cache_clear()
    erd._index.cache_clear()
    try:
        assert jk.robots.erd_names() == ["erd/two_arms"]
        assert jk.robots.load("erd/two_arms").dof == 6
    finally:
        monkeypatch.delenv(erd.ENV)
        erd.robots_dir.cache_clear()
        erd._index.cache_clear()
