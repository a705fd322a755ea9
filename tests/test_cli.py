"""The command line: `jaxkin velocities` end to end (in-process), its errors, atomic output.

Compiling the results kernels is most of this file's time: one per (robot, options, dtype, rows
per chunk). Tests that only need some run share one (:func:`niryo_run`), and the others keep to a
few robots and row counts so that a kernel compiled by one test is loaded from the run's
compilation cache by the next (conftest.py). Library results are recomputed by eager calls,
compiled once per robot and options.
"""

import ast
import collections
import contextlib
import io
import os
import pathlib
import subprocess
import sys

import jax
import numpy as np
import pytest

import jaxkin as jk
from jaxkin import cli

KEYS = {"q", "qd", "twist", "J", "Ja", "margin", "sigma"}
META = {
    "robot",
    "joint_names",
    "frame",
    "reference",
    "representation",
    "dtype",
    "seed",
    "qd_scale",
    "singular_tol",
    "jaxkin_version",
}


@pytest.fixture(autouse=True)
def in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def run(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def load(path):
    with np.load(path, allow_pickle=False) as f:
        return {k: f[k] for k in f.files}


def recompute(robot, qs, frame=None, reference="world_aligned", representation="rpy"):
    """J, Ja and margin of a few rows straight from the library, row by row (eager calls: one
    compiled kernel per robot and options, shared by the tests that use them)."""

    def one(q):
        J = jk.geometric_jacobian(robot, q, frame=frame, reference=reference)
        Ja, margin = jk.analytical_jacobian(
            robot, q, representation, frame=frame, return_margin=True
        )
        return np.asarray(J), np.asarray(Ja), np.asarray(margin)

    return [np.stack(parts) for parts in zip(*(one(q) for q in qs), strict=True)]


def assert_usage_error(capsys, *argv, match):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert err.startswith("jaxkin: error: ") and err.count("\n") == 1, err
    assert match in err
    assert "Traceback" not in err and out == ""


NIRYO_N = 2001


@pytest.fixture(scope="module")
def niryo_run(tmp_path_factory):
    """One ``jaxkin velocities`` run of the default robot (niryo_one, float64, seed 3), shared
    by the tests that read it: ``(exit code, stdout, path of its .npz)``. 2,001 rows in chunks
    of at most 512: the checked kernel runs 2 chunks of 500 rows, the one-pass kernel 2 of 501,
    the last one with 3 padding rows."""
    where = tmp_path_factory.mktemp("niryo")
    out, err, before = io.StringIO(), io.StringIO(), os.getcwd()
    os.chdir(where)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = cli.main(["velocities", "--n", str(NIRYO_N), "--chunk-size", "512",
                             "--output", "v.npz", "--seed", "3"])  # fmt: skip
    finally:
        os.chdir(before)
    return code, out.getvalue(), where / "v.npz"


def test_niryo_one_float64(niryo_run):
    n = NIRYO_N  # 4 chunks of 500 or 501 rows, the last one with 3 padding rows
    code, out, path = niryo_run
    assert code == 0
    assert "PASS" in out and "niryo_one" in out and str(path) in out
    d = load(path)
    assert set(d) == KEYS | META
    robot = jk.robots.load("niryo_one", dtype="float64")
    assert d["q"].shape == d["qd"].shape == (n, 6)
    assert d["J"].shape == d["Ja"].shape == (n, 6, 6)
    assert d["twist"].shape == (n, 6) and d["sigma"].shape == (n, 6) and d["margin"].shape == (n,)
    assert all(d[k].dtype == np.float64 for k in KEYS)
    assert str(d["robot"]) == "niryo_one" and str(d["frame"]) == "gripper_link"
    assert list(d["joint_names"]) == list(robot.joint_names)
    assert (str(d["reference"]), str(d["representation"]), str(d["dtype"])) == (
        "world_aligned",
        "rpy",
        "float64",
    )
    assert int(d["seed"]) == 3 and str(d["jaxkin_version"]) == jk.__version__
    assert np.all(d["q"] >= np.asarray(robot.lower)) and np.all(d["q"] <= np.asarray(robot.upper))
    assert np.all(np.abs(d["qd"]) <= 1.0)
    np.testing.assert_allclose(d["twist"], np.einsum("nij,nj->ni", d["J"], d["qd"]), atol=1e-14)
    np.testing.assert_allclose(d["sigma"], np.linalg.svd(d["J"], compute_uv=False), atol=1e-12)
    rows = [0, 500, 501, 1502, 1503, n - 1]  # chunk boundaries and the padded chunk's last row
    J, Ja, margin = recompute(robot, d["q"][rows])
    np.testing.assert_allclose(d["J"][rows], J, atol=1e-14)
    np.testing.assert_allclose(d["Ja"][rows], Ja, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(d["margin"][rows], margin, atol=1e-14)


def test_other_robot_frame_reference_representation(capsys, in_tmp):
    argv = ["velocities", "cylindrical", "--n", "300", "--frame", "link2", "--reference", "local",
            "--representation", "zyz", "--qd-scale", "0.5", "--output", "c.npz"]  # fmt: skip
    code, out, _ = run(capsys, *argv)
    assert code == 0 and "PASS" in out
    d = load(in_tmp / "c.npz")
    robot = jk.robots.load("cylindrical", dtype="float64")
    assert d["J"].shape == (300, 6, 3) and d["sigma"].shape == (300, 3)
    assert (str(d["frame"]), str(d["reference"]), str(d["representation"])) == (
        "link2",
        "local",
        "zyz",
    )
    assert np.all(np.abs(d["qd"]) <= 0.5)
    np.testing.assert_allclose(d["twist"], np.einsum("nij,nj->ni", d["J"], d["qd"]), atol=1e-14)
    rows = [0, 299]
    J, Ja, margin = recompute(robot, d["q"][rows], "link2", "local", "zyz")
    np.testing.assert_allclose(d["J"][rows], J, atol=1e-14)
    np.testing.assert_allclose(d["Ja"][rows], Ja, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(d["margin"][rows], margin, atol=1e-14)


def test_float32(capsys, in_tmp):
    argv = ["velocities", "two_link_planar", "--n", "500", "--dtype", "float32", "--output", "f"]
    code, out, _ = run(capsys, *argv)
    assert code == 0 and "PASS" in out and "float32" in out
    d = load(in_tmp / "f")  # written exactly where asked, no suffix added
    assert all(d[k].dtype == np.float32 for k in KEYS) and str(d["dtype"]) == "float32"
    np.testing.assert_allclose(d["twist"], np.einsum("nij,nj->ni", d["J"], d["qd"]), atol=1e-5)


def test_default_output_name_and_no_output(capsys, in_tmp):
    # 40 rows, as in every two_link_planar run here: one compiled kernel serves them all
    code, out, _ = run(capsys, "velocities", "two_link_planar", "--n", "40", "--no-output")
    assert code == 0 and "none (--no-output)" in out
    assert os.listdir(in_tmp) == []
    code, _, _ = run(capsys, "velocities", "two_link_planar", "--n", "40")
    assert code == 0
    assert os.listdir(in_tmp) == ["velocities_two_link_planar_40.npz"]
    assert load(in_tmp / "velocities_two_link_planar_40.npz")["sigma"].shape == (40, 2)


def test_a_repeated_run_reuses_its_kernel(capsys, monkeypatch):
    """The results kernel is made once per robot, options and process, and chunked_map keeps its
    program: a second identical run (tests, a notebook calling cli.main) traces nothing."""
    made, traces = [], []
    real = cli.velocity_results

    def counted(*args, **kwargs):
        made.append(kwargs.get("check", False))
        fn = real(*args, **kwargs)

        def results(q, qd):
            traces.append(1)
            return fn(q, qd)

        return results

    monkeypatch.setattr(cli, "velocity_results", counted)
    argv = ("velocities", "two_link_planar", "--n", "40", "--no-output")
    assert run(capsys, *argv)[0] == 0
    assert made == [True] and len(traces) == 1  # 40 rows: all checked, one kernel
    assert run(capsys, *argv)[0] == 0
    assert made == [True] and len(traces) == 1


def test_float64_turns_x64_on_for_the_run_only(capsys):
    jax.config.update("jax_enable_x64", False)  # conftest turns it back on after the test
    code, out, _ = run(capsys, "velocities", "two_link_planar", "--n", "40", "--no-output")
    assert code == 0 and "float64" in out and "PASS (tol 1e-10)" in out
    assert not jax.config.read("jax_enable_x64")


def test_check_failure_exits_1(capsys, monkeypatch, in_tmp):
    kernel = cli.velocity_results

    def broken(*args, **kwargs):
        fn = kernel(*args, **kwargs)
        if not kwargs.get("check"):
            return fn
        return lambda q, qd: {**fn(q, qd), "jac_err": fn(q, qd)["jac_err"] + 1.0}

    monkeypatch.setattr(cli, "velocity_results", broken)
    code, out, err = run(capsys, "velocities", "two_link_planar", "--n", "20", "--no-output")
    assert code == 1 and "FAIL" in out and "disagree" in err


def test_robots_and_help(capsys):
    code, out, _ = run(capsys, "robots", "--zoo")
    assert code == 0
    assert [line.split()[0] for line in out.splitlines()] == jk.robots.names()
    code, out, _ = run(capsys, "robots")
    assert code == 0
    zoo, _, rest = out.partition("\n\n")
    assert [line.split()[0] for line in zoo.splitlines()] == jk.robots.names()
    erd, mjcf = jk.robots.erd_names(), jk.robots.mjcf_names()
    named = [line for line in rest.splitlines() if line and not line.startswith("#")]
    assert named == erd + mjcf
    assert "URDF file" in rest
    code, out, _ = run(capsys, "velocities", "--help")
    assert code == 0 and "--singular-tol" in out and "sigma_min / sigma_max" in out
    assert "-pi/pi rad" in out and "-1/1 m" in out
    flat = " ".join(out.split())  # argparse wraps help lines
    for word in ("--configurations", "qd_<joint>", "--format csv", "URDF file path", "--tip"):
        assert word in flat, word
    code, out, _ = run(capsys, "jacobian", "--help")
    assert code == 0
    flat = " ".join(out.split())
    for word in ("--q", "--config", "--reference", "world_aligned", "[v; omega]", "--analytical",
                 "Rz(yaw) Ry(pitch) Rx(roll)", "per rad/s", "examples:"):  # fmt: skip
        assert word in flat, word
    code, out, _ = run(capsys, "--help")
    assert code == 0 and "velocities" in out and "robots" in out and "jacobian" in out


# ---------------------------------------------------------------------- usage errors
def test_unknown_robot(capsys):
    assert_usage_error(capsys, "velocities", "nosuchbot", match="unknown robot 'nosuchbot'")
    assert_usage_error(capsys, "jacobian", "nosuchbot", match="unknown robot 'nosuchbot'")
    assert_usage_error(capsys, "velocities", "missing.urdf", "--n", "3", match="missing.urdf")


@pytest.mark.parametrize("bad", ["0", "-5", "abc", "1.5", "1e-3", "inf", ""])
def test_bad_n(capsys, bad):
    assert_usage_error(capsys, "velocities", "--n", bad, match="argument --n")


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--dtype", "float16"], "argument --dtype: invalid choice"),
        (["--chunk-size", "0"], "argument --chunk-size"),
        (["--qd-scale", "nan"], "argument --qd-scale"),
        (["--singular-tol", "0"], "argument --singular-tol"),
        (["--reference", "global"], "argument --reference"),
        (["--frame", "nosuchframe"], "no frame 'nosuchframe'"),
        (["--output", "x.npz", "--no-output"], "not allowed with"),
        (["--bogus"], "unrecognized arguments"),
    ],
)
def test_bad_options(capsys, argv, match):
    assert_usage_error(capsys, "velocities", "--n", "10", *argv, match=match)


def test_n_spellings():
    parser = cli.build_parser()
    for text in ("1000000", "1_000_000", "1e6"):
        assert parser.parse_args(["velocities", "--n", text]).n == 1_000_000


def test_no_command(capsys):
    assert_usage_error(capsys, match="choose a command")


def test_unwritable_output(capsys, in_tmp):
    assert_usage_error(capsys, "velocities", "--n", "10", "--output", "missing/dir/v.npz",
                       match="does not exist")  # fmt: skip
    os.mkdir(in_tmp / "adir")
    assert_usage_error(capsys, "velocities", "--n", "10", "--output", "adir",
                       match="is a directory")  # fmt: skip
    assert os.listdir(in_tmp) == ["adir"] and os.listdir(in_tmp / "adir") == []


# ---------------------------------------------------------------------- atomic output
def test_exception_during_computation_leaves_nothing(capsys, monkeypatch, in_tmp):
    seen = []

    def boom(*args, **kwargs):
        seen.extend(os.listdir(in_tmp))  # the temporary file exists while computing
        raise RuntimeError("simulated failure")

    monkeypatch.setattr(cli, "chunked_map", boom)
    with pytest.raises(RuntimeError, match="simulated"):
        cli.main(["velocities", "--n", "10", "--output", "v.npz"])
    assert len(seen) == 1 and seen[0].startswith(".v.npz.") and seen[0].endswith(".tmp")
    assert os.listdir(in_tmp) == []


def test_interrupt_leaves_nothing(capsys, monkeypatch, in_tmp):
    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "chunked_map", interrupt)
    code, _, err = run(capsys, "velocities", "--n", "10")
    assert code == 130 and "interrupted" in err
    assert os.listdir(in_tmp) == []


def test_failed_write_keeps_the_old_file(capsys, monkeypatch, in_tmp):
    (in_tmp / "v.npz").write_bytes(b"previous result")

    def half_written(self, arrays):  # the disk fills up in the middle of the results
        self.f.write(b"PK partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(jk.io._NpzFile, "append", half_written)
    assert_usage_error(capsys, "velocities", "two_link_planar", "--n", "40", "--output", "v.npz",
                       match="No space left on device")  # fmt: skip
    assert os.listdir(in_tmp) == ["v.npz"]
    assert (in_tmp / "v.npz").read_bytes() == b"previous result"


# ---------------------------------------------------------------------- what the module holds
def test_cli_holds_no_kernel_sampler_or_reader():
    """The command line parses, prints and turns library errors into one-line exits: the
    per-configuration kernel is jaxkin.velocity's, block sampling jaxkin.sampling's and the
    configuration readers jaxkin.io's (issue 22, item 3)."""
    tree = ast.parse(pathlib.Path(cli.__file__).read_text(encoding="utf-8"))
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not imported & {"jax.numpy", "zipfile", "zlib", "io"}, imported
    calls = {ast.unparse(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    library = ("jnp.", "jax.jit", "jax.vmap", "jax.random.", "np.load", "jk.jacobians.")
    assert not sorted(c for c in calls if c.startswith(library))
    assert cli.velocity_results is jk.velocity.velocity_results
    assert cli.sample_rows is jk.sampling.sample_rows
    assert cli.read_configurations is jk.io.read_configurations


# ---------------------------------------------------------------------- as a program
def test_python_dash_m(in_tmp):
    proc = subprocess.run(
        [sys.executable, "-m", "jaxkin", "velocities", "--n", "500", "--no-output"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "PASS" in proc.stdout and "niryo_one" in proc.stdout
    assert os.listdir(in_tmp) == []


# ---------------------------------------------------------------------- jaxkin jacobian
NIRYO_Q = ["0.2", "-0.5", "0.3", "0.1", "-0.4", "0.6"]


def parse_csv_jacobian(out):
    lines = out.strip().splitlines()
    header = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:]]
    return header, [r[0] for r in rows], np.array([[float(x) for x in r[1:]] for r in rows])


@pytest.mark.parametrize("reference", ["world_aligned", "local", "world"])
def test_jacobian_csv_is_the_library_jacobian(capsys, reference):
    code, out, _ = run(capsys, "jacobian", "niryo_one", "--q", *NIRYO_Q, "--reference", reference,
                       "--format", "csv")  # fmt: skip
    assert code == 0
    header, rows, J = parse_csv_jacobian(out)
    robot = jk.robots.load("niryo_one", dtype="float64")
    assert header == ["row", *robot.joint_names]
    assert rows == ["vx", "vy", "vz", "wx", "wy", "wz"]
    q = np.array([float(x) for x in NIRYO_Q])
    expected = np.asarray(jk.geometric_jacobian(robot, q, reference=reference))
    np.testing.assert_array_equal(J, expected)  # repr() round-trips float64 exactly


def test_jacobian_text_states_frame_reference_rows_and_units(capsys):
    code, out, _ = run(capsys, "jacobian", "niryo_one", "--q", "0.2,-0.5,0.3", "0.1", "-0.4,0.6")
    assert code == 0
    for words in (
        "frame gripper_link (the tip)",
        "reference world_aligned",
        "[v; omega] = J @ qd",
        "world axes",
        "rows   vx vy vz wx wy wz",
        "joint_1=0.2 rad",
        "per rad/s",
    ):
        assert words in out, words
    table = [line.split() for line in out.splitlines() if line.startswith(("v", "w"))]
    labels = [" ".join(t[:2]) for t in table]
    assert labels == ["vx [m/s]", "vy [m/s]", "vz [m/s]", "wx [rad/s]", "wy [rad/s]", "wz [rad/s]"]
    robot = jk.robots.load("niryo_one", dtype="float64")
    J = np.asarray(jk.geometric_jacobian(robot, np.array([float(x) for x in NIRYO_Q])))
    np.testing.assert_allclose([[float(x) for x in t[2:]] for t in table], J, atol=5e-5)
    assert "-0.0000" not in out


def test_jacobian_named_configuration_point_frame_analytical_json(capsys):
    import json

    robot = jk.robots.load("puma560", dtype="float64")
    q = robot.configurations["qn"]
    code, out, _ = run(capsys, "jacobian", "puma560", "--config", "qn", "--frame", "link5",
                       "--point", "0", "0", "0.1", "--format", "json")  # fmt: skip
    assert code == 0
    d = json.loads(out)
    assert (d["frame"], d["kind"], d["reference"], d["point"]) == (
        "link5",
        "geometric",
        "world_aligned",
        [0, 0, 0.1],
    )
    expected = jk.geometric_jacobian(robot, q, frame="link5", point=[0, 0, 0.1])
    np.testing.assert_array_equal(np.array(d["J"]), np.asarray(expected))
    assert d["columns"] == list(robot.joint_names) and d["q"] == q.tolist()
    code, out, _ = run(capsys, "jacobian", "cylindrical", "--q", "0.3", "0.4", "0.5",
                       "--analytical", "rpy")  # fmt: skip
    assert code == 0 and "rows   x y z roll pitch yaw" in out and "d[p; phi]/dq" in out
    code, out, _ = run(capsys, "jacobian", "two_link_planar")  # default: q = 0
    assert code == 0 and "joint1=0 rad, joint2=0 rad" in out


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["niryo_one", "--q", "1", "2"], "has 6 joints (joint_1, joint_2"),
        (["niryo_one", "--q", "1", "2", "x", "4", "5", "6"], "'x' is not a number"),
        (["niryo_one", "--q", "1", "2", "3", "4", "5", "nan"], "finite"),
        (["niryo_one", "--config", "nosuch"], "no configuration 'nosuch'"),
        (["niryo_one", "--q", "0", "--config", "zero"], "not allowed with"),
        (["niryo_one", "--frame", "nosuch"], "no frame 'nosuch'"),
        (["niryo_one", "--tip", "hand_link"], "--tip and --base apply to URDF robots"),
        (
            ["niryo_one", "--q", "0", "0", "0", "0", str(np.pi / 2), "0", "--analytical", "rpy"],
            "representation is singular",
        ),
        (["niryo_one", "--reference", "global"], "argument --reference"),
        (["nosuch.urdf"], "no such URDF file: nosuch.urdf"),
    ],
)
def test_jacobian_usage_errors(capsys, argv, match):
    assert_usage_error(capsys, "jacobian", *argv, match=match)


def test_jacobian_notes_a_frame_no_joint_moves(capsys):
    code, out, _ = run(capsys, "jacobian", "niryo_one", "--frame", "base_link")
    assert code == 0 and "note: no joint moves frame 'base_link'" in out


# ---------------------------------------------------------------------- configuration files
def twist_of(robot, q, qd):
    """The library's twists, row by row (eager calls: one compiled kernel per robot)."""
    return np.stack([np.asarray(jk.twist(robot, a, b)) for a, b in zip(q, qd, strict=True)])


def test_velocities_configurations_csv_with_header_and_qd(capsys, in_tmp):
    robot = jk.robots.load("two_link_planar", dtype="float64")
    (in_tmp / "c.csv").write_text(
        "# two configurations\nqd_joint2,joint2,q_joint1,qd_joint1\n0.5,0.2,0.1,-1\n\n"
        "0,-3.5,3.0,2\n"
    )
    code, out, _ = run(capsys, "velocities", "two_link_planar", "--configurations", "c.csv",
                       "--output", "v.npz")  # fmt: skip
    assert code == 0 and "2 from c.csv (qd from the file; 1 outside the joint limits)" in out
    d = load(in_tmp / "v.npz")
    np.testing.assert_array_equal(d["q"], [[0.1, 0.2], [3.0, -3.5]])
    np.testing.assert_array_equal(d["qd"], [[-1.0, 0.5], [2.0, 0.0]])
    np.testing.assert_allclose(d["twist"], twist_of(robot, d["q"], d["qd"]), atol=1e-15)


def test_velocities_configurations_plain_csv_and_npz(capsys, in_tmp):
    robot = jk.robots.load("niryo_one", dtype="float64")
    # 500 rows: niryo_run's checked kernel (chunks of 500 rows) serves them
    q = np.random.default_rng(1).uniform(robot.lower, robot.upper, size=(500, 6))
    np.savetxt(in_tmp / "q.csv", q, delimiter=",")  # no header, q only: qd is sampled
    code, out, _ = run(capsys, "velocities", "--configurations", "q.csv", "--seed", "4",
                       "--output", "a.npz")  # fmt: skip
    assert code == 0 and "500 from q.csv (qd uniform in [-1, 1]" in out and "seed 4" in out
    a = load(in_tmp / "a.npz")
    np.testing.assert_array_equal(a["q"], q)
    qd_expected = jk.sampling.sample_rows(robot, 500, 4, 1.0, np.float64)[1][0:500]
    np.testing.assert_array_equal(a["qd"], qd_expected)
    qd = -q
    np.savez(in_tmp / "qqd.npz", q=q, qd=qd)
    code, _, _ = run(capsys, "velocities", "--configurations", "qqd.npz", "--output", "b.npz")
    assert code == 0
    b = load(in_tmp / "b.npz")
    np.testing.assert_array_equal(b["qd"], qd)
    np.testing.assert_allclose(b["twist"], twist_of(robot, q, qd), atol=1e-15)
    np.savez(in_tmp / "one.npz", q=np.array([0.3, -0.2]))  # a single configuration (dof,)
    code, out, _ = run(capsys, "velocities", "two_link_planar", "--configurations", "one.npz",
                       "--no-output")  # fmt: skip
    assert code == 0 and "1 from one.npz" in out


@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        ("a.csv", "0.1,0.2,0.3\n", "line 1: 3 values; robot 'two_link_planar' has 2 joints"),
        ("b.csv", "0.1,0.2\n0.1,0.2,0.3,0.4\n", "rows mix 2 and 4 values"),
        ("c.csv", "joint1,elbow\n0,0\n", "unknown column 'elbow'"),
        ("d.csv", "joint1\n0\n", "no column for joint(s) ['joint2']"),
        ("e.csv", "joint1,joint2,qd_joint1\n0,0,1\n", "qd_<joint> for every joint"),
        ("f.csv", "0.1,0.2\n0.1,abc\n", "line 2: not a row of numbers"),
        ("g.csv", "0.1,inf\n", "q of configuration 0 is not finite"),
        ("h.csv", "# only a comment\n", "holds no configurations"),
        ("i.csv", "joint1,joint2\n1,2,3\n", "line 2: 3 values, the header has 2"),
        ("j.npz", "not a zip", "is not an .npz file"),
    ],
)
def test_bad_configuration_files(capsys, in_tmp, name, content, match):
    (in_tmp / name).write_text(content)
    assert_usage_error(capsys, "velocities", "two_link_planar", "--configurations", name,
                       "--no-output", match=match)  # fmt: skip


def test_bad_configuration_npz_arrays(capsys, in_tmp):
    cases = [
        ({"x": np.zeros(2)}, "has no array 'q' (it has ['x'])"),
        ({"q": np.zeros((3, 5))}, "q has shape (3, 5); robot 'two_link_planar' has 2 joints"),
        ({"q": np.zeros((3, 2)), "qd": np.zeros((2, 2))}, "qd has shape (2, 2) but q has (3, 2)"),
        ({"q": np.array([["a", "b"]])}, "q must hold numbers"),
    ]
    for k, (arrays, match) in enumerate(cases):
        np.savez(in_tmp / f"{k}.npz", **arrays)
        assert_usage_error(capsys, "velocities", "two_link_planar", "--configurations",
                           f"{k}.npz", "--no-output", match=match)  # fmt: skip
    assert_usage_error(capsys, "velocities", "--configurations", "none.csv", match="does not exist")
    os.mkdir(in_tmp / "d.csv")
    assert_usage_error(capsys, "velocities", "--configurations", "d.csv", match="is not a file")
    assert_usage_error(capsys, "velocities", "--configurations", "x.csv", "--n", "5",
                       match="not allowed with argument")  # fmt: skip


def test_velocities_csv_output_matches_npz(capsys, in_tmp):
    argv = ["velocities", "two_link_planar", "--n", "40", "--seed", "2"]
    assert run(capsys, *argv, "--output", "v.npz")[0] == 0
    code, out, _ = run(capsys, *argv, "--format", "csv")
    assert code == 0 and "velocities_two_link_planar_40.csv" in out
    assert run(capsys, *argv, "--output", "w.csv")[0] == 0  # format from the suffix
    d = load(in_tmp / "v.npz")
    for name in ("velocities_two_link_planar_40.csv", "w.csv"):
        text = (in_tmp / name).read_text()
        assert "# jaxkin velocities: robot = two_link_planar" in text
        lines = [line for line in text.splitlines() if not line.startswith("#")]
        header = lines[0].split(",")
        assert header == ["q_joint1", "q_joint2", "qd_joint1", "qd_joint2", "vx", "vy", "vz",
                          "wx", "wy", "wz", "sigma_1", "sigma_2", "margin"]  # fmt: skip
        table = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
        expected = np.concatenate(
            [d["q"], d["qd"], d["twist"], d["sigma"], d["margin"][:, None]], axis=1
        )
        np.testing.assert_array_equal(table, expected)  # %.17g round-trips float64


# ---------------------------------------------------------------------- URDF robots
TINY_URDF = """<?xml version="1.0"?>
<robot name="tiny_arm">
  <link name="base"/><link name="upper"/><link name="fore"/><link name="hand"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0.3 0 0" rpy="0.2 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/>
  </joint>
  <joint name="slide" type="prismatic">
    <parent link="fore"/><child link="hand"/>
    <origin xyz="0.2 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.1" effort="1" velocity="1"/>
  </joint>
</robot>
"""


def test_urdf_file_jacobian_and_velocities(capsys, in_tmp):
    (in_tmp / "arm.urdf").write_text(TINY_URDF)
    robot = jk.load_urdf(in_tmp / "arm.urdf", dtype="float64")
    code, out, _ = run(capsys, "jacobian", "arm.urdf", "--q", "0.1", "0.2", "0.05", "--format",
                       "csv")  # fmt: skip
    assert code == 0
    header, _, J = parse_csv_jacobian(out)
    assert header == ["row", "shoulder", "elbow", "slide"]
    q = np.array([0.1, 0.2, 0.05])
    np.testing.assert_array_equal(J, np.asarray(jk.geometric_jacobian(robot, q)))
    code, out, _ = run(capsys, "velocities", str(in_tmp / "arm.urdf"), "--n", "30")
    assert code == 0 and "tiny_arm (3 dof: shoulder, elbow, slide)" in out and "PASS" in out
    d = load(in_tmp / "velocities_arm_30.npz")
    np.testing.assert_allclose(d["twist"], twist_of(robot, d["q"], d["qd"]), atol=1e-15)
    code, out, _ = run(capsys, "jacobian", "arm.urdf", "--tip", "fore", "--q", "0", "0")
    assert code == 0 and "frame fore (the tip)" in out


def test_bad_urdf_files_are_one_line_errors(capsys, in_tmp):
    (in_tmp / "broken.urdf").write_text("<robot")
    assert_usage_error(capsys, "jacobian", "broken.urdf", match="broken.urdf")
    (in_tmp / "arm.urdf").write_text(TINY_URDF)
    assert_usage_error(capsys, "jacobian", "arm.urdf", "--tip", "nolink", match="nolink")
    os.mkdir(in_tmp / "dir.urdf")
    assert_usage_error(capsys, "velocities", "dir.urdf", "--n", "3", match="is not a file")


# ---------------------------------------------------------------------- renovation: streaming,
# one pass, library sampler, files and limits
HANGING_URDF = """<?xml version="1.0"?>
<robot name="hanging">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="sensor"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-1.79e308" upper="1.79e308" effort="1" velocity="1"/>
  </joint>
  <joint name="j2" type="continuous"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
  </joint>
  <joint name="mount" type="fixed"><parent link="base"/><child link="sensor"/>
    <origin xyz="0 0 0.5"/>
  </joint>
</robot>
"""


def test_library_sampler_block_by_block(niryo_run):
    robot = jk.robots.load("niryo_one", dtype="float64")
    block = jk.sampling.SAMPLE_BLOCK
    q, qd = jk.sampling.sample_rows(robot, block + 10, 3, 0.5, np.float64)
    key_q = jax.random.split(jax.random.key(3))[0]
    second = jk.sample_configurations(robot, block, jax.random.fold_in(key_q, 1))
    np.testing.assert_array_equal(q[block - 2 : block + 10][2:], second[:10])
    np.testing.assert_array_equal(q.tail(3)[0:4], q[3:7])
    assert np.all(np.abs(qd[0:100]) <= 0.5)
    # a row depends on the seed and its index only, not on n or the chunk size (the shared run:
    # seed 3, n = 2,001, chunks of 512; here n = block + 10)
    code, _, path = niryo_run
    assert code == 0
    np.testing.assert_array_equal(load(path)["q"], q[0:NIRYO_N])


def test_one_forward_pass_and_bounded_check(capsys, monkeypatch, in_tmp):
    """What is counted is the kernel's passes and which rows are checked, whatever the robot: a
    small one (three joints), world reference and zyz angles (not the defaults)."""
    calls = {"pass": 0, "fwd": 0}
    real_pass, real_fwd = jk.velocity.jacobian_pass, jk.velocity.jacobian_fwd

    def counted_pass(*args, **kwargs):
        calls["pass"] += 1
        return real_pass(*args, **kwargs)

    def counted_fwd(*args, **kwargs):
        calls["fwd"] += 1
        return real_fwd(*args, **kwargs)

    monkeypatch.setattr(jk.velocity, "jacobian_pass", counted_pass)
    monkeypatch.setattr(jk.velocity, "jacobian_fwd", counted_fwd)
    robot = jk.robots.load("cylindrical", dtype="float64")
    fn = jk.velocity.velocity_results(robot, None, "world", "zyz")
    jax.make_jaxpr(fn)(np.zeros(3), np.zeros(3))
    assert calls == {"pass": 1, "fwd": 0}  # J, the twist and Ja from one forward pass
    code, out, _ = run(capsys, "velocities", "cylindrical", "--n", "1500", "--reference", "world",
                       "--representation", "zyz", "--output", "w.npz")  # fmt: skip
    assert code == 0 and "over the first 1,000 configurations  PASS" in out
    d = load(in_tmp / "w.npz")
    rows = [0, 999, 1000, 1499]  # checked and unchecked rows alike
    J, Ja, margin = recompute(robot, d["q"][rows], None, "world", "zyz")
    np.testing.assert_allclose(d["J"][rows], J, atol=1e-13)
    np.testing.assert_allclose(d["Ja"][rows], Ja, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(d["margin"][rows], margin, atol=1e-14)


def test_unbounded_limits_sampled_finite_and_frame_checks(capsys, in_tmp):
    (in_tmp / "hang.urdf").write_text(HANGING_URDF)
    code, out, _ = run(capsys, "velocities", "hang.urdf", "--n", "50", "--frame", "l2")
    assert code == 0 and "frame            l2," in out
    d = load(in_tmp / "velocities_hang_50.npz")
    assert np.all(np.isfinite(d["q"])) and np.all(np.abs(d["q"]) <= np.pi)  # not +-1.79e308
    # a fixed leaf off the root: no joint moves it, whichever way it was chosen
    assert_usage_error(
        capsys,
        "velocities",
        "hang.urdf",
        "--n",
        "50",
        "--frame",
        "sensor",
        "--output",
        "s.npz",
        match="frame 'sensor' of robot 'hanging' is not moved",
    )
    assert not (in_tmp / "s.npz").exists() and not any(p.startswith(".") for p in os.listdir())
    code, out, err = run(capsys, "velocities", "hang.urdf", "--n", "50", "--output", "x.npz")
    frame = jk.load_urdf(in_tmp / "hang.urdf").frame_names[-1]
    if code == 0:  # the default frame is moved by some joint and named in the summary
        assert str(load(in_tmp / "x.npz")["frame"]) in out and np.any(load(in_tmp / "x.npz")["J"])
    else:
        assert code == 2 and "is not moved by any joint" in err and err.count("\n") == 1
    assert frame in jk.load_urdf(in_tmp / "hang.urdf").frame_names


def test_non_finite_results_fail(capsys, monkeypatch, in_tmp):
    kernel = cli.velocity_results

    def overflowing(*args, **kwargs):
        fn = kernel(*args, **kwargs)
        return lambda q, qd: {**fn(q, qd), "twist": fn(q, qd)["twist"] * np.inf}

    monkeypatch.setattr(cli, "velocity_results", overflowing)
    code, out, err = run(capsys, "velocities", "two_link_planar", "--n", "1100", "--output",
                         "v.npz")  # fmt: skip
    assert code == 1 and "1,100 configuration(s) gave non-finite results" in err
    assert "(first: configuration 0, twist)" in err
    assert "not written" in out and os.listdir(in_tmp) == []


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["velocities", "--n", "1e9"], "argument --n: expected an integer from 1 to 100,000,000"),
        (["velocities", "--n", "10", "--chunk-size", "1e12"], "argument --chunk-size"),
        (["velocities", "--n", "10", "--seed", "1e30"], "argument --seed"),
        (["jacobian", "niryo_one", "--digits", "1e8"], "argument --digits"),
        (
            ["jacobian", "niryo_one", "--point", "nan", "0", "0"],
            "argument --point: expected a finite",
        ),
        (["jacobian", "niryo_one", "--q", "nan", "0", "0", "0", "0", "0"], "--q must be finite"),
        (["velocities", "--n", "10", "--format", "csv", "--output", "x.npz"], "contradicts"),
        (["velocities", "--n", "10", "--format", "npz", "--output", "-"], "csv only"),
    ],
)
def test_absurd_sizes_and_contradictions(capsys, argv, match):
    assert_usage_error(capsys, *argv, match=match)


def test_output_that_cannot_fit_the_disk(capsys, monkeypatch, in_tmp):
    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(jk.io.shutil, "disk_usage", lambda path: usage(10**6, 0, 1000))
    assert_usage_error(capsys, "velocities", "--n", "100", "--output", "v.npz",
                       match="has 1.0 kB free")  # fmt: skip
    assert os.listdir(in_tmp) == []


def test_help_states_limits_and_dash(capsys):
    code, out, _ = run(capsys, "velocities", "--help")
    flat = " ".join(out.split())
    assert code == 0
    for words in ("at most 100,000,000", "- for standard input", "- for standard output",
                  "fold_in", "first 1,000 configurations", "byte order mark"):  # fmt: skip
        assert words in flat, words


def test_csv_from_excel_r_stdin_and_duplicates(capsys, monkeypatch, in_tmp):
    (in_tmp / "excel.csv").write_bytes(b"\xef\xbb\xbfjoint1,joint2\r\n0.1,0.2\r\n0.3,0.4\r\n")
    (in_tmp / "r.csv").write_text('"","joint1","joint2","qd_joint1","qd_joint2"\n'
                                  '"1",0.1,0.2,1,2\n"2",0.3,0.4,3,4\n')  # fmt: skip
    for name in ("excel.csv", "r.csv"):
        code, out, _ = run(capsys, "velocities", "two_link_planar", "--configurations", name,
                           "--output", f"{name}.npz")  # fmt: skip
        assert code == 0, out
        np.testing.assert_array_equal(load(in_tmp / f"{name}.npz")["q"], [[0.1, 0.2], [0.3, 0.4]])
    np.testing.assert_array_equal(load(in_tmp / "r.csv.npz")["qd"], [[1, 2], [3, 4]])
    (in_tmp / "dup.csv").write_text("joint1,joint2,q_joint1\n0,0,0\n")
    assert_usage_error(capsys, "velocities", "two_link_planar", "--configurations", "dup.csv",
                       match="column 'q_joint1' duplicates column 'joint1'")  # fmt: skip
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(b"0.5,0.25\n")))
    code, out, err = run(capsys, "velocities", "two_link_planar", "--configurations", "-",
                         "--output", "-")  # fmt: skip
    assert code == 0 and "1 from standard input" in err and "output           standard" in err
    lines = [line for line in out.splitlines() if not line.startswith("#")]
    assert lines[0].startswith("q_joint1,q_joint2,qd_joint1") and lines[1].startswith("0.5,0.25,")


def test_streams_results_to_disk(capsys, monkeypatch, in_tmp):
    """Results go to the file chunk by chunk: no chunk handed to the writer exceeds the chunk
    size, and chunked_map never returns the whole results."""
    sizes, real = [], jk.io.ResultWriter.append

    def spy(self, rows):
        sizes.append(len(rows["q"]))
        return real(self, rows)

    monkeypatch.setattr(jk.io.ResultWriter, "append", spy)
    code, _, _ = run(capsys, "velocities", "two_link_planar", "--n", "5000", "--chunk-size",
                     "512", "--output", "s.csv")  # fmt: skip
    assert code == 0 and sum(sizes) == 5000 and max(sizes) <= 1000
    assert len(load_csv_rows(in_tmp / "s.csv")) == 5000


def load_csv_rows(path):
    return [line for line in path.read_text().splitlines() if not line.startswith("#")][1:]


def test_jacobian_of_a_branching_urdf_with_an_explicit_frame(capsys, in_tmp):
    # arm + two fingers: no default frame, but --frame names one; the CLI must not ask for
    # the default just to label the output
    from test_default_frame import FINGERS

    (in_tmp / "fingers.urdf").write_text(FINGERS)
    code, out, _ = run(capsys, "jacobian", "fingers.urdf", "--frame", "finger_l", "--q", *["0"] * 5)
    assert code == 0, out
    assert "finger_l" in out and "(the tip)" not in out
    code, _, err = run(capsys, "jacobian", "fingers.urdf", "--q", *["0"] * 5)
    assert code == 2 and "finger_l" in err and "finger_r" in err
