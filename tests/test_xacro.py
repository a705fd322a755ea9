"""xacro: ``jk.load_urdf("robot.urdf.xacro", xacro_args=..., trust=True)`` expands the file with
the xacro package (trusted files here; tests/test_xacro_hostile.py for the refusals) and parses
the result with the strict URDF parser. Oracle: the URDF the xacro file should produce, written
by hand; the two loaded robots compare equal (every number, name, limit
and the default frame), for the argument's default and a given value; and a real xacro (the
KUKA LBR iiwa of rtbdata) against the URDF shipped beside it."""

from __future__ import annotations

import builtins

import numpy as np
import pytest

import jaxkin as jk
from jaxkin.urdf import URDFError, parse_urdf

MACROS = """<?xml version="1.0"?>
<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:property name="axis_z" value="0 0 1"/>
  <xacro:macro name="link_and_joint" params="name parent length:=0.5 lower upper">
    <link name="${name}_link"/>
    <joint name="${name}" type="revolute">
      <parent link="${parent}"/>
      <child link="${name}_link"/>
      <origin xyz="${length} 0 0" rpy="0 0 ${pi/2}"/>
      <axis xyz="${axis_z}"/>
      <limit lower="${lower}" upper="${upper}" effort="1" velocity="1"/>
    </joint>
  </xacro:macro>
</robot>
"""

ROBOT = """<?xml version="1.0"?>
<robot name="xarm" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:arg name="reach" default="0.25"/>
  <xacro:property name="reach" value="$(arg reach)"/>
  <xacro:include filename="macros.xacro"/>
  <link name="base"/>
  <xacro:link_and_joint name="shoulder" parent="base" lower="-1" upper="1"/>
  <xacro:link_and_joint name="elbow" parent="shoulder_link" length="${reach}"
      lower="${-pi/4}" upper="${pi/4}"/>
  <xacro:if value="${float(reach) > 0.3}">
    <link name="tool"/>
    <joint name="flange" type="fixed"><parent link="elbow_link"/><child link="tool"/>
      <origin xyz="${2 * float(reach)} 0 0"/></joint>
  </xacro:if>
</robot>
"""


def _expected(reach: float) -> str:
    tool = (
        f'<link name="tool"/><joint name="flange" type="fixed"><parent link="elbow_link"/>'
        f'<child link="tool"/><origin xyz="{2 * reach!r} 0 0"/></joint>'
        if reach > 0.3
        else ""
    )
    joint = (
        '<joint name="{n}" type="revolute"><parent link="{p}"/><child link="{n}_link"/>'
        '<origin xyz="{x} 0 0" rpy="0 0 1.5707963267948966"/><axis xyz="0 0 1"/>'
        '<limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/></joint>'
    )
    return (
        '<robot name="xarm"><link name="base"/><link name="shoulder_link"/>'
        + joint.format(n="shoulder", p="base", x=0.5, lo=-1, hi=1)
        + '<link name="elbow_link"/>'
        + joint.format(
            n="elbow", p="shoulder_link", x=reach, lo=-0.7853981633974483, hi=0.7853981633974483
        )
        + tool
        + "</robot>"
    )


@pytest.fixture
def xacro_file(tmp_path):
    (tmp_path / "macros.xacro").write_text(MACROS)
    path = tmp_path / "arm.urdf.xacro"
    path.write_text(ROBOT)
    return path


def test_xacro_expands_to_the_urdf_it_should_produce(xacro_file):
    default = jk.load_urdf(xacro_file, dtype=np.float64, trust=True)
    assert default == jk.load_urdf(_expected(0.25), dtype=np.float64)
    assert default.frame_names == ("base", "shoulder_link", "elbow_link")
    longer = jk.load_urdf(str(xacro_file), xacro_args={"reach": 0.5}, dtype=np.float64, trust=True)
    assert longer == jk.load_urdf(_expected(0.5), dtype=np.float64)
    assert longer.frame_names[longer.tip_frame] == "tool" and longer != default
    np.testing.assert_array_equal(np.asarray(longer.params["xyz"])[-1], [1.0, 0.0, 0.0])


def test_errors_name_the_xacro_file(xacro_file, tmp_path):
    bad = tmp_path / "bad.urdf.xacro"
    bad.write_text(ROBOT.replace('lower="-1"', 'lower="${undefined_thing}"'))
    with pytest.raises(URDFError, match=r"xacro could not expand.*undefined_thing") as e:
        jk.load_urdf(bad, trust=True)
    assert e.value.file == str(bad)
    worse = tmp_path / "worse.urdf.xacro"
    worse.write_text(ROBOT.replace('parent="shoulder_link"', 'parent="nowhere"'))
    with pytest.raises(URDFError, match=r"nowhere.*\(in the URDF that xacro expanded\)") as e:
        jk.load_urdf(worse, trust=True)
    assert e.value.file == str(worse)
    with pytest.raises(URDFError, match="no such file"):
        jk.load_urdf(tmp_path / "missing.urdf.xacro", trust=True)
    with pytest.raises(jk.ModelError, match="xacro_args needs the path"):
        jk.load_urdf(_expected(0.25), xacro_args={"reach": 1}, trust=True)


def test_the_parser_itself_never_runs_xacro(xacro_file):
    with pytest.raises(URDFError, match=r"never runs xacro.*jk\.load_urdf\(.*, trust=True\)"):
        parse_urdf(xacro_file)


def test_without_xacro_the_error_names_the_extra(xacro_file, monkeypatch):
    real = builtins.__import__

    def no_xacro(name, *args, **kwargs):
        if name == "xacro":
            raise ImportError("No module named 'xacro'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_xacro)
    with pytest.raises(URDFError, match=r"pip install 'jaxkin\[xacro\]'"):
        jk.load_urdf(xacro_file, trust=True)


def test_a_real_xacro_expands_to_the_urdf_shipped_beside_it(monkeypatch):
    """The KUKA LBR iiwa 14 R820 of the Robotics Toolbox's data package (rtbdata: ROS-Industrial's
    kuka_experimental description): its xacro, which includes macros from two packages through
    ``$(find ...)``, against the URDF generated from it in the same folder. ROS resolves
    ``$(find pkg)`` through its package index; here xacro's hook names the two package folders
    (offline, as a ROS workspace would)."""
    from pathlib import Path

    from xacro import substitution_args

    rtbdata = pytest.importorskip("rtbdata")
    root = Path(rtbdata.__file__).parent / "xacro" / "kuka_description"
    shares = {
        "kuka_lbr_iiwa_support": root / "kuka_lbr_iiwa",
        "kuka_resources": root / "kuka_resources",
    }
    # xacro's $(find) hook (ament's index in ROS 2; xacrodoc, installed with the Robotics
    # Toolbox, replaces it with its own search): here, the two package folders
    monkeypatch.setattr(substitution_args, "_eval_find", lambda name: str(shares[name]))
    urdf = root / "kuka_lbr_iiwa" / "urdf"
    expanded = jk.load_urdf(urdf / "lbr_iiwa_14_r820.xacro", dtype=np.float64, trust=True)
    shipped = jk.load_urdf(urdf / "lbr_iiwa_14_r820.urdf", dtype=np.float64)
    assert expanded == shipped  # every number, name, limit and the default frame
    assert expanded.dof == 7 and expanded.frame_names[expanded.tip_frame] == "tool0"
