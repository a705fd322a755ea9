"""Inverse-kinematics benchmark: 1,000 random reachable Panda targets, four solvers, same seeds.

Targets: ``fk`` of 1,000 configurations drawn uniformly within the Panda's joint limits (fixed
seed), the Franka Hand TCP as the tip (the zoo's ``panda``). Starts: ``S`` configurations drawn
uniformly within the limits (fixed seed), *the same for every solver and every target*: the
first is the start of the single-start run (``S = 1``), all of them the starts of the multi-start
run, tried in order (the LM solvers, Pinocchio) or all at once (pytorch_kinematics).

Solvers (all float64, CPU):

* **jaxkin** ``jk.solve_ik(robot, T, q0=seeds[0], seeds=seeds[1:])``: Levenberg-Marquardt, all
  targets in one jitted call; the first call (trace + compile + run) and the steady state
  (median of repeats) are timed apart;
* **Pinocchio**: the damped-least-squares loop of its documentation example
  (``examples/inverse-kinematics.py``: ``log6`` error in the frame, ``Jlog6``, ``DT = 0.1``,
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
orientation error <= 1e-9 rad (ORACLES.md: converged IK pose) and every joint within its limits;
the loose column uses 1e-6. The Pinocchio model and the pytorch_kinematics chain come from one
URDF that ``jk.to_urdf`` writes from the zoo's modified-DH Panda; the toolbox's
``models.DH.Panda`` has the same table (tests/test_oracle_rtb.py) and gets the zoo's tool.

Usage: ``python3 -m bench.ik [--n N] [--seeds S] [--quick] [--out PATH]``; writes
``bench/results/ik.json`` and prints a markdown table.
"""

from __future__ import annotations

import argparse
import datetime
import gc
import json
import os
import platform
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk

RESULTS_DIR = Path(__file__).resolve().parent / "results"
TARGET_SEED = 2024
START_SEED = 7
TOL = 1e-9
LOOSE = 1e-6


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------- models
def sample_within_limits(robot: jk.Robot, n: int, seed: int) -> np.ndarray:
    lo, hi = np.asarray(robot.lower, dtype=np.float64), np.asarray(robot.upper, dtype=np.float64)
    return lo + (hi - lo) * np.random.default_rng(seed).random((n, robot.dof))


# ----------------------------------------------------------------------------- judge
class Judge:
    """Pose errors of answers, with jaxkin's float64 fk, and the success criteria."""

    def __init__(self, robot: jk.Robot, Ts: np.ndarray):
        self.robot = robot
        self.Ts = Ts
        self._fk = jax.jit(jax.vmap(lambda q: jk.fk(robot, q)))
        self.lo = np.asarray(robot.lower)
        self.hi = np.asarray(robot.upper)

    def __call__(self, qs: np.ndarray) -> dict[str, Any]:
        qs = np.asarray(qs, dtype=np.float64)
        finite = np.all(np.isfinite(qs), axis=1)
        T = np.asarray(self._fk(jnp.asarray(np.where(finite[:, None], qs, 0.0))))
        dp = np.linalg.norm(T[:, :3, 3] - self.Ts[:, :3, 3], axis=1)
        M = self.Ts[:, :3, :3] @ np.swapaxes(T[:, :3, :3], 1, 2)
        a = np.stack([M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0], M[:, 1, 0] - M[:, 0, 1]], 1)
        dw = np.arctan2(0.5 * np.linalg.norm(a, axis=1), 0.5 * (np.trace(M, axis1=1, axis2=2) - 1))
        within = np.all((qs >= self.lo - 1e-12) & (qs <= self.hi + 1e-12), axis=1) & finite
        ok = within & (dp <= TOL) & (dw <= TOL)
        loose = within & (dp <= LOOSE) & (dw <= LOOSE)
        return dict(
            success=float(ok.mean()),
            success_loose=float(loose.mean()),
            within_limits=float(within.mean()),
            median_position_error_of_successes=float(np.median(dp[ok])) if ok.any() else None,
            max_position_error_of_successes=float(dp[ok].max()) if ok.any() else None,
            max_orientation_error_of_successes=float(dw[ok].max()) if ok.any() else None,
        )


# ----------------------------------------------------------------------------- solvers
def run_jaxkin(robot, Ts, seeds, repeats: int) -> dict[str, Any]:
    kw = dict(q0=seeds[0], seeds=seeds[1:] if len(seeds) > 1 else None, throw=False)

    def solve():
        sol = jk.solve_ik(robot, Ts, **kw)
        jax.block_until_ready(sol)
        return sol

    t0 = time.perf_counter()
    sol = solve()
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sol = solve()
        times.append(time.perf_counter() - t0)
    return dict(
        q=np.asarray(sol.q),
        own_converged=float(np.mean(np.asarray(sol.converged))),
        first_call_s=first,
        steady_s=float(np.median(times)),
        steady_min_s=float(np.min(times)),
        samples_s=times,
        how="jk.solve_ik (LM, lax.while_loop, 64+ lanes), defaults",
    )


def run_pinocchio(model, fid, Ts, seeds, lo, hi, time_budget_s: float) -> dict[str, Any]:
    """The documentation example's loop (frame version), eps 1e-10, next start on failure."""
    import pinocchio as pin

    data = model.createData()
    eps, it_max, dt, damp = 1e-10, 1000, 1e-1, 1e-12
    qs = np.full((len(Ts), model.nq), np.nan)
    own = np.zeros(len(Ts), bool)
    iterations = 0
    t0 = time.perf_counter()
    done = 0
    for k, T in enumerate(Ts):
        oMdes = pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())
        for q_start in seeds:
            q = q_start.copy()
            success = False
            for _ in range(it_max):
                pin.framesForwardKinematics(model, data, q)
                iMd = data.oMf[fid].actInv(oMdes)
                err = pin.log(iMd).vector
                if np.linalg.norm(err) < eps:
                    success = True
                    break
                J = pin.computeFrameJacobian(model, data, q, fid)  # LOCAL
                J = -np.dot(pin.Jlog6(iMd.inverse()), J)
                v = -J.T.dot(np.linalg.solve(J.dot(J.T) + damp * np.eye(6), err))
                q = pin.integrate(model, q, v * dt)
                iterations += 1
            qs[k] = q
            if success and np.all((q >= lo) & (q <= hi)):
                own[k] = True
                break
        done = k + 1
        if time.perf_counter() - t0 > time_budget_s:
            break
    elapsed = time.perf_counter() - t0
    return dict(
        q=qs,
        own_converged=float(own[:done].mean()),
        total_s=elapsed * len(Ts) / done,
        measured_targets=done,
        iterations=iterations,
        how="Pinocchio docs DLS loop (log6, Jlog6, DT=0.1, damp=1e-12, IT_MAX=1000), eps=1e-10",
    )


def run_rtb(rtb_robot, Ts, seeds, time_budget_s: float) -> dict[str, Any]:
    ets = rtb_robot.ets()
    qs = np.full((len(Ts), len(seeds[0])), np.nan)
    own = np.zeros(len(Ts), bool)
    t0 = time.perf_counter()
    done = 0
    for k, T in enumerate(Ts):
        sol = ets.ikine_LM(T, q0=seeds, slimit=len(seeds), ilimit=100, tol=1e-20, joint_limits=True)
        qs[k] = sol.q
        own[k] = bool(sol.success)
        done = k + 1
        if time.perf_counter() - t0 > time_budget_s:
            break
    elapsed = time.perf_counter() - t0
    return dict(
        q=qs,
        own_converged=float(own[:done].mean()),
        total_s=elapsed * len(Ts) / done,
        measured_targets=done,
        how="ets.ikine_LM(q0=seeds, slimit=S, ilimit=100, tol=1e-20, joint_limits=True)",
    )


def run_pk(urdf: str, Ts, seeds, lo, hi) -> dict[str, Any]:
    import pytorch_kinematics as pk
    import torch

    chain = pk.build_serial_chain_from_urdf(urdf.encode(), end_link_name="tool")
    chain = chain.to(dtype=torch.float64)
    limits = torch.tensor(np.stack([lo, hi], 1), dtype=torch.float64)
    ik = pk.PseudoInverseIK(
        chain,
        retry_configs=torch.tensor(seeds, dtype=torch.float64),
        joint_limits=limits,
        max_iterations=200,
        pos_tolerance=1e-10,
        rot_tolerance=1e-10,
        early_stopping_any_converged=True,
    )
    target = pk.Transform3d(matrix=torch.tensor(Ts, dtype=torch.float64))
    t0 = time.perf_counter()
    sol = ik.solve(target)
    elapsed = time.perf_counter() - t0
    conv = sol.converged.numpy()
    err = (sol.err_pos + sol.err_rot).numpy()
    pick = np.where(conv.any(1), conv.argmax(1), err.argmin(1))
    q = sol.solutions.numpy()[np.arange(len(Ts)), pick]
    return dict(
        q=q,
        own_converged=float(conv.any(1).mean()),
        total_s=elapsed,
        how="PseudoInverseIK(retry_configs=seeds, max_iterations=200, tol 1e-10, "
        "early_stopping_any_converged=True), float64 chain",
    )


# ----------------------------------------------------------------------------- checks, info
def check_models(robot, pin_model, fid, rtb_robot, urdf, qs) -> dict[str, float]:
    """Largest fk difference of each peer's model from jaxkin's, over ``qs``."""
    import pinocchio as pin

    T_jk = np.asarray(jax.vmap(lambda q: jk.fk(robot, q))(jnp.asarray(qs)))
    data = pin_model.createData()
    out = {}
    d = 0.0
    for q, T in zip(qs, T_jk, strict=True):
        pin.framesForwardKinematics(pin_model, data, q)
        d = max(d, float(np.abs(data.oMf[fid].homogeneous - T).max()))
    out["pinocchio"] = d
    out["robotics_toolbox"] = max(
        float(np.abs(rtb_robot.fkine(q).A - T).max()) for q, T in zip(qs, T_jk, strict=True)
    )
    try:
        import pytorch_kinematics as pk
        import torch

        chain = pk.build_serial_chain_from_urdf(urdf.encode(), end_link_name="tool")
        chain = chain.to(dtype=torch.float64)
        m = chain.forward_kinematics(torch.tensor(qs)).get_matrix().numpy()
        out["pytorch_kinematics"] = float(np.abs(m - T_jk).max())
    except ImportError:
        pass
    return out


def _version(mod: str) -> str | None:
    try:
        from importlib.metadata import version

        return version(mod)
    except Exception:
        return None


def machine_info() -> dict[str, Any]:
    cpu = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return dict(
        cpu=cpu,
        cores=os.cpu_count(),
        python=platform.python_version(),
        platform=platform.platform(),
        versions={
            m: _version(m)
            for m in (
                "jax",
                "jaxlib",
                "numpy",
                "optax",
                "pin",
                "roboticstoolbox-python",
                "torch",
                "pytorch-kinematics",
            )
        },
        jaxkin=jk.__version__,
        jax_devices=[str(d) for d in jax.devices()],
    )


def markdown(rows: list[dict[str, Any]]) -> str:
    out = [
        "| starts | solver | success (1e-9, in limits) | success (1e-6) | own flag | total time "
        "[s] | first call [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        first = f"{r['first_call_s']:.2f}" if r.get("first_call_s") is not None else "-"
        note = (
            ""
            if r.get("measured_targets", r["n"]) >= r["n"]
            else f" (extrapolated from {r['measured_targets']})"
        )
        out.append(
            f"| {r['starts']} | {r['solver']} | {100 * r['success']:.1f}% | "
            f"{100 * r['success_loose']:.1f}% | {100 * r['own_converged']:.1f}% | "
            f"{r['total_s']:.3f}{note} | {first} |"
        )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
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
    args = ap.parse_args(argv)
    if args.quick:
        args.n, args.budget = 100, 20.0
    jax.config.update("jax_enable_x64", True)
    if args.cache is not None:
        jax.config.update("jax_compilation_cache_dir", str(args.cache))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    warnings.simplefilter("ignore", DeprecationWarning)
    gc.disable()

    robot = jk.robots.load("panda", dtype=np.float64)
    q_star = sample_within_limits(robot, args.n, TARGET_SEED)
    seeds = sample_within_limits(robot, args.seeds, START_SEED)
    Ts = np.asarray(jax.jit(jax.vmap(lambda q: jk.fk(robot, q)))(jnp.asarray(q_star)))
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    urdf = jk.to_urdf(robot)

    import pinocchio as pin
    import roboticstoolbox as rtb

    pin_model = pin.buildModelFromXML(urdf)
    fid = pin_model.getFrameId("tool")
    rtb_robot = rtb.models.DH.Panda()
    rtb_robot.tool = np.asarray(robot.tool)
    info = dict(
        benchmark="ik",
        date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        n_targets=args.n,
        starts=args.seeds,
        compilation_cache=str(args.cache) if args.cache else None,
        criteria=dict(position_m=TOL, orientation_rad=TOL, loose=LOOSE, within_limits=True),
        model_fk_max_abs_diff=check_models(robot, pin_model, fid, rtb_robot, urdf, q_star[:20]),
        machine=machine_info(),
        load_average_before=os.getloadavg(),
    )
    _log(f"models agree with jaxkin to {info['model_fk_max_abs_diff']}")
    rows = []
    for S in sorted({1, args.seeds}):
        starts = seeds[:S]
        results = {}
        _log(f"S = {S}: jaxkin")
        results["jaxkin"] = run_jaxkin(robot, Ts, starts, args.repeats)
        if "pk" not in args.skip:
            _log(f"S = {S}: pytorch_kinematics")
            results["pytorch_kinematics"] = run_pk(urdf, Ts, starts, lo, hi)
        if "rtb" not in args.skip:
            _log(f"S = {S}: Robotics Toolbox")
            results["robotics_toolbox"] = run_rtb(rtb_robot, Ts, starts, args.budget)
        if "pinocchio" not in args.skip:
            _log(f"S = {S}: Pinocchio")
            results["pinocchio"] = run_pinocchio(pin_model, fid, Ts, starts, lo, hi, args.budget)
        for name, res in results.items():
            q = res.pop("q")
            measured = res.get("measured_targets", args.n)
            verdict = Judge(robot, Ts[:measured])(q[:measured])
            total = res.pop("total_s", None) or res["steady_s"]
            row = dict(solver=name, starts=S, n=args.n, total_s=total, **verdict, **res)
            rows.append(row)
            _log(f"  {name}: {verdict['success']:.3f} success, {total:.3f} s")
    info["load_average_after"] = os.getloadavg()
    info["rows"] = rows
    out = args.out or RESULTS_DIR / ("ik_quick.json" if args.quick else "ik.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(info, indent=1, default=float))
    print(markdown(rows))
    _log(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
