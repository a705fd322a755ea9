"""jk.load_mjcf against MuJoCo, feature by feature, each a small hand-written MJCF string:
every body and site pose equals ``mj_kinematics`` and point Jacobians equal ``mj_jac`` (1e-12,
float64; tests/_mjcf_oracle.py), with ``q`` = MuJoCo's ``qpos``. Then what MuJoCo rejects and
what jaxkin cannot represent (errors naming the element), the default frame, ``base``/``tip``,
zero-dof models, missing assets and the missing extra. Real models: tests/test_mjcf_models.py."""

from __future__ import annotations

import builtins
import math

import mujoco
import numpy as np
import pytest
from _mjcf_oracle import check, sample

import jaxkin as jk
from jaxkin.mjcf import MJCFDependencyError, MJCFError


def _both(xml: str, **kw):
    return mujoco.MjModel.from_xml_string(xml), jk.load_mjcf(xml, dtype=np.float64, **kw)


def _mj(body: str, head: str = "") -> str:
    return f'<mujoco model="t">{head}<worldbody>{body}</worldbody></mujoco>'


G = '<geom size=".05"/>'

FEATURES = {
    "defaults_classes_childclass": _mj(
        f"""<body name="a" childclass="arm" pos=".1 .2 .3"><joint name="j1"/>{G}
              <body name="b" pos=".5 0 0"><joint name="j2" class="twist"/>{G}
                <site name="s" pos=".2 .1 0"/></body></body>""",
        """<default><default class="arm"><joint axis="0 1 0" range="-1 2"/>
             <default class="twist"><joint axis="1 0 0"/></default></default></default>""",
    ),
    "angle_degree": _mj(
        f"""<body name="a" euler="30 0 45"><joint name="j1" axis="0 0 1" range="-90 120"/>{G}
              <body name="b" pos=".4 0 0" euler="0 90 0"><joint name="j2" ref="30"/>{G}
                <site name="s" pos=".1 0 0" euler="10 20 30"/></body></body>""",
        '<compiler angle="degree"/>',
    ),
    "orientation_forms_radian_eulerseq": _mj(
        f"""<body name="q" quat="0.3 -0.5 0.2 0.7"><joint name="j1" axis="1 1 0"/>{G}
              <site name="sq" pos=".3 0 0" quat="1 2 3 4"/>
            <body name="e" pos="0 .3 0" euler="0.3 -0.6 1.1"><joint name="j2" axis="0 1 1"/>{G}
            <body name="aa" pos=".2 0 0" axisangle="1 -2 0.5 1.3"><joint name="j3"/>{G}
              <site name="saa" pos=".2 .2 0" axisangle="0 1 0 -1.5707963267948966"/>
            <body name="xy" pos="0 0 .2" xyaxes="0 1 0 -1 0 0.3"><joint name="j4" axis="0 0 1"/>
              {G}<site name="sxy" pos=".2 0 0" xyaxes="1 1 0 0 0 1"/>
            <body name="z" pos=".1 .1 0" zaxis="1 1 1"><joint name="j5" axis="0 1 0"/>{G}
              <site name="sz" pos="0 .2 0" zaxis="0 -1 0"/>
            </body></body></body></body></body>""",
        '<compiler angle="radian" eulerseq="ZyX"/>',
    ),
    "ref_hinge_and_slide": _mj(
        f"""<body name="a" pos="0 0 .2"><joint name="h" axis="0 1 0" ref="40" range="-10 80"/>{G}
              <body name="b" pos=".5 0 0"><joint name="p" type="slide" axis="1 0 1" ref=".2"
                range="-.5 .7"/>{G}<site name="tip" pos=".1 0 0"/></body></body>"""
    ),
    "welded_bodies_and_mocap": _mj(
        f"""<body name="m" mocap="true" pos="1 2 3"/>
            <body name="a"><joint name="j" axis="0 0 1"/>{G}
              <body name="w1" pos=".3 0 0" euler="0 0 30">{G}
                <body name="w2" pos="0 .2 0" quat="0 1 0 0">{G}
                  <body name="b" pos=".2 0 0"><joint name="k" axis="0 1 0"/>{G}</body>
                </body></body></body>"""
    ),
    "joint_anchor_pos": _mj(
        f"""<body name="a" pos=".1 0 0"><joint name="j" pos=".3 .2 -.1" axis="0 0 1"/>{G}
              <body name="b" pos="0 .5 0"><joint name="k" pos="0 0 .4" axis="1 0 0" ref="15"/>
                {G}<site name="s" pos=".1 .1 .1"/></body></body>"""
    ),
    "several_joints_in_one_body": _mj(
        f"""<body name="a" pos=".2 .1 0" euler="10 20 30">
              <joint name="x" type="slide" axis="1 0 0" ref=".1"/>
              <joint name="y" type="slide" axis="0 1 0"/>
              <joint name="yaw" axis="0 0 1" pos=".1 0 0" ref="20"/>
              <joint name="pitch" axis="0 1 0" pos="0 .2 .1"/>{G}
              <site name="s" pos=".3 0 0"/>
              <body name="b" pos=".4 0 0"><joint name="k" axis="1 0 0"/>{G}</body></body>"""
    ),
    "equality_joint_coupling": _mj(
        f"""<body name="a"><joint name="lead" axis="0 0 1" ref="10" range="-60 60"/>{G}
              <body name="b" pos=".4 0 0"><joint name="follow" axis="0 0 1" ref="-20"/>{G}
                <body name="c" pos=".3 0 0"><joint name="slider" type="slide" axis="1 0 0"/>{G}
                  <site name="tip" pos=".1 0 0"/></body></body></body>""",
        """<equality><joint joint1="follow" joint2="lead" polycoef="0.1 -0.5 0 0 0"/>
             <joint joint1="slider" joint2="follow" polycoef="0.05 0.2 0 0 0"/></equality>""",
    ),
}


@pytest.mark.parametrize("feature", list(FEATURES))
def test_feature_matches_mujoco(feature):
    """At qpos0 (the pose the file draws) and two random configurations within the ranges."""
    m, robot = _both(FEATURES[feature])
    qpos0 = [m.qpos0[m.jnt_qposadr[m.joint(n).id]] for n in robot.joint_names]
    qs = np.vstack([qpos0, sample(robot, 2, seed=1)])
    n = check(m, robot, qs, jac_frames=_jac_frames(robot))
    assert n >= 2  # bodies and sites compared


def _jac_frames(robot):
    """The default frame (or the first candidate) and one frame half-way down: two Jacobians."""
    ends = list(robot.default_frames) or [robot.frame_names[robot.tip_frame]]
    middle = robot.frame_names[len(robot.frame_names) // 2]
    return list(dict.fromkeys([ends[0], middle] if ":" not in middle else ends[:1]))


def test_degrees_are_radians_in_q_and_limits():
    m, robot = _both(FEATURES["angle_degree"])
    np.testing.assert_allclose(robot.lower[0], -math.pi / 2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(robot.upper[0], 120 * math.pi / 180, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(np.asarray([robot.lower[0], robot.upper[0]]), m.jnt_range[0])


def test_ref_q_equals_qpos_and_limits_are_jnt_range():
    """At q = ref (MuJoCo's qpos0) the robot is drawn as in the file; q is qpos, unshifted."""
    m, robot = _both(FEATURES["ref_hinge_and_slide"])
    np.testing.assert_array_equal(np.asarray(robot.lower), m.jnt_range[:, 0])
    np.testing.assert_array_equal(np.asarray(robot.upper), m.jnt_range[:, 1])
    np.testing.assert_allclose(m.qpos0, [40 * math.pi / 180, 0.2], rtol=0, atol=1e-15)
    # poses at q = qpos0 against MuJoCo: test_feature_matches_mujoco[ref_hinge_and_slide]


def test_coupled_joints_are_not_in_q():
    _, robot = _both(FEATURES["equality_joint_coupling"])
    assert robot.joint_names == ("lead",) and robot.dof == 1


def test_include(tmp_path):
    (tmp_path / "arm.xml").write_text(
        f"""<mujoco><body name="a"><joint name="j" axis="0 1 0"/>{G}
              <body name="b" pos=".3 0 0"><joint name="k"/>{G}</body></body></mujoco>"""
    )
    main = tmp_path / "scene.xml"
    main.write_text('<mujoco model="inc"><worldbody><include file="arm.xml"/></worldbody></mujoco>')
    robot = jk.load_mjcf(main, dtype=np.float64)
    assert robot.joint_names == ("j", "k") and robot.name == "inc"
    m = mujoco.MjModel.from_xml_path(str(main))
    check(m, robot, sample(robot, 2, seed=2), jac_frames=["b"])
    missing = tmp_path / "broken.xml"
    missing.write_text('<mujoco><worldbody><include file="nothere.xml"/></worldbody></mujoco>')
    with pytest.raises(MJCFError, match=r"nothere\.xml.*include") as e:
        jk.load_mjcf(missing)
    assert e.value.file == str(missing)


def test_mesh_files_are_never_needed():
    xml = _mj(
        """<body name="a"><joint name="j"/><geom type="mesh" mesh="m"/>
             <body name="b" pos=".2 0 0"><joint name="k"/><geom size=".1" material="skin"/>
           </body></body>""",
        """<asset><mesh name="m" file="nothere.stl"/><texture name="t" type="2d"
             file="nothere.png"/><material name="skin" texture="t"/></asset>""",
    )
    with pytest.raises(ValueError, match="nothere"):
        mujoco.MjModel.from_xml_string(xml)  # MuJoCo itself needs the files
    robot = jk.load_mjcf(xml, dtype=np.float64)
    assert robot.joint_names == ("j", "k") and robot.frame_names == ("world", "a", "b")


def test_default_frame_rules():
    _, robot = _both(FEATURES["welded_bodies_and_mocap"])
    assert robot.frame_names[robot.tip_frame] == "b"
    branching = _mj(
        f"""<body name="palm"><joint name="w"/>{G}
              <body name="f1" pos=".1 0 0"><joint name="a"/>{G}<site name="t1"/></body>
              <body name="f2" pos="-.1 0 0"><joint name="b"/>{G}</body></body>"""
    )
    robot = jk.load_mjcf(branching)
    assert robot.default_frames == ("t1", "f2")
    with pytest.raises(jk.NoDefaultFrameError, match="t1"):
        jk.fk(robot, np.zeros(3))
    chain = jk.load_mjcf(branching, tip="t1", dtype=np.float64)
    assert chain.joint_names == ("w", "a") and chain.frame_names[chain.tip_frame] == "t1"
    # the file loaders' one rule: where the fixed frames branch, the tool flange 'tool0'
    flange = _mj(
        f"""<body name="arm"><joint name="w"/>{G}
              <body name="wrist"><site name="ee"/><site name="tool0" pos="0 0 .1"/></body>
            </body>"""
    )
    assert jk.load_mjcf(flange).frame_names[jk.load_mjcf(flange).tip_frame] == "tool0"
    no_flange = flange.replace('"tool0"', '"flange"')
    assert jk.load_mjcf(no_flange).frame_names[jk.load_mjcf(no_flange).tip_frame] == "wrist"


def test_base_selects_a_subtree_relative_to_its_body():
    xml = FEATURES["joint_anchor_pos"]
    m = mujoco.MjModel.from_xml_string(xml)
    robot = jk.load_mjcf(xml, base="a", dtype=np.float64)
    assert robot.joint_names == ("k",) and robot.frame_names[0] == "a"  # j moves a: left out
    assert jk.load_mjcf(xml, base="b").dof == 0  # k moves b in a: above b's frame
    d = mujoco.MjData(m)
    for q in sample(robot, 2, seed=3):
        d.qpos[:] = [0.7, q[0]]  # any j: poses are relative to a
        mujoco.mj_kinematics(m, d)
        T_wb = np.eye(4)
        T_wb[:3, :3], T_wb[:3, 3] = d.xmat[1].reshape(3, 3), d.xpos[1]
        T_ws = np.eye(4)
        T_ws[:3, :3], T_ws[:3, 3] = d.site_xmat[0].reshape(3, 3), d.site_xpos[0]
        want = np.linalg.solve(T_wb, T_ws)
        np.testing.assert_allclose(jk.fk(robot, q, frame="s"), want, rtol=0, atol=1e-12)


def test_no_joint_is_a_zero_dof_robot():
    m, robot = _both(_mj(f'<body name="a" pos="1 0 0" euler="0 0 90">{G}<site name="s"/></body>'))
    assert robot.dof == 0 and robot.frame_names == ("world", "a", "s")
    check(m, robot, np.zeros((1, 0)))
    assert jk.geometric_jacobian(robot, np.zeros(0)).shape == (6, 0)


def test_float32_subset():
    xml = FEATURES["several_joints_in_one_body"]
    m = mujoco.MjModel.from_xml_string(xml)
    robot = jk.load_mjcf(xml, dtype=np.float32)
    qs = sample(robot, 2, seed=4).astype(np.float32)
    tol = 4 * np.finfo(np.float32).eps * (1 + float(np.abs(qs).max())) * robot.dof
    check(m, robot, qs, jac_frames=["b"], tol=tol)


# ------------------------------------------------------------------------------------ errors
def test_mujoco_rejects_the_file():
    bad = _mj('<body name="a"><joint name="j" type="hinj"/></body>')
    with pytest.raises(MJCFError, match=r"invalid keyword: 'hinj'.*Element 'joint', line 1"):
        jk.load_mjcf(bad)
    with pytest.raises(MJCFError, match=r"unrecognized element"):
        jk.load_mjcf(_mj('<body name="a"><jiont name="j"/></body>'))
    with pytest.raises(MJCFError, match=r"repeated name 'a'"):
        jk.load_mjcf(_mj('<body name="a">' + G + '</body><body name="a">' + G + "</body>"))
    with pytest.raises(MJCFError, match="no such file"):
        jk.load_mjcf("/nonexistent/robot.xml")
    with pytest.raises(jk.ModelError, match="source must be an MJCF path"):
        jk.load_mjcf(3.5)


@pytest.mark.parametrize(
    "xml, match",
    [
        (
            _mj(
                f'<body name="a"><joint name="x"/>{G}<body name="b"><joint name="y"/>{G}'
                "</body></body>",
                '<equality><joint name="sq" joint1="y" joint2="x" polycoef="0 1 0.5 0 0"/>'
                "</equality>",
            ),
            r"equality 'sq' on joint 'y' has a non-linear polycoef",
        ),
        (
            _mj(
                f'<body name="a"><joint name="x"/>{G}</body>',
                '<equality><joint name="hold" joint1="x"/></equality>',
            ),
            r"equality 'hold' on joint 'x' has no joint2",
        ),
        (
            _mj(
                f'<body name="a"><joint name="x"/>{G}<body name="b"><joint name="y"/>{G}'
                "</body></body>",
                '<tendon><fixed name="t1"><joint joint="x" coef="1"/></fixed><fixed name="t2">'
                '<joint joint="y" coef="1"/></fixed></tendon><equality><tendon name="te" '
                'tendon1="t1" tendon2="t2"/></equality>',
            ),
            r"tendon equality 'te' couples joints \['x', 'y'\]",
        ),
    ],
    ids=["nonlinear", "no_joint2", "tendon"],
)
def test_accepted_by_mujoco_but_refused_by_name(xml, match):
    mujoco.MjModel.from_xml_string(xml)  # MuJoCo accepts it
    with pytest.raises(MJCFError, match=match) as e:
        jk.load_mjcf(xml)
    assert e.value.element and e.value.element.startswith("<")


def test_free_joint_outside_the_selection_is_fine():
    xml = _mj(
        f"""<body name="ball"><freejoint name="fj"/>{G}</body>
            <body name="a"><joint name="j"/>{G}<site name="s" pos=".1 0 0"/></body>"""
    )
    assert jk.load_mjcf(xml, tip="s").joint_names == ("j",)
    whole = jk.load_mjcf(xml)  # free joints load (tests/test_mjcf_free_ball.py)
    assert (whole.nq, whole.nv) == (8, 7)
    assert jk.load_mjcf(xml, base="ball").dof == 0  # what hangs below it (nothing here)


def test_bad_tip_and_base():
    xml = FEATURES["joint_anchor_pos"]
    with pytest.raises(MJCFError, match=r"base='nope' is not a body"):
        jk.load_mjcf(xml, base="nope")
    with pytest.raises(MJCFError, match=r"tip='nope' is not a body or site"):
        jk.load_mjcf(xml, tip="nope")
    with pytest.raises(MJCFError, match=r"tip 'world' is not below base 'a'"):
        jk.load_mjcf(xml, tip="world", base="a")


def test_without_mujoco_the_error_names_the_extra(monkeypatch):
    real = builtins.__import__

    def no_mujoco(name, *args, **kwargs):
        if name == "mujoco":
            raise ImportError("No module named 'mujoco'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_mujoco)
    with pytest.raises(MJCFDependencyError, match=r"pip install 'jaxkin\[mjcf\]'") as e:
        jk.load_mjcf(FEATURES["joint_anchor_pos"])
    assert isinstance(e.value, ImportError) and isinstance(e.value, jk.JaxkinError)


def test_exported():
    assert jk.load_mjcf.__module__ == "jaxkin.mjcf"
    assert issubclass(MJCFError, jk.ModelError)


def test_a_leader_outside_the_part_that_itself_follows_a_joint_inside():
    """Loading the chain to ``tip`` leaves out the branch with joint ``outer``; ``arm2`` (in the
    chain) follows ``outer``, which follows ``lead`` (in the chain): the chain is followed
    through the joint left out, so ``arm2`` moves with ``lead`` and ``q`` is ``lead`` alone."""
    xml = _mj(
        f"""<body name="a"><joint name="lead" axis="0 0 1" ref="5" range="-60 60"/>{G}
              <body name="side" pos="0 .3 0"><joint name="outer" axis="1 0 0" ref="-10"/>{G}
              </body>
              <body name="b" pos=".4 0 0"><joint name="arm2" axis="0 1 0"/>{G}
                <site name="tip" pos=".2 0 0"/></body></body>""",
        """<equality><joint joint1="outer" joint2="lead" polycoef="0.2 -1.5 0 0 0"/>
             <joint joint1="arm2" joint2="outer" polycoef="-0.1 0.4 0 0 0"/></equality>""",
    )
    m, robot = _both(xml, tip="tip")
    assert robot.joint_names == ("lead",) and "side" not in robot.frame_names
    qs = np.vstack([[m.qpos0[0]], sample(robot, 3, seed=4)])
    assert check(m, robot, qs, jac_frames=["tip", "b"]) >= 3
