"""The benchmark's Pinocchio side and its report (bench/peers.py, bench/jacobian_report.py,
bench/jacobians.py): the jaxkin <-> Pinocchio layout, the free-flyer loops and the humanoid
tables. Oracles: Pinocchio's own kinematics (quaternion order, Jacobian columns) and hand-made
results; one small eager Jacobian (Solo12), no benchmark is run."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _sampling import random_q

import jaxkin as jk
from bench import jacobian_report as R
from bench import peers as P
from bench.jacobians import CHECK_TOL, check

pin = pytest.importorskip("pinocchio")


def solo12():
    text = P.erd_urdf("erd/solo12")
    src = P.RobotSource("solo12", text, "FL_FOOT", "test", floating_base=True)
    robot, _ = P.jaxkin_robot(src, np.float64)
    return src, robot, pin.buildModelFromXML(text, pin.JointModelFreeFlyer())


def test_layout_puts_the_quaternion_in_pinocchio_order_and_maps_columns():
    _, robot, model = solo12()
    layout = P.PinocchioLayout(robot, model)
    q = random_q(robot, 1)[0]  # numpy; the free flyer's quaternion (w, x, y, z) is unit
    data = model.createData()
    pin.forwardKinematics(model, data, layout.q(q))
    w, x, y, z = q[3:7]
    R_base = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    np.testing.assert_allclose(data.oMi[1].rotation, R_base, atol=1e-12)
    np.testing.assert_allclose(data.oMi[1].translation, q[:3], atol=1e-12)
    J = np.asarray(jk.geometric_jacobian(robot, q, frame="FL_FOOT"))
    pin.computeJointJacobians(model, data, layout.q(q))
    pin.updateFramePlacements(model, data)
    fid = model.getFrameId("FL_FOOT")
    Jp = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(layout.columns_to_jaxkin(Jp), J, rtol=0, atol=1e-12)
    np.testing.assert_allclose(layout.columns_to_pinocchio(J), Jp, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(layout.v(np.arange(robot.nv)), layout.v_src)


def test_layout_handles_ball_and_planar_joints_and_refuses_unknown_names():
    robot = jk.Robot.from_joints(
        [
            dict(name="b", type="ball", child="l"),
            dict(name="p", type="planar", parent="l", child="m"),
            dict(name="r", type="revolute", parent="m", child="n", axis=(0, 0, 1)),
        ]
    )
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "b")
    j = model.addJoint(j, pin.JointModelPlanar(), pin.SE3.Identity(), "p")
    model.addJoint(j, pin.JointModelRZ(), pin.SE3.Identity(), "r")
    layout = P.PinocchioLayout(robot, model)
    # jaxkin b.qw b.qx b.qy b.qz p.x p.y p.cos p.sin r; Pinocchio b (x, y, z, w), p, r
    np.testing.assert_array_equal(layout.q_src, [1, 2, 3, 0, 4, 5, 6, 7, 8])
    other = pin.Model()
    other.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "not_in_jaxkin")
    with pytest.raises(RuntimeError, match="not_in_jaxkin"):
        P.PinocchioLayout(robot, other)


@pytest.mark.parametrize("several", [False, True])
def test_pinocchio_frames_stored_loop_fills_the_preallocated_array(several):
    src, robot, _ = solo12()
    frames = ("FL_FOOT", "HR_FOOT") if several else ("FL_FOOT",)
    pf = P.PinocchioFrames(src, robot, P.Case("feet", frames, "local", several))
    Q = random_q(robot, 3)
    out = np.full(pf.shape(3), np.nan)
    pf.loop(True, 3, out)(pf.prepare(Q))
    assert out.shape == ((3, 2, 6, robot.nv) if several else (3, 6, robot.nv))
    want = pf.jacobians(Q)
    np.testing.assert_array_equal(pf.layout.columns_to_jaxkin(out), want)
    pf.loop(False, 3)(pf.prepare(Q))  # the unstored loop runs on the same inputs
    data = pf.model.createData()
    J0 = pin.computeFrameJacobian(
        pf.model, data, pf.layout.q(Q[0]), pf.ids[-1], pin.ReferenceFrame.LOCAL
    )
    got = want[0, -1] if several else want[0]
    np.testing.assert_allclose(got, pf.layout.columns_to_jaxkin(J0), rtol=0, atol=1e-12)


def test_check_fails_a_float64_row_over_the_scaled_tolerance_only():
    want = np.full((2, 6, 3), 10.0)
    ok = dict(dtype="float64", status="ok")
    check(ok, want + 5 * CHECK_TOL, want, "Pinocchio")  # 5e-12 over a scale of 10
    assert ok["status"] == "ok" and math.isclose(
        ok["scaled_diff"], 5 * CHECK_TOL / 10, rel_tol=1e-3
    )
    bad = dict(dtype="float64", status="ok")
    check(bad, want + 20 * CHECK_TOL, want, "Pinocchio")
    assert bad["status"].startswith("failed: differs from Pinocchio")
    f32 = dict(dtype="float32", status="ok")
    check(f32, want + 1e-6, want, "Pinocchio")
    assert f32["status"] == "ok"


def _row(robot, quantity, per_s, stored=None, unstored=None, n=100_000):
    row = dict(robot=robot, impl="jaxkin", quantity=quantity, dtype="float64", n=n, status="ok")
    row.update(per_s=per_s, lower_s=0.2, compile_s=0.6, max_abs_diff=1e-15)
    row.update(pin_samples_s=[1 / unstored] if unstored else [])
    if unstored:
        row.update(pin_per_s=unstored, ratio_vs_pin=per_s / unstored)
    if stored:
        row.update(pin_stored_samples_s=[1 / stored], pin_stored_per_s=stored)
        row.update(ratio_vs_pin_stored=per_s / stored)
    return row


def test_summary_table_gives_both_ratios_and_the_issue_targets():
    result = dict(
        robots=dict(
            panda=dict(dof=7),
            talos=dict(floating_base=True, cases={"hand, local": {}}),
            old=dict(dof=6),
        ),
        rows=[
            _row("panda", "geometric", 3.2e6, stored=1e6, unstored=2e6),
            _row("talos", "hand, local", 1e6, stored=4e5, unstored=8e5),
            _row("old", "geometric", 1e6, unstored=5e5),  # a run without the stored loop
        ],
    )
    lines = R.summary_table(result).splitlines()[2:]
    assert "| 3.20x | 2.00 M/s | 1.60x |" in lines[0] and lines[0].endswith("yes |")
    assert "hand, local" in lines[1] and "| 2.50x |" in lines[1] and lines[1].endswith("yes |")
    assert lines[2].endswith("stored loop not measured |")
    table = R.case_table(result["rows"], "talos")
    assert "1.00 M (2.50x / 1.25x)" in table and "400.0 k/s" in table and "800.0 k/s" in table


def test_chunked_rows_and_page_faults_are_reported_beside_the_jit_vmap_row():
    # A chunked_map row (the N results into a preallocated array) is judged against the stored
    # loop measured beside it, with its own compile; page faults appear in the profile.
    chunked = _row("g1", "feet + hands", 3e5, stored=1e5, unstored=2e5)
    chunked.update(impl=R.CHUNKED, chunk_compile_s=3.6, chunk_size=1248)
    vmapped = _row("g1", "feet + hands", 1.5e5, stored=1e5, unstored=2e5)
    vmapped.update(page_faults_per_call=250_000.0, hlo=dict(fusions=48))
    result = dict(
        robots=dict(g1=dict(floating_base=True, cases={"feet + hands": {}})),
        rows=[vmapped, chunked],
    )
    (line,) = R.summary_table(result).splitlines()[2:]
    assert "| 1.50x |" in line and "| 300.0 k/s | 3.00x | 3.60 s |" in line
    assert line.endswith("jit(vmap): no; chunked_map: no |")  # compiles over 1.5 s
    table = R.case_table(result["rows"], "g1").splitlines()
    assert "| jit(vmap) | 150.0 k (1.50x / 0.75x) |" in table[2]
    assert "| chunked_map into an array | 300.0 k (3.00x / 1.50x) |" in table[3]
    assert "| 3.60 |" in table[3] and "| 0.80 |" in table[2]  # compile: its own, lower + compile
    profile = R.profile_table(result["rows"], 2.4)
    assert "2.40 us" in profile
    assert "| 250,000 | 10,240 | 150.0 k/s |" in profile  # faults per call, bytes per config


def test_path_costs_compare_a_row_with_the_one_its_bar_names():
    # The issue's bars on how the cost grows: a Talos hand against the Panda's tip, the G1's four
    # frames against one; the time per Jacobian, through chunked_map and one jit(vmap) call.
    rows = [
        _row("panda", "geometric", 6e6, stored=1e6, unstored=2e6),
        _row("talos", "hand, world-aligned", 1.5e6, stored=1e6, unstored=2e6),
        _row("g1", "feet + hands, world-aligned", 3e5, stored=1e5, unstored=2e5),
        _row("g1", "left hand, world-aligned", 9e5, stored=1e5, unstored=2e5),
    ]
    chunked = _row("panda", "geometric", 8e6, stored=1e6, unstored=2e6)
    chunked.update(impl=R.CHUNKED, chunk_compile_s=0.2, chunk_size=20_000)
    talos, g1 = R.path_costs([*rows, chunked]).splitlines()
    assert talos.startswith("- talos hand, world-aligned against panda tip")
    assert "jit(vmap) 4.00x (1.50 M/s against 6.00 M/s" in talos
    assert "chunked_map" not in talos  # no chunked Talos row: that comparison is left out
    assert "against g1 left hand, world-aligned (one frame's; bar <= 1.5x)" in g1
    assert "jit(vmap) 3.00x (300.0 k/s against 900.0 k/s" in g1
    assert R.path_costs(rows[:1]) == ""
