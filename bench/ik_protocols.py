"""Inverse kinematics on the field's own protocols: TRAC-IK's, cuRobo's / PyRoki's, and 1e-9.

``python3 -m bench.ik_protocols [--quick] [--write-md]`` (``--quick``: 300 targets per arm,
peers on 50) writes ``bench/results/ik_protocols.json`` and prints the tables; ``--write-md``
puts them into bench/IK.md between the ``protocols:start`` / ``protocols:end`` markers.

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
* **Pinocchio**, its documentation's DLS loop (``bench.ik.run_pinocchio``: eps 1e-10, 1000
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
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk

from .ik import run_pinocchio
from .peers import Pinocchio, RobotSource, _quiet, erd_urdf
from .report import (
    HERE,
    RESULTS_DIR,
    log,
    machine_info,
    markdown_table,
    median,
    replace_section,
    timed,
    utc_now,
    write_json,
)

TARGET_SEED = 15
GPU_SEED = 16
TOL = 1e-5
PRECISE = 1e-9
GPU_POS, GPU_ROT = 5e-3, 5e-2
PUBLISHED_GPU = {"PyRoki": 13.3e-3, "cuRobo": 26.5e-3}  # s per 1,000 targets, RTX 4090
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


# ---------------------------------------------------------------------------- judge
class Judge:
    """Per-component pose errors with jaxkin's float64 fk: position and rotation vector of
    ``R R_target^T`` (base axes), and whether every joint is within its limits."""

    def __init__(self, robot: jk.Robot, Ts: np.ndarray):
        self.Ts = Ts
        self._fk = jax.jit(jax.vmap(lambda q: jk.fk(robot, q)))
        self.lo, self.hi = np.asarray(robot.lower), np.asarray(robot.upper)

    def errors(self, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 6) absolute error components (inf for a non-finite answer) and (n,) in-limits."""
        qs = np.asarray(qs, dtype=np.float64)
        Ts = self.Ts[: len(qs)]
        finite = np.all(np.isfinite(qs), axis=1)
        T = np.asarray(self._fk(jnp.asarray(np.where(finite[:, None], qs, 0.0))))
        dp = T[:, :3, 3] - Ts[:, :3, 3]
        M = T[:, :3, :3] @ np.swapaxes(Ts[:, :3, :3], 1, 2)
        v = 0.5 * np.stack(
            [M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0], M[:, 1, 0] - M[:, 0, 1]], 1
        )
        s = np.linalg.norm(v, axis=1)
        angle = np.arctan2(s, 0.5 * (np.trace(M, axis1=1, axis2=2) - 1))
        scale = np.where(s > 1e-300, angle / np.maximum(s, 1e-300), 1.0)
        dw = v * scale[:, None]
        err = np.abs(np.concatenate([dp, dw], 1))
        err[~finite] = np.inf
        within = finite & np.all((qs >= self.lo - 1e-12) & (qs <= self.hi + 1e-12), axis=1)
        return err, within

    def success(self, qs: np.ndarray, tol: float) -> np.ndarray:
        err, within = self.errors(qs)
        return within & np.all(err <= tol, axis=1)

    def gpu_success(self, qs: np.ndarray) -> np.ndarray:
        err, within = self.errors(qs)
        pos = np.linalg.norm(err[:, :3], axis=1)
        rot = np.linalg.norm(err[:, 3:], axis=1)
        return within & (pos <= GPU_POS) & (rot <= GPU_ROT)


# ---------------------------------------------------------------------------- solvers
def run_jaxkin(robot, Ts, q0, repeats: int, **kw) -> dict[str, Any]:
    def solve():
        sol = jk.solve_ik(robot, Ts, q0=q0, throw=False, **kw)
        return jax.block_until_ready(sol)

    sol, first = timed(solve)
    times = [timed(solve)[1] for _ in range(repeats)]
    return dict(
        q=np.asarray(sol.q),
        n=len(Ts),
        total_s=median(times),
        first_call_s=first,
        samples_s=times,
        own_converged=float(np.mean(np.asarray(sol.converged))),
    )


def _one_at_a_time(Ts, dof, solve, budget_s: float) -> dict[str, Any]:
    qs, t0 = [], time.perf_counter()
    for k, T in enumerate(Ts):
        qs.append(solve(k, T))
        if time.perf_counter() - t0 > budget_s:
            break
    elapsed = time.perf_counter() - t0
    return dict(q=np.array(qs).reshape(-1, dof), n=len(qs), total_s=elapsed)


def run_tracik(src: RobotSource, robot, Ts, mid, budget_s: float) -> dict[str, Any]:
    import pytracik
    from scipy.spatial.transform import Rotation

    base = robot.frame_names[0]
    with _quiet():
        solver = pytracik.TRAC_IK(base, src.tip, src.urdf, 0.005, TOL, pytracik.SolveType.Speed)
    if pytracik.get_num_joints(solver) != robot.dof:
        raise RuntimeError(f"TRAC-IK chain has {pytracik.get_num_joints(solver)} joints")
    lo = np.where(np.isfinite(robot.lower), robot.lower, -2 * math.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, 2 * math.pi)
    pytracik.set_joint_limits(solver, [float(x) for x in lo], [float(x) for x in hi])
    fk_diff = max(
        float(np.abs(pytracik.fk(solver, q) - np.asarray(jk.fk(robot, q))).max())
        for q in np.asarray(jk.sample_configurations(robot, 5, 99))
    )
    if fk_diff > 1e-9:
        raise RuntimeError(f"TRAC-IK's chain disagrees with jaxkin's fk by {fk_diff:.1e}")
    quats = Rotation.from_matrix(Ts[:, :3, :3]).as_quat()  # x, y, z, w

    def solve(k, T):
        out = pytracik.ik(solver, mid, *T[:3, 3], *quats[k])
        return out[1:] if out[0] >= 0 else np.full(robot.dof, np.nan)

    res = _one_at_a_time(Ts, robot.dof, solve, budget_s)
    res["fk_max_abs_diff"] = fk_diff
    return res


def run_rtb(src: RobotSource, robot, Ts, mid, budget_s: float) -> dict[str, Any]:
    import roboticstoolbox as rtb

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "arm.urdf"
        path.write_text(src.urdf)
        with warnings.catch_warnings(), _quiet():
            warnings.simplefilter("ignore")
            ets = rtb.Robot.URDF(str(path)).ets(end=src.tip)
    if ets.n != robot.dof:
        raise RuntimeError(f"RTB's ETS has {ets.n} joints, jaxkin {robot.dof}")
    qs = np.asarray(jk.sample_configurations(robot, 5, 99))
    fk_diff = max(float(np.abs(ets.fkine(q).A - np.asarray(jk.fk(robot, q))).max()) for q in qs)
    if fk_diff > 1e-9:
        raise RuntimeError(f"its URDF import disagrees with jaxkin's fk by {fk_diff:.1e}")

    def solve(k, T):
        sol = ets.ikine_LM(T, q0=mid, tol=1e-12, joint_limits=True)
        return sol.q if sol.success else np.full(robot.dof, np.nan)

    res = _one_at_a_time(Ts, robot.dof, solve, budget_s)
    res["fk_max_abs_diff"] = fk_diff
    return res


def run_pin(src: RobotSource, robot, Ts, mid, budget_s: float) -> dict[str, Any]:
    pin = Pinocchio(src, robot)  # refuses a model whose q differs from jaxkin's
    qs = np.asarray(jk.sample_configurations(robot, 5, 99))
    fk_diff = max(float(np.abs(pin.pose(q) - np.asarray(jk.fk(robot, q))).max()) for q in qs)
    if fk_diff > 1e-9:
        raise RuntimeError(f"Pinocchio's model disagrees with jaxkin's fk by {fk_diff:.1e}")
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    out = run_pinocchio(pin.model, pin.fid, Ts, mid[None], lo, hi, budget_s)
    n = out["measured_targets"]
    return dict(q=out["q"][:n], n=n, total_s=out["total_s"] * n / len(Ts), fk_max_abs_diff=fk_diff)


def run_pk(src: RobotSource, robot, Ts, mid) -> dict[str, Any]:
    import pytorch_kinematics as pk
    import torch

    with _quiet():
        chain = pk.build_serial_chain_from_urdf(src.urdf.encode(), src.tip).to(dtype=torch.float64)
    if tuple(chain.get_joint_parameter_names()) != tuple(robot.joint_names):
        raise RuntimeError("pytorch_kinematics' joint order differs from jaxkin's")
    lo = np.where(np.isfinite(robot.lower), robot.lower, -math.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, math.pi)
    qs = np.asarray(jk.sample_configurations(robot, 5, 99))
    m = chain.forward_kinematics(torch.tensor(qs)).get_matrix().numpy()
    fk_diff = float(np.abs(m - np.asarray(jax.vmap(lambda q: jk.fk(robot, q))(qs))).max())
    ik = pk.PseudoInverseIK(
        chain,
        retry_configs=torch.tensor(mid[None], dtype=torch.float64),
        joint_limits=torch.tensor(np.stack([lo, hi], 1), dtype=torch.float64),
        max_iterations=100,
        pos_tolerance=TOL,
        rot_tolerance=TOL,
        early_stopping_any_converged=True,
    )
    target = pk.Transform3d(matrix=torch.tensor(Ts, dtype=torch.float64))
    sol, elapsed = timed(lambda: ik.solve(target))
    return dict(q=sol.solutions.numpy()[:, 0], n=len(Ts), total_s=elapsed, fk_max_abs_diff=fk_diff)


# ---------------------------------------------------------------------------- protocols
def trac_ik_protocol(name: str, src: RobotSource, args) -> list[dict[str, Any]]:
    robot = jk.load_urdf(src.urdf, tip=src.tip, dtype=np.float64, name=name)
    q_star = np.asarray(jk.sample_configurations(robot, args.n, TARGET_SEED))
    Ts = np.asarray(jax.jit(jax.vmap(lambda q: jk.fk(robot, q)))(q_star))
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
    add("jaxkin", run_jaxkin(robot, Ts, mid, args.repeats))
    peer_Ts = Ts[: args.peer_targets]
    peers = {
        "TRAC-IK (pytracik)": lambda: run_tracik(src, robot, peer_Ts, mid, args.budget),
        "Robotics Toolbox ikine_LM": lambda: run_rtb(src, robot, peer_Ts, mid, args.budget),
        "Pinocchio docs DLS loop": lambda: run_pin(src, robot, peer_Ts, mid, args.budget),
        "pytorch_kinematics PseudoInverseIK": lambda: run_pk(src, robot, peer_Ts, mid),
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
    Ts = np.asarray(jax.jit(jax.vmap(lambda q: jk.fk(robot, q)))(q_star))
    starts = np.asarray(jk.sample_configurations(robot, 16, GPU_SEED + 1))
    judge = Judge(robot, Ts)
    rows = []
    for label, kw in (("defaults (tol 1e-10)", {}), ("tol=1e-4", {"tol": 1e-4})):
        log(f"GPU protocol: jaxkin {label}")
        res = run_jaxkin(robot, Ts, starts[0], args.repeats, seeds=starts[1:], **kw)
        q = res.pop("q")
        res.pop("n")
        rows.append(
            dict(
                setting=label,
                n=n,
                success=float(judge.gpu_success(q).mean()),
                success_1e9=float(judge.success(q, PRECISE).mean()),
                **res,
            )
        )
    return rows


# ---------------------------------------------------------------------------- report
def _pct(x: float) -> str:
    return f"{100 * x:.2f}%"


def tables(res: dict[str, Any]) -> str:
    m = res["machine"]
    la, lb = res["load_average_before"], res["load_average_after"]
    out = [
        f"`python3 -m bench.ik_protocols{' --quick' if res['quick'] else ''}` ({res['date']}; "
        f"{', '.join(m['cpu_model'])}, {m['cpus_usable']} cores; load "
        f"average (1, 5, 15 min) {', '.join(f'{x:.1f}' for x in la)} before, "
        f"{', '.join(f'{x:.1f}' for x in lb)} after; jax {m['jax']}, numpy {m['numpy']}, "
        f"pytracik {res['versions']['pytracik']}, roboticstoolbox-python {m['roboticstoolbox']}, "
        f"Pinocchio {m['pinocchio']}, pytorch-kinematics {m['pytorch_kinematics']}, torch "
        f"{m['torch']}; total {res['wall_s']:.0f} s).",
        "",
        f"**TRAC-IK's protocol**: {res['n']:,} random reachable targets per arm, one seed at "
        "mid-limits, success = every pose-error component <= 1e-5 (m, rad) and within the "
        f"limits. Peers on the first {res['peer_targets']:,} targets, stopped after "
        f"{res['budget']:.0f} s per arm (column *targets*). Time = wall time per target "
        "(jaxkin: one batched call, steady state; its first call, compile included, apart). "
        "The 1e-9 column judges the same answers at 1e-9 per component (float64).",
        "",
    ]
    rows = []
    for r in res["trac_ik"]:
        if "error" in r:
            rows.append([r["arm"], str(r["dof"]), r["solver"], "-", "-", "-", "-", r["error"]])
            continue
        first = f"first call {r['first_call_s']:.1f} s" if "first_call_s" in r else ""
        rows.append(
            [
                r["arm"],
                str(r["dof"]),
                r["solver"],
                f"{r['n']:,}",
                _pct(r["success"]),
                _pct(r["success_1e9"]),
                f"{r['mean_time_per_target_s'] * 1e3:.3g}",
                first,
            ]
        )
    out.append(
        markdown_table(
            [
                "arm",
                "DOF",
                "solver",
                "targets",
                "success 1e-5",
                "success 1e-9",
                "ms / target",
                "note",
            ],
            rows,
            "lrlrrrrl",
        )
    )
    if not res.get("gpu"):
        return "\n".join([*out, "", "cuRobo / PyRoki protocol: not run (the run was stopped)."])
    out += [
        "",
        f"**cuRobo / PyRoki protocol** (Franka Panda, {res['gpu'][0]['n']:,} targets, 16 seeds, "
        "success at 5 mm / 0.05 rad). jaxkin on this 2-core CPU; PyRoki and cuRobo are their "
        "published figures on an RTX 4090 GPU, **different hardware, not measured here**:",
        "",
    ]
    grows = [
        [
            f"jaxkin, {r['setting']} (this CPU)",
            _pct(r["success"]),
            _pct(r["success_1e9"]),
            f"{r['total_s'] * 1e3 * 1000 / r['n']:.1f}",
            f"{r['first_call_s']:.1f}",
        ]
        for r in res["gpu"]
    ]
    grows += [
        [f"{k} (published, RTX 4090)", "-", "-", f"{v * 1e3:.1f}", "-"]
        for k, v in PUBLISHED_GPU.items()
    ]
    out.append(
        markdown_table(
            ["solver", "success", "success 1e-9", "ms per 1,000 targets", "first call s"],
            grows,
            "lrrrr",
        )
    )
    return "\n".join(out)


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
        import json

        res = json.loads(args.from_json.read_text())
        res.setdefault("load_average_after", res["load_average_before"])
        res.setdefault("wall_s", math.nan)
        text = tables(res)
        print(text)
        if args.write_md:
            replace_section(
                HERE / "IK.md", text, "<!-- protocols:start -->", "<!-- protocols:end -->"
            )
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
    text = tables(res)
    print(text)
    if args.write_md:
        replace_section(HERE / "IK.md", text, "<!-- protocols:start -->", "<!-- protocols:end -->")
    log(f"wrote {out}")
    return 0


if __name__ == "__main__":
    rc = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)
