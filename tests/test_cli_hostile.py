"""The command line on hostile files and careless calls (issue 21): xacro only with consent,
bounded inputs, read-only output directories, flags (not Python keywords) in its advice, MJCF
file paths, robot-name suggestions and the dtype it states. Every refusal is one line, exit 2."""

import errno
import io
import os
import re
import sys
import zipfile

import numpy as np
import pytest
from test_cli import TINY_URDF, assert_usage_error, run
from test_default_frame import FINGERS

import jaxkin as jk
from jaxkin import cli


@pytest.fixture(autouse=True)
def in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


PYTHON_ADVICE = re.compile(r"\b(frame|tip|base|trust)=|jk\.")


def assert_flag_advice(capsys, *argv, match):
    """A one-line refusal whose advice names flags, not Python keywords or calls."""
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("jaxkin: error: ") and match in err, err
    assert not PYTHON_ADVICE.search(err), err
    return err


# ---------------------------------------------------------------------- xacro needs consent
XACRO = TINY_URDF.replace(
    '<robot name="tiny_arm">',
    '<robot name="tiny_arm" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
    '  <xacro:property name="reach" value="0.3"/>',
).replace('<origin xyz="0.3 0 0" rpy="0.2 0 0"/>', '<origin xyz="${reach} 0 0" rpy="0.2 0 0"/>')


def test_xacro_is_refused_without_trust_xacro(capsys, monkeypatch, in_tmp):
    assert "${reach}" in XACRO
    (in_tmp / "arm.urdf.xacro").write_text(XACRO)

    def never(*args, **kwargs):
        raise AssertionError("the file was handed to the loader without consent")

    monkeypatch.setattr(jk, "load_urdf", never)
    for command in (["jacobian"], ["velocities", "--n", "3", "--no-output"]):
        err = assert_flag_advice(capsys, *command, "./arm.urdf.xacro", match="--trust-xacro")
        assert "programs" in err and "files you trust" in err
    code, out, _ = run(capsys, "velocities", "--help")
    flat = " ".join(out.split())
    assert code == 0 and "--trust-xacro" in flat and "only for files you trust" in flat


def test_xacro_expands_with_trust_xacro(capsys, monkeypatch, in_tmp):
    pytest.importorskip("xacro")
    (in_tmp / "arm.urdf.xacro").write_text(XACRO)
    (in_tmp / "arm.urdf").write_text(TINY_URDF)
    seen, real = [], jk.load_urdf

    def spy(*args, **kwargs):
        seen.append(kwargs.get("trust"))
        return real(*args, **kwargs)

    monkeypatch.setattr(jk, "load_urdf", spy)
    code, out, err = run(capsys, "jacobian", "./arm.urdf.xacro", "--trust-xacro", "--format",
                         "csv", "--q", "0.1", "0.2", "0.05")  # fmt: skip
    assert code == 0, err
    _, expanded, _ = run(capsys, "jacobian", "arm.urdf", "--format", "csv", "--q", "0.1", "0.2",
                         "0.05")  # fmt: skip
    assert out == expanded and out.startswith("row,shoulder,elbow,slide")
    assert seen == [True, False]  # the consent is passed on for the xacro file only


# ---------------------------------------------------------------------- bounded inputs
def npy_header(shape, descr="<f8"):
    buf = io.BytesIO()
    header = {"descr": descr, "fortran_order": False, "shape": shape}
    np.lib.format.write_array_header_1_0(buf, header)
    return buf.getvalue()


def npy(a):
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def test_npz_reads_only_q_and_qd_and_states_the_dtype(capsys, in_tmp):
    # an unused member whose header declares 8 TiB (numpy allocates what the header declares
    # before reading): a zip bomb in a few bytes
    q = np.array([[0.1, 0.2], [0.3, 0.4]])
    with zipfile.ZipFile(in_tmp / "bomb.npz", "w") as z:
        z.writestr("q.npy", npy(q))
        z.writestr("junk.npy", npy_header((2**40,)) + bytes(64))
    code, out, err = run(capsys, "velocities", "two_link_planar", "--configurations", "bomb.npz",
                         "--output", "v.npz")  # fmt: skip
    assert code == 0, err
    with np.load(in_tmp / "v.npz") as d:
        np.testing.assert_array_equal(d["q"], q)
    # the summary names the dtype and says the command line turned float64 on
    (line,) = [s for s in out.splitlines() if s.strip().startswith("dtype")]
    assert "float64" in line and "jax_enable_x64" in line and "float32" in line, line


def test_npz_members_are_sized_before_they_are_read(capsys, monkeypatch, in_tmp):
    with zipfile.ZipFile(in_tmp / "huge.npz", "w") as z:
        z.writestr("q.npy", npy_header((2**40, 2)) + bytes(64))
    assert_usage_error(capsys, "velocities", "two_link_planar", "--configurations", "huge.npz",
                       match="'q' declares 16 TiB")  # fmt: skip
    with zipfile.ZipFile(in_tmp / "short.npz", "w") as z:  # a header promising more than is there
        z.writestr("q.npy", npy(np.zeros((2, 2))))
        z.writestr("qd.npy", npy_header((1000, 2)) + bytes(64))
    assert_usage_error(capsys, "velocities", "two_link_planar", "--configurations", "short.npz",
                       match="the file is corrupt")  # fmt: skip
    np.savez(in_tmp / "big.npz", q=np.zeros((100, 2)))  # 1,728 bytes with its header
    monkeypatch.setattr(jk.io, "MAX_INPUT_BYTES", 1000)
    assert_usage_error(capsys, "velocities", "two_link_planar", "--configurations", "big.npz",
                       match="over the 1,000 bytes cap")  # fmt: skip
    (in_tmp / "big.csv").write_text("0.1,0.2\n" * 200)
    assert_usage_error(capsys, "velocities", "two_link_planar", "--configurations", "big.csv",
                       match="MAX_INPUT_BYTES")  # fmt: skip


class Endless(io.RawIOBase):
    """A standard input that never ends (``yes 0.1,0.2``); reading all of it is a MemoryError."""

    def __init__(self):
        self.served = 0

    def readable(self):
        return True

    def readinto(self, b):
        if self.served > 64 << 20:
            raise MemoryError("read the endless stream whole")
        n = len(b)
        b[:n] = (b"0.1,0.2\n" * (n // 8 + 1))[:n]
        self.served += n
        return n


def test_stdin_is_read_up_to_a_cap(capsys, monkeypatch):
    stream = Endless()
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BufferedReader(stream)))
    monkeypatch.setattr(jk.io, "MAX_INPUT_BYTES", 100_000)
    assert_usage_error(capsys, "velocities", "two_link_planar", "--configurations", "-",
                       match="more than 97.7 KiB (the cap")  # fmt: skip
    assert stream.served <= 100_000 + (1 << 20)
    code, out, _ = run(capsys, "velocities", "--help")
    assert code == 0 and "MAX_INPUT_BYTES" in out and "1 GiB" in " ".join(out.split())


# ---------------------------------------------------------------------- read-only output
def test_read_only_output_directory_is_refused_before_computing(capsys, monkeypatch, in_tmp):
    ro = in_tmp / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if os.geteuid() == 0:  # root writes anywhere: give the answer a user gets
        real_open = os.open

        def refuse(path, *args, **kwargs):
            if os.path.dirname(os.path.abspath(path)) == str(ro):
                raise PermissionError(errno.EACCES, "Permission denied", path)
            return real_open(path, *args, **kwargs)

        monkeypatch.setattr(os, "open", refuse)
    computed = []
    monkeypatch.setattr(cli, "chunked_map", lambda *a, **k: computed.append(1))
    try:
        assert_usage_error(capsys, "velocities", "two_link_planar", "--n", "10", "--output",
                           "ro/v.npz", match=str(ro / "v.npz"))  # fmt: skip
    finally:
        ro.chmod(0o755)
    assert computed == [] and os.listdir(ro) == []


# ---------------------------------------------------------------------- flags, not Python
def test_refusals_advise_flags(capsys, in_tmp):
    (in_tmp / "arm.urdf").write_text(TINY_URDF)
    (in_tmp / "fingers.urdf").write_text(FINGERS)
    err = assert_flag_advice(capsys, "jacobian", "arm.urdf", "--frame", "nope",
                             match="--frame nope: robot 'tiny_arm' has no frame")  # fmt: skip
    assert "'hand'" in err  # the frames to choose from
    assert_flag_advice(capsys, "velocities", "two_link_planar", "--n", "5", "--frame", "99",
                       match="--frame 99: frame index 99 is out of range")  # fmt: skip
    err = assert_flag_advice(capsys, "jacobian", "fingers.urdf", match="has no default frame")
    assert "--frame finger_l" in err and "--tip" in err and "finger_r" in err
    assert_flag_advice(capsys, "velocities", "fingers.urdf", "--n", "5", "--no-output",
                       match="--frame finger_l")  # fmt: skip
    assert_flag_advice(capsys, "jacobian", "arm.urdf", "--tip", "nolink",
                       match="--tip 'nolink' is not a link of robot 'tiny_arm'")  # fmt: skip
    assert_flag_advice(capsys, "jacobian", "arm.urdf", "--base", "hand", "--tip", "upper",
                       match="leave out --base")  # fmt: skip


# ---------------------------------------------------------------------- MJCF files, names
MJCF = """<mujoco model="arm"><worldbody><body name="upper">
  <joint name="shoulder" axis="0 0 1" range="-90 90"/><geom size=".05"/>
  <body name="fore" pos="1 0 0"><joint name="elbow" axis="0 1 0" range="-90 90"/>
    <geom size=".05"/><site name="hand" pos="1 0 0"/></body></body>
</worldbody></mujoco>
"""


def test_mjcf_file_paths_load(capsys, in_tmp):
    pytest.importorskip("mujoco")
    (in_tmp / "arm.xml").write_text('<?xml version="1.0"?>\n<!-- an arm -->\n' + MJCF)
    (in_tmp / "tiny.xml").write_text(TINY_URDF)  # a URDF may end in .xml too
    robot = jk.load_mjcf(in_tmp / "arm.xml", dtype="float64")
    code, out, err = run(capsys, "jacobian", "arm.xml", "--q", "0.3", "-0.2", "--format", "csv")
    assert code == 0, err
    J = np.array([[float(x) for x in line.split(",")[1:]] for line in out.splitlines()[1:]])
    np.testing.assert_allclose(J, jk.geometric_jacobian(robot, np.array([0.3, -0.2])), atol=1e-15)
    code, out, err = run(capsys, "jacobian", "arm.xml", "--tip", "upper", "--q", "0.1")
    assert code == 0 and "frame upper (the tip)" in out, err
    code, out, err = run(capsys, "jacobian", "tiny.xml", "--q", "0", "0", "0")
    assert code == 0 and "robot  tiny_arm (3 joints)" in out, err
    assert_usage_error(capsys, "jacobian", "arm.xml", "--tip", "nosuch", match="--tip 'nosuch'")


def test_mistyped_robot_names_get_suggestions(capsys):
    if "erd/ur5_robot" in jk.robots.erd_names():
        err = assert_flag_advice(capsys, "jacobian", "erd/ur5", match="'erd/ur5_robot'")
        assert "no such" not in err and "'jaxkin robots'" in err
    assert_flag_advice(capsys, "velocities", "mjcf/nosuch", "--n", "3",
                       match="unknown MJCF robot 'mjcf/nosuch'")  # fmt: skip


def test_jacobian_csv_and_text_output_escape_names(capsys, in_tmp):
    """Joint and robot names with commas, quotes and line breaks (legal in a URDF as character
    references) neither break the Jacobian's CSV header nor forge lines of the text output."""
    hostile = (
        TINY_URDF.replace('name="tiny_arm"', 'name="evil&#10;robot  fake 0 joints"')
        .replace('"shoulder"', '"sh,oulder"')
        .replace('"elbow"', '"el&#10;1,2,3&#10;bow"')
        .replace('"slide"', '"sl&quot;ide"')
    )
    (in_tmp / "arm.urdf").write_text(hostile)
    robot = jk.load_urdf(in_tmp / "arm.urdf")
    code, out, _ = run(capsys, "jacobian", "arm.urdf", "--q", "0.1", "0.2", "0.05",
                       "--format", "csv")  # fmt: skip
    assert code == 0
    records = [fields for _, fields in jk.io.csv_records(io.StringIO(out, newline=""))]
    assert records[0] == ["row", *robot.joint_names]
    assert len(records) == 7 and all(len(r) == 1 + robot.dof for r in records)
    code, out, _ = run(capsys, "jacobian", "arm.urdf", "--q", "0.1", "0.2", "0.05")
    assert code == 0
    assert not any(line.startswith("1,2,3") or line.startswith("robot  fake")
                   for line in out.splitlines())  # fmt: skip
    assert repr("el\n1,2,3\nbow") in out
