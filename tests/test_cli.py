"""The command line: `jaxkin velocities` end to end (in-process), its errors, atomic output."""

import os
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
    """J, Ja and margin of a few rows straight from the library (one jitted vmap: eager calls
    would compile op by op, which is slower)."""

    def one(q):
        J = jk.geometric_jacobian(robot, q, frame=frame, reference=reference)
        Ja, margin = jk.analytical_jacobian(
            robot, q, representation, frame=frame, return_margin=True
        )
        return J, Ja, margin

    return jax.jit(jax.vmap(one))(qs)


def assert_usage_error(capsys, *argv, match):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert err.startswith("jaxkin: error: ") and err.count("\n") == 1, err
    assert match in err
    assert "Traceback" not in err and out == ""


def test_niryo_one_float64(capsys, in_tmp):
    n = 2001  # 4 chunks of 501 rows, the last one with 3 padding rows
    code, out, _ = run(capsys, "velocities", "--n", str(n), "--chunk-size", "512", "--output",
                       "v.npz", "--seed", "3")  # fmt: skip
    assert code == 0
    assert "PASS" in out and "niryo_one" in out and str(in_tmp / "v.npz") in out
    d = load(in_tmp / "v.npz")
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
    code, out, _ = run(capsys, "velocities", "two_link_planar", "--n", "50", "--no-output")
    assert code == 0 and "none (--no-output)" in out
    assert os.listdir(in_tmp) == []
    code, _, _ = run(capsys, "velocities", "two_link_planar", "--n", "50")
    assert code == 0
    assert os.listdir(in_tmp) == ["velocities_two_link_planar_50.npz"]
    assert load(in_tmp / "velocities_two_link_planar_50.npz")["sigma"].shape == (50, 2)


def test_float64_turns_x64_on_for_the_run_only(capsys):
    jax.config.update("jax_enable_x64", False)  # conftest turns it back on after the test
    code, out, _ = run(capsys, "velocities", "two_link_planar", "--n", "20", "--no-output")
    assert code == 0 and "float64" in out and "PASS (tol 1e-10)" in out
    assert not jax.config.read("jax_enable_x64")


def test_check_failure_exits_1(capsys, monkeypatch, in_tmp):
    kernel = cli.velocity_kernel

    def broken(*args):
        fn = kernel(*args)
        return lambda q, qd: {**fn(q, qd), "jac_err": fn(q, qd)["jac_err"] + 1.0}

    monkeypatch.setattr(cli, "velocity_kernel", broken)
    code, out, err = run(capsys, "velocities", "two_link_planar", "--n", "20", "--no-output")
    assert code == 1 and "FAIL" in out and "disagree" in err


def test_robots_and_help(capsys):
    code, out, _ = run(capsys, "robots")
    assert code == 0
    assert [line.split()[0] for line in out.splitlines()] == jk.robots.names()
    code, out, _ = run(capsys, "velocities", "--help")
    assert code == 0 and "--singular-tol" in out and "sigma_min / sigma_max" in out
    assert "-pi/pi rad" in out and "-1/1 m" in out
    code, out, _ = run(capsys, "--help")
    assert code == 0 and "velocities" in out and "robots" in out


# ---------------------------------------------------------------------- usage errors
def test_unknown_robot(capsys):
    assert_usage_error(capsys, "velocities", "nosuchbot", match="unknown robot 'nosuchbot'")


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

    def half_written(f, **arrays):
        f.write(b"PK partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", half_written)
    assert_usage_error(capsys, "velocities", "two_link_planar", "--n", "10", "--output", "v.npz",
                       match="No space left on device")  # fmt: skip
    assert os.listdir(in_tmp) == ["v.npz"]
    assert (in_tmp / "v.npz").read_bytes() == b"previous result"


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
