"""One loader path (issue 22, item 2): ``jk.robots.load`` takes file paths as well as names,
and every loader selects its part of the tree with :func:`jaxkin.build.select`. Host-side only:
no JAX compile."""

from __future__ import annotations

from pathlib import Path

import pytest

import jaxkin as jk
import jaxkin.build
import jaxkin.mjcf
import jaxkin.urdf
from jaxkin.build import SelectionError, select

DATA = Path(__file__).parent / "data"
KUKA = DATA / "kuka_iiwa14.urdf"
TREE = DATA / "tree_mimic.urdf"

ARM_XML = """<mujoco model="arm"><worldbody>
  <body name="upper"><joint name="shoulder" axis="0 0 1"/><geom size=".05"/>
    <body name="fore" pos="1 0 0"><joint name="elbow" axis="0 0 1"/><geom size=".05"/>
      <body name="hand" pos="1 0 0"><joint name="wrist" axis="0 1 0"/><geom size=".05"/>
        <site name="tcp" pos="0.1 0 0"/></body>
      <body name="finger" pos="0.5 0 0"><joint name="finger" axis="1 0 0"/><geom size=".05"/>
      </body></body></body>
</worldbody>
<equality><joint joint1="finger" joint2="shoulder" polycoef="0 0.5 0 0 0"/></equality>
</mujoco>"""


@pytest.mark.parametrize(
    ("path", "options"),
    [
        (KUKA, {}),
        (KUKA, {"tip": "lbr_iiwa_link_5", "base": "lbr_iiwa_link_2"}),
        (str(TREE), {"tip": "l_finger_tip"}),  # its mimic leader lies outside the chain
        (TREE, {"base": "l_upper", "name": "hand"}),
    ],
)
def test_load_of_a_urdf_path_is_load_urdf(path, options):
    assert jk.robots.load(path, **options) == jk.load_urdf(path, **options)


@pytest.mark.parametrize(
    "options",
    [{}, {"tip": "tcp"}, {"base": "fore", "tip": "finger"}, {"base": "fore", "name": "part"}],
)
def test_load_of_an_mjcf_path_is_load_mjcf(tmp_path, options):
    pytest.importorskip("mujoco")
    path = tmp_path / "arm.xml"
    path.write_text(ARM_XML)
    robot = jk.robots.load(path, **options)
    assert robot == jk.load_mjcf(path, **options)
    assert jk.robots.load(str(path), **options) == robot


def test_mjcf_leader_outside_the_selection_drives_its_follower(tmp_path):
    pytest.importorskip("mujoco")
    path = tmp_path / "arm.xml"
    path.write_text(ARM_XML)
    robot = jk.robots.load(path, base="fore", tip="finger")
    assert robot.joint_names == ("shoulder",) and robot.frame_names == ("fore", "finger")
    assert robot.name == "arm"  # the model's name (once the last outside leader's: a shadowed name)


def test_a_xacro_path_needs_trust(tmp_path):
    path = tmp_path / "arm.urdf.xacro"
    path.write_text('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"/>')
    with pytest.raises(jaxkin.urdf.URDFError, match="trust=True"):
        jk.robots.load(path)
    with pytest.raises(jaxkin.urdf.URDFError, match="trust=True"):
        jk.robots.load(str(path), tip="x")


def test_names_win_over_files_and_files_take_loader_options(tmp_path, monkeypatch):
    files = jk.robots.files
    monkeypatch.chdir(tmp_path)
    (tmp_path / "niryo_one").write_text("<robot/>")
    assert not files.is_path("niryo_one")  # a zoo name, though a file of that name exists
    assert files.is_path("./niryo_one") and files.is_path(tmp_path / "niryo_one")
    assert not files.is_path("erd/no_such_robot")  # a mistyped name: suggestions, not a file
    assert files.is_path("erd/no_such_robot.urdf") and files.is_path("robot.URDF")
    assert not files.is_path("no_such_robot") and not files.is_path("")
    with pytest.raises(jk.UnknownRobotError):
        jk.robots.load("no_such_robot")
    with pytest.raises(jk.JaxkinError, match="floating_base"):
        jk.robots.load(KUKA, floating_base=True)


def test_root_tag_reads_the_first_element_only(tmp_path):
    root_tag = jk.robots.files.root_tag
    (tmp_path / "a.xml").write_text("<?xml version='1.0'?>\n<!-- c --><mujoco><bad")
    (tmp_path / "b.xml").write_text("<!DOCTYPE x [<!ENTITY e 'x'>]><mujoco/>")
    assert root_tag(tmp_path / "a.xml") == "mujoco"
    assert root_tag(tmp_path / "b.xml") is None  # no DTD is processed
    assert root_tag(tmp_path) is None and root_tag(tmp_path / "missing.xml") is None


def test_every_file_loader_selects_with_build_select(monkeypatch, tmp_path):
    """The selection is written once: both loaders call the one in jaxkin.build."""
    assert jaxkin.urdf.select is jaxkin.build.select
    assert jaxkin.mjcf.select is jaxkin.build.select
    calls = []

    def spy(*args, **kwargs):
        calls.append(args[2:4])
        return select(*args, **kwargs)

    monkeypatch.setattr(jaxkin.urdf, "select", spy)
    jk.load_urdf(KUKA, tip="lbr_iiwa_link_3")
    assert calls == [(None, "lbr_iiwa_link_3")]
    pytest.importorskip("mujoco")
    monkeypatch.setattr(jaxkin.mjcf, "select", spy)
    jk.load_mjcf(ARM_XML, base="fore")
    assert calls[1:] == [("fore", None)]


SPECS = [  # a tree below "base": a chain a-b-c with a finger on b that follows j1
    dict(name="j1", type="revolute", parent="base", child="a", lower=-1.0, upper=1.0),
    dict(name="j2", type="revolute", parent="a", child="b", lower=-2.0, upper=2.0),
    dict(name="j3", type="prismatic", parent="b", child="c", lower=0.0, upper=0.5),
    dict(name="flange", type="fixed", parent="c", child="tool0"),
    dict(
        name="finger",
        type="revolute",
        parent="b",
        child="f",
        lower=-1.0,
        upper=1.0,
        mimic={"joint": "j1", "multiplier": 2.0},
    ),
]


def test_select_on_joint_specs():
    whole = select(SPECS, "base")
    assert whole.index == (0, 1, 2, 3, 4) and whole.leaders == []
    assert whole.default_frames == ("tool0", "f")  # the moving joints branch
    chain = select(SPECS, "base", tip="tool0")
    assert chain.index == (0, 1, 2, 3) and chain.default_frames == ("tool0",)
    part = select(SPECS, "base", base="a", tip="f")
    assert part.root == "a" and part.index == (1, 4)
    assert part.joints[1]["mimic"] == SPECS[4]["mimic"]
    assert part.leaders == [dict(name="j1", type="revolute", lower=-1.0, upper=1.0)]
    robot = jk.Robot.from_joints(
        part.joints, root=part.root, leaders=part.leaders, default_frames=part.default_frames
    )
    assert robot.joint_names == ("j2", "j1") and robot.frame_names == ("a", "b", "f")
    free = select(SPECS, "base", base="b", above=dict(name="root", type="free", parent="u"))
    assert free.root == "u" and free.joints[0]["child"] == "b" and free.index == (2, 3, 4)


@pytest.mark.parametrize(
    ("base", "tip", "problem"),
    [
        ("nowhere", None, "base"),
        (None, "nowhere", "tip"),
        ("c", "f", "not_below"),
        (3, None, "base"),
    ],
)
def test_select_names_what_it_cannot_honour(base, tip, problem):
    with pytest.raises(SelectionError) as info:
        select(SPECS, "base", base=base, tip=tip)
    assert info.value.problem == problem and isinstance(info.value, jk.ModelError)
