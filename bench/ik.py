"""Inverse-kinematics benchmark: 1,000 random reachable Panda targets, four solvers, same seeds.

Targets: ``fk`` of 1,000 configurations drawn uniformly within the Panda's joint limits by
``jk.sample_configurations`` (fixed key), the Franka Hand TCP as the tip (the zoo's ``panda``).
Starts: ``S`` configurations drawn the same way (another fixed key), *the same for every solver
and every target*: the first is the start of the single-start run (``S = 1``), all of them the
starts of the multi-start run, tried in order (the LM solvers, Pinocchio) or all at once
(pytorch_kinematics).

Solvers (all float64, CPU):

* **jaxkin** ``jk.solve_ik(robot, T, q0=seeds[0], seeds=seeds[1:])``: Levenberg-Marquardt, all
  targets in one jitted call; the first call (trace + compile + run) and the steady state
  (median of repeats) are timed apart;
* **Pinocchio**: the damped-least-squares loop of its documentation example (Pinocchio's
  ``examples/inverse-kinematics.py``: ``log6`` error in the frame, ``Jlog6``, ``DT = 0.1``,
  ``damp = 1e-12``, ``IT_MAX = 1000``), with ``eps`` tightened from 1e-4 to 1e-10 so that it can
  meet the 1e-9 criterion, one target at a time in Python; a start whose answer leaves the joint
  limits (the example ignores them) counts as failed and the next start is tried;
* **Robotics Toolbox** ``ets.ikine_LM(T, q0=seeds, slimit=S, ilimit=100, tol=1e-20,
  joint_limits=True)`` (its ``E = 0.5 e^T e`` below 1e-20 means ``|e|`` below 1.4e-10);
* **pytorch_kinematics** ``PseudoInverseIK(chain, retry_configs=seeds, max_iterations=200,
  pos_tolerance=1e-10, rot_tolerance=1e-10, early_stopping_any_converged=True, joint_limits)``,
  float64 chain built from the same URDF string, all targets in one batched call.

Every answer is judged the same way, with jaxkin's float64 forward kinematics (checked against
Pinocchio and the Robotics Toolbox at start-up): *success* = position error <= 1e-9 m and
orientation error <= 1e-9 rad (the converged-pose criterion of tests/test_ik.py) and every joint
within its limits; the loose column uses 1e-6. The Pinocchio model and the pytorch_kinematics
chain come from one URDF that ``jk.to_urdf`` writes from the zoo's modified-DH Panda; the
toolbox's ``models.DH.Panda`` has the same table (tests/test_oracle_rtb.py) and gets the zoo's
tool.

This module measures, with the judge and the runners of :mod:`bench.ik_harness`;
:mod:`bench.ik_report` writes the table.

Usage: ``python3 -m bench.ik [--n N] [--seeds S] [--quick] [--out PATH]``; writes
``bench/results/ik.json`` and prints a markdown table.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
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
from .ik_report import results_table
from .report import RESULTS_DIR, log, machine_info, utc_now, write_json

TARGET_SEED = 2024
START_SEED = 7
TOL = 1e-9
LOOSE = 1e-6


# ----------------------------------------------------------------------------- judge
def verdict(judge: Judge, qs: np.ndarray) -> dict[str, Any]:
    """The shares of answers that succeed (position and rotation angle within :data:`TOL`, in
    the limits), succeed loosely (:data:`LOOSE`) and lie within the limits, and the errors of the
    successes."""
    e = judge.errors(qs)
    dp, dw, within = np.linalg.norm(e.position, axis=1), e.angle, e.within
    ok = judge.norm_success(qs, TOL, TOL)
    loose = judge.norm_success(qs, LOOSE, LOOSE)
    return dict(
        success=float(ok.mean()),
        success_loose=float(loose.mean()),
        within_limits=float(within.mean()),
        median_position_error_of_successes=float(np.median(dp[ok])) if ok.any() else None,
        max_position_error_of_successes=float(dp[ok].max()) if ok.any() else None,
        max_orientation_error_of_successes=float(dw[ok].max()) if ok.any() else None,
    )


# ----------------------------------------------------------------------------- solvers
def run_jaxkin_from(robot, Ts, seeds, repeats: int) -> dict[str, Any]:
    """Exactly the shared starts: the given seeds, or q0 alone (num_seeds=1: no default
    restarts)."""
    extra = {"seeds": seeds[1:]} if len(seeds) > 1 else {"num_seeds": 1}
    return dict(
        **run_jaxkin(robot, Ts, seeds[0], repeats, **extra),
        how="jk.solve_ik (LM, lax.while_loop, 64+ lanes), defaults",
    )


def run_pinocchio_docs(model, fid, Ts, seeds, lo, hi, time_budget_s: float) -> dict[str, Any]:
    return dict(
        **run_pinocchio(model, fid, Ts, seeds, lo, hi, time_budget_s),
        how="Pinocchio docs DLS loop (log6, Jlog6, DT=0.1, damp=1e-12, IT_MAX=1000), eps=1e-10",
    )


def run_rtb(rtb_robot, Ts, seeds, time_budget_s: float) -> dict[str, Any]:
    solve = rtb_solver(
        rtb_robot.ets(), q0=seeds, slimit=len(seeds), ilimit=100, tol=1e-20, joint_limits=True
    )
    return dict(
        **one_target_at_a_time(Ts, len(seeds[0]), solve, time_budget_s),
        how="ets.ikine_LM(q0=seeds, slimit=S, ilimit=100, tol=1e-20, joint_limits=True)",
    )


def run_pk_seeds(urdf: str, Ts, seeds, lo, hi) -> dict[str, Any]:
    out = run_pk(pk_chain(urdf, "tool"), Ts, seeds, lo, hi, max_iterations=200, tol=1e-10)
    return dict(
        **out,
        how="PseudoInverseIK(retry_configs=seeds, max_iterations=200, tol 1e-10, "
        "early_stopping_any_converged=True), float64 chain",
    )


# ----------------------------------------------------------------------------- checks
def check_models(robot, pin_model, fid, rtb_robot, urdf, qs) -> dict[str, float]:
    """Largest fk difference of each peer's model from jaxkin's, over ``qs``."""
    import pinocchio as pin

    data = pin_model.createData()

    def pin_pose(q):
        pin.framesForwardKinematics(pin_model, data, q)
        return np.array(data.oMf[fid].homogeneous)

    out = {
        "pinocchio": fk_disagreement(robot, qs, np.stack([pin_pose(q) for q in qs])),
        "robotics_toolbox": fk_disagreement(
            robot, qs, np.stack([rtb_robot.fkine(q).A for q in qs])
        ),
    }
    try:
        import torch

        m = pk_chain(urdf, "tool").forward_kinematics(torch.tensor(qs)).get_matrix().numpy()
        out["pytorch_kinematics"] = fk_disagreement(robot, qs, m)
    except ImportError:
        pass
    return out


# ----------------------------------------------------------------------------- main
def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--budget", type=float, default=300.0, help="seconds per slow peer and run")
    ap.add_argument("--quick", action="store_true", help="N = 100, budget 20 s")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--skip", nargs="*", default=[], help="peers to skip: pinocchio rtb pk")
    ap.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="JAX persistent compilation cache directory (a second run then loads the compiled "
        "solver instead of compiling it: its first call shows the cost in a new process)",
    )
    return ap


def _configure_jax(cache: Path | None) -> None:
    jax.config.update("jax_enable_x64", True)
    if cache is not None:
        jax.config.update("jax_compilation_cache_dir", str(cache))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def solve_all(problem: dict[str, Any], starts: np.ndarray, args) -> dict[str, dict[str, Any]]:
    """Every solver not in ``args.skip`` on every target from ``starts``."""
    p = problem
    S = len(starts)
    results = {}
    log(f"S = {S}: jaxkin")
    results["jaxkin"] = run_jaxkin_from(p["robot"], p["Ts"], starts, args.repeats)
    if "pk" not in args.skip:
        log(f"S = {S}: pytorch_kinematics")
        results["pytorch_kinematics"] = run_pk_seeds(p["urdf"], p["Ts"], starts, p["lo"], p["hi"])
    if "rtb" not in args.skip:
        log(f"S = {S}: Robotics Toolbox")
        results["robotics_toolbox"] = run_rtb(p["rtb_robot"], p["Ts"], starts, args.budget)
    if "pinocchio" not in args.skip:
        log(f"S = {S}: Pinocchio")
        results["pinocchio"] = run_pinocchio_docs(
            p["pin_model"], p["fid"], p["Ts"], starts, p["lo"], p["hi"], args.budget
        )
    return results


def judge_rows(problem: dict[str, Any], S: int, n: int, results: dict) -> list[dict[str, Any]]:
    """One row per solver: its answers judged, its times and its own report."""
    rows = []
    for name, res in results.items():
        q = res.pop("q")
        measured = res.get("measured_targets", n)
        judged = verdict(Judge(problem["robot"], problem["Ts"][:measured]), q[:measured])
        total = res.pop("total_s", None) or res["steady_s"]
        rows.append(dict(solver=name, starts=S, n=n, total_s=total, **judged, **res))
        log(f"  {name}: {judged['success']:.3f} success, {total:.3f} s")
    return rows


def setup(n: int, n_seeds: int) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    """The robot, its targets and every peer's model (``problem``), the starts, and the
    configurations of the targets."""
    import pinocchio as pin
    import roboticstoolbox as rtb

    robot = jk.robots.load("panda", dtype=np.float64)
    q_star = np.asarray(jk.sample_configurations(robot, n, TARGET_SEED))
    seeds = np.asarray(jk.sample_configurations(robot, n_seeds, START_SEED))
    Ts = target_poses(robot, q_star)
    urdf = jk.to_urdf(robot)
    pin_model = pin.buildModelFromXML(urdf)
    rtb_robot = rtb.models.DH.Panda()
    rtb_robot.tool = np.asarray(robot.tool)
    problem = dict(
        robot=robot,
        Ts=Ts,
        lo=np.asarray(robot.lower),
        hi=np.asarray(robot.upper),
        urdf=urdf,
        pin_model=pin_model,
        fid=pin_model.getFrameId("tool"),
        rtb_robot=rtb_robot,
    )
    return problem, seeds, q_star


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.quick:
        args.n, args.budget = 100, 20.0
    _configure_jax(args.cache)
    warnings.simplefilter("ignore", DeprecationWarning)
    gc.disable()

    problem, seeds, q_star = setup(args.n, args.seeds)
    p = problem
    fk_diff = check_models(
        p["robot"], p["pin_model"], p["fid"], p["rtb_robot"], p["urdf"], q_star[:20]
    )
    info = dict(
        benchmark="ik",
        date=utc_now(),
        n_targets=args.n,
        starts=args.seeds,
        compilation_cache=str(args.cache) if args.cache else None,
        criteria=dict(position_m=TOL, orientation_rad=TOL, loose=LOOSE, within_limits=True),
        model_fk_max_abs_diff=fk_diff,
        machine=machine_info(),
        load_average_before=os.getloadavg(),
    )
    log(f"models agree with jaxkin to {info['model_fk_max_abs_diff']}")
    rows = []
    for S in sorted({1, args.seeds}):
        rows += judge_rows(problem, S, args.n, solve_all(problem, seeds[:S], args))
    info["load_average_after"] = os.getloadavg()
    info["rows"] = rows
    out = args.out or RESULTS_DIR / ("ik_quick.json" if args.quick else "ik.json")
    write_json(out, info)
    print(results_table(rows))
    log(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
