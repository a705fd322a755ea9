"""Inverse kinematics on the field's own protocols: TRAC-IK's, cuRobo's / PyRoki's, and 1e-9.

``python3 -m bench.ik_protocols [--quick] [--write-md]`` (``--quick``: 300 targets per arm,
peers on 50) writes ``bench/results/ik_protocols.json`` and prints the tables; ``--write-md``
puts them into bench/IK.md between the ``protocols:start`` / ``protocols:end`` markers;
``--from-json PATH`` reports an earlier run without measuring. This module measures, with the
judge and the runners of :mod:`bench.ik_harness`; :mod:`bench.ik_protocols_report` writes the
tables.

**TRAC-IK's protocol** (Beeson and Ames, 2015): per arm, ``N`` (10,000) targets ``fk(q*)`` of
configurations drawn uniformly within the joint limits (``jk.sample_configurations``, fixed key;
an unbounded joint draws in [-pi, pi]); one seed, the mid-limit configuration (0 for an
unbounded joint); success when every component of the pose error (position in metres, the
rotation vector of ``R R_target^T`` in radians, both in base axes, as KDL's ``diff``) is at most
1e-5 and every joint lies within its limits; success rate and mean time per target.

* **jaxkin**, default arguments, batched: ``jk.solve_ik(robot, Ts, q0=mid, throw=False)``
  (Levenberg-Marquardt, tol 1e-10, its default random restarts), all targets in one call;
  first call (trace + compile + run) apart from the steady state (median of repeats).
* **TRAC-IK** through ``pytracik`` (PyPI, binary wheel): ``TRAC_IK(base, tip, urdf, 0.005,
  1e-5, Speed)`` (TRAC-IK's defaults: 5 ms timeout, eps 1e-5), one target at a time from the
  mid seed. Its URDF reader leaves most joint limits at 0 here, so the limits are set with
  ``set_joint_limits`` (an unbounded joint gets +-2 pi).
* **Robotics Toolbox** ``ets.ikine_LM(T, q0=mid, tol=1e-12, joint_limits=True)`` (its defaults
  otherwise: 30 iterations, 100 random restarts; ``E = 0.5 |e|^2 < 1e-12``), only where its URDF
  import agrees with jaxkin's fk.
* **Pinocchio**, its documentation's DLS loop (``bench.ik_harness.run_pinocchio``: eps 1e-10, 1000
  iterations), from the mid seed, no restarts (the example has none).
* **pytorch_kinematics** ``PseudoInverseIK(chain, retry_configs=[mid], max_iterations=100,
  pos_tolerance=1e-5, rot_tolerance=1e-5, joint_limits=...)``, float64, batched.

Peers run on the first ``--peer-targets`` targets (and stop after ``--budget`` seconds per arm):
the table says how many each measured.

**The GPU-solver protocol** of cuRobo and PyRoki (PyRoki's paper: Franka Panda, 1,000 targets,
16 seeds, success at 5 mm / 0.05 rad): jaxkin on this CPU, 16 starts (``q0`` plus 15 drawn
seeds), with default arguments and with ``tol=1e-4``; their published times (RTX 4090: PyRoki
13.3 ms, cuRobo 26.5 ms per 1,000 targets) are quoted, not measured: different hardware.

**Precision tier**: the TRAC-IK targets judged again at 1e-9 per component.
"""

from __future__ import annotations

import argparse
import gc
import math
import os
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import jax
import numpy as np

import jaxkin as jk

from .ik_harness import (
    Judge,
    fk_disagreement,
    one_target_at_a_time,
    pk_chain,
    rtb_solver,
    run_jaxkin,
    run_pinocchio,
    run_pk,
    target_poses,
)
from .ik_protocols_report import load, report
from .peers import Pinocchio, RobotSource, erd_urdf, quiet
from .report import HERE, RESULTS_DIR, exit_without_teardown, log, machine_info, utc_now, write_json

TARGET_SEED = 15
GPU_SEED = 16
TOL = 1e-5
PRECISE = 1e-9
GPU_POS, GPU_ROT = 5e-3, 5e-2
ROOT = HERE.parent


# ---------------------------------------------------------------------------- arms
def arms() -> dict[str, RobotSource]:
    """Every arm available offline: one URDF text and tip each (jaxkin and every peer)."""
    erd = {
        "panda": ("erd/panda", "panda_hand_tcp"),
        "ur3": ("erd/ur3_robot", "tool0"),
        "ur5": ("erd/ur5_robot", "tool0"),
        "ur10": ("erd/ur10_robot", "tool0"),
        "kinova (Jaco2 6-DOF)": ("erd/kinova", "j2s6s200_end_effector"),
        "xarm7": ("erd/xarm7", "link_eef"),
        "unitree z1": ("erd/z1", "link06"),
    }
    out = {
        name: RobotSource(name, erd_urdf(path), tip, f"example-robot-data {path}")
        for name, (path, tip) in erd.items()
    }
    iiwa = (ROOT / "tests" / "data" / "kuka_iiwa14.urdf").read_text()
    r = jk.load_urdf(iiwa)
    out["iiwa14"] = RobotSource(
        "iiwa14", iiwa, r.frame_names[r.tip_frame], "tests/data/kuka_iiwa14.urdf"
    )
    niryo = jk.robots.load("niryo_one")
    out["niryo one"] = RobotSource(
        "niryo one",
        jk.to_urdf(niryo),
        niryo.frame_names[niryo.tip_frame],
        "jk.to_urdf(zoo niryo_one)",
    )
    return out


def mid_seed(robot: jk.Robot) -> np.ndarray:
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    return np.where(np.isfinite(lo) & np.isfinite(hi), 0.5 * (lo + hi), 0.0)


# ---------------------------------------------------------------------------- solvers
def jaxkin_row(robot, Ts, q0, repeats: int, **kw) -> dict[str, Any]:
    """:func:`bench.ik_harness.run_jaxkin` as this protocol's row: steady time as ``total_s``."""
    res = run_jaxkin(robot, Ts, q0, repeats, **kw)
    return dict(
        q=res["q"],
        n=len(Ts),
        total_s=res["steady_s"],
        first_call_s=res["first_call_s"],
        samples_s=res["samples_s"],
        own_converged=res["own_converged"],
    )


def measured(out: dict[str, Any], n_targets: int) -> dict[str, Any]:
    """A :func:`bench.ik_harness.one_target_at_a_time` result as this protocol's row: the
    answers and the time of the measured targets alone."""
    n = out["measured_targets"]
    return dict(q=out["q"][:n], n=n, total_s=out["total_s"] * n / n_targets)


def check_configurations(robot) -> np.ndarray:
    """The configurations on which a peer's model is checked against jaxkin's fk."""
    return np.asarray(jk.sample_configurations(robot, 5, 99))


def agreeing(what: str, diff: float) -> float:
    """``diff`` (a peer's largest fk difference from jaxkin's), refused above 1e-9."""
    if diff > 1e-9:
        raise RuntimeError(f"{what} disagrees with jaxkin's fk by {diff:.1e}")
    return diff


def run_tracik(src: RobotSource, robot, Ts, mid, budget_s: float) -> dict[str, Any]:
    import pytracik
    from scipy.spatial.transform import Rotation

    base = robot.frame_names[0]
    with quiet():
        solver = pytracik.TRAC_IK(base, src.tip, src.urdf, 0.005, TOL, pytracik.SolveType.Speed)
    if pytracik.get_num_joints(solver) != robot.dof:
        raise RuntimeError(f"TRAC-IK chain has {pytracik.get_num_joints(solver)} joints")
    lo = np.where(np.isfinite(robot.lower), robot.lower, -2 * math.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, 2 * math.pi)
    pytracik.set_joint_limits(solver, [float(x) for x in lo], [float(x) for x in hi])
    qs = check_configurations(robot)
    poses = np.stack([pytracik.fk(solver, q) for q in qs])
    fk_diff = agreeing("TRAC-IK's chain", fk_disagreement(robot, qs, poses))
    quats = Rotation.from_matrix(Ts[:, :3, :3]).as_quat()  # x, y, z, w

    def solve(k, T):
        out = pytracik.ik(solver, mid, *T[:3, 3], *quats[k])
        return (out[1:], True) if out[0] >= 0 else (np.full(robot.dof, np.nan), False)

    res = measured(one_target_at_a_time(Ts, robot.dof, solve, budget_s), len(Ts))
    return dict(**res, fk_max_abs_diff=fk_diff)


def run_rtb(src: RobotSource, robot, Ts, mid, budget_s: float) -> dict[str, Any]:
    import roboticstoolbox as rtb

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "arm.urdf"
        path.write_text(src.urdf)
        with warnings.catch_warnings(), quiet():
            warnings.simplefilter("ignore")
            ets = rtb.Robot.URDF(str(path)).ets(end=src.tip)
    if ets.n != robot.dof:
        raise RuntimeError(f"RTB's ETS has {ets.n} joints, jaxkin {robot.dof}")
    qs = check_configurations(robot)
    poses = np.stack([ets.fkine(q).A for q in qs])
    fk_diff = agreeing("its URDF import", fk_disagreement(robot, qs, poses))
    ikine_lm = rtb_solver(ets, q0=mid, tol=1e-12, joint_limits=True)

    def solve(k, T):  # an answer it calls failed counts as failed
        q, ok = ikine_lm(k, T)
        return (q if ok else np.full(robot.dof, np.nan)), ok

    res = measured(one_target_at_a_time(Ts, robot.dof, solve, budget_s), len(Ts))
    return dict(**res, fk_max_abs_diff=fk_diff)


def run_pin(src: RobotSource, robot, Ts, mid, budget_s: float) -> dict[str, Any]:
    pin = Pinocchio(src, robot)  # refuses a model whose q differs from jaxkin's
    qs = check_configurations(robot)
    poses = np.stack([pin.pose(q) for q in qs])
    fk_diff = agreeing("Pinocchio's model", fk_disagreement(robot, qs, poses))
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    out = run_pinocchio(pin.model, pin.fid, Ts, mid[None], lo, hi, budget_s)
    return dict(**measured(out, len(Ts)), fk_max_abs_diff=fk_diff)


def run_pk_mid(src: RobotSource, robot, Ts, mid) -> dict[str, Any]:
    import torch

    with quiet():
        chain = pk_chain(src.urdf, src.tip)
    if tuple(chain.get_joint_parameter_names()) != tuple(robot.joint_names):
        raise RuntimeError("pytorch_kinematics' joint order differs from jaxkin's")
    lo = np.where(np.isfinite(robot.lower), robot.lower, -math.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, math.pi)
    qs = check_configurations(robot)
    m = chain.forward_kinematics(torch.tensor(qs)).get_matrix().numpy()
    fk_diff = fk_disagreement(robot, qs, m)
    res = run_pk(chain, Ts, mid[None], lo, hi, max_iterations=100, tol=TOL)
    return dict(q=res["q"], n=len(Ts), total_s=res["total_s"], fk_max_abs_diff=fk_diff)


# ---------------------------------------------------------------------------- protocols
def trac_ik_protocol(name: str, src: RobotSource, args) -> list[dict[str, Any]]:
    robot = jk.load_urdf(src.urdf, tip=src.tip, dtype=np.float64, name=name)
    q_star = np.asarray(jk.sample_configurations(robot, args.n, TARGET_SEED))
    Ts = target_poses(robot, q_star)
    mid = mid_seed(robot)
    judge = Judge(robot, Ts)
    rows = []

    def add(solver: str, res: dict[str, Any] | None, error: str | None = None):
        row = dict(arm=name, dof=robot.dof, solver=solver, n_total=args.n)
        if res is None:
            row["error"] = error
            log(f"  {name} {solver}: {error}")
        else:
            q = res.pop("q")
            ok = judge.success(q, TOL)
            precise = judge.success(q, PRECISE)
            row.update(
                n=int(res["n"]),
                success=float(ok.mean()),
                success_1e9=float(precise.mean()),
                mean_time_per_target_s=res["total_s"] / res["n"],
                **{k: v for k, v in res.items() if k not in ("n",)},
            )
            log(
                f"  {name} {solver}: {row['success']:.4f} ({row['n']} targets), "
                f"{row['mean_time_per_target_s'] * 1e3:.3f} ms/target"
            )
        rows.append(row)

    log(f"{name}: jaxkin, {args.n} targets")
    add("jaxkin", jaxkin_row(robot, Ts, mid, args.repeats))
    peer_Ts = Ts[: args.peer_targets]
    peers = {
        "TRAC-IK (pytracik)": lambda: run_tracik(src, robot, peer_Ts, mid, args.budget),
        "Robotics Toolbox ikine_LM": lambda: run_rtb(src, robot, peer_Ts, mid, args.budget),
        "Pinocchio docs DLS loop": lambda: run_pin(src, robot, peer_Ts, mid, args.budget),
        "pytorch_kinematics PseudoInverseIK": lambda: run_pk_mid(src, robot, peer_Ts, mid),
    }
    for solver, run in peers.items():
        if solver.split()[0].lower() in args.skip:
            continue
        try:
            add(solver, run())
        except Exception as e:  # a peer that cannot load this arm is reported, not fatal
            add(solver, None, f"{type(e).__name__}: {e}"[:300])
    return rows


def gpu_protocol(args) -> list[dict[str, Any]]:
    src = arms()["panda"]
    robot = jk.load_urdf(src.urdf, tip=src.tip, dtype=np.float64, name="panda")
    n = args.gpu_n
    q_star = np.asarray(jk.sample_configurations(robot, n, GPU_SEED))
    Ts = target_poses(robot, q_star)
    starts = np.asarray(jk.sample_configurations(robot, 16, GPU_SEED + 1))
    judge = Judge(robot, Ts)
    rows = []
    for label, kw in (("defaults (tol 1e-10)", {}), ("tol=1e-4", {"tol": 1e-4})):
        log(f"GPU protocol: jaxkin {label}")
        res = jaxkin_row(robot, Ts, starts[0], args.repeats, seeds=starts[1:], **kw)
        q = res.pop("q")
        res.pop("n")
        rows.append(
            dict(
                setting=label,
                n=n,
                success=float(judge.norm_success(q, GPU_POS, GPU_ROT).mean()),
                success_1e9=float(judge.success(q, PRECISE).mean()),
                **res,
            )
        )
    return rows


# ---------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="300 targets per arm, peers on 50")
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--peer-targets", type=int, default=500)
    ap.add_argument("--budget", type=float, default=12.0, help="seconds per slow peer and arm")
    ap.add_argument("--gpu-n", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--arms", default=None, help="comma-separated subset")
    ap.add_argument(
        "--skip", nargs="*", default=[], help="peers: trac-ik robotics pinocchio pytorch_kinematics"
    )
    ap.add_argument("--write-md", action="store_true")
    ap.add_argument("--from-json", type=Path, default=None, help="re-print a (partial) result")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.quick:
        args.n, args.peer_targets, args.budget, args.gpu_n, args.repeats = 300, 50, 5.0, 200, 1
    args.skip = [s.lower() for s in args.skip]
    if args.from_json is not None:
        report(load(args.from_json), args.write_md)
        return 0
    jax.config.update("jax_enable_x64", True)
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    from .report import version

    res: dict[str, Any] = dict(
        benchmark="ik_protocols",
        date=utc_now(),
        quick=args.quick,
        n=args.n,
        peer_targets=args.peer_targets,
        budget=args.budget,
        machine=machine_info(),
        versions=dict(pytracik=version("pytracik")),
        load_average_before=os.getloadavg(),
    )
    gc.disable()
    chosen = arms()
    if args.arms:
        chosen = {k: v for k, v in chosen.items() if k in args.arms.split(",")}
    out = args.out or RESULTS_DIR / (
        "ik_protocols_quick.json" if args.quick else "ik_protocols.json"
    )
    res["trac_ik"] = []
    for name, src in chosen.items():  # an arm that fails is reported; results saved per arm
        try:
            res["trac_ik"] += trac_ik_protocol(name, src, args)
        except Exception as e:
            log(f"{name}: {type(e).__name__}: {e}")
            res["trac_ik"].append(dict(arm=name, dof=0, solver="jaxkin", error=str(e)[:300]))
        write_json(out, res)
    res["gpu"] = gpu_protocol(args)
    res["load_average_after"] = os.getloadavg()
    res["wall_s"] = time.perf_counter() - t0
    write_json(out, res)
    report(res, args.write_md)
    log(f"wrote {out}")
    return 0


if __name__ == "__main__":
    exit_without_teardown(main())
