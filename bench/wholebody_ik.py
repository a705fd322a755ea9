"""Whole-body inverse kinematics: success rate, time per target and compile time of ``jk.solve_ik``
with several frames on floating-base robots (issue 23 item 3).

Protocol: for each robot, N random reachable whole-body targets: the poses of the chosen frames
(``jk.fk(robot, q, frame=[...])``) at configurations drawn by ``jk.sample_configurations``
(fixed key; the floating base anywhere in [-1, 1]^3 m with any orientation, the joints uniform
within their limits). One call ``jk.solve_ik(robot, T, jk.neutral(robot), frame=[...],
throw=False)`` with default arguments solves all N. A target counts as solved when the
forward kinematics at the answer (``jk.fk``, independent of the solver's loop) puts every
frame within 1e-6 m and 1e-6 rad of its target (and, separately, when the solver reports
``converged``: residual <= 1e-10).

* ``g1``: example-robot-data's G1 (29 joints, free-flyer root): both ankles and both hands;
* ``talos``: Talos (reduced, 32 joints): both soles and both grippers;
* ``solo12``: Solo12 (12 joints): the four feet.

Also per robot: the share of targets whose first start (``q0``) converged, and of the others the
share whose first random restart converged (read from ``sol.seed``: the answer is the first
converging start in order), which is how good the restarts' rule is (``jaxkin.ik._start_fn``,
``_aligned_starts``).

Timed: the first call (trace + compile + solve) and the median of ``--repeats`` later calls
(steady state); time per target = steady / N. Prints a markdown table with the machine and the
load (``os.getloadavg``), and writes ``results/wholebody_ik.json``.

Usage: ``python3 -m bench.wholebody_ik [--n 500] [--robots g1,talos,solo12] [--repeats 2]``;
``--max-steps``, ``--damping`` pass those to ``jk.solve_ik``, ``--restart-ramp`` and
``--start-slots`` override ``jaxkin.ik``'s constants (what the solver's docstrings cite).
"""

from __future__ import annotations

import argparse
import os

import jax
import numpy as np

import jaxkin as jk

from .report import RESULTS_DIR, first_and_repeats, log, machine_info, markdown_table, write_json

ROBOTS = {
    "g1": (
        "erd/g1_29dof_rev_1_0",
        ["left_ankle_roll_link", "right_ankle_roll_link", "left_rubber_hand", "right_rubber_hand"],
    ),
    "talos": (
        "erd/talos_reduced",
        [
            "left_sole_link",
            "right_sole_link",
            "gripper_left_motor_double_link",
            "gripper_right_motor_double_link",
        ],
    ),
    "solo12": ("erd/solo12", ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]),
}
TOL_M = 1e-6
TOL_RAD = 1e-6


def frame_errors(robot, qs, T, frames):
    """Per target the largest position (m) and orientation (rad) error over the frames, by
    ``jk.fk`` at the answers."""
    Tq = np.asarray(jax.jit(jax.vmap(lambda q: jk.fk(robot, q, frame=frames)))(qs))
    ep = np.linalg.norm(Tq[..., :3, 3] - T[..., :3, 3], axis=-1).max(axis=1)
    M = np.einsum("nkij,nklj->nkil", T[..., :3, :3], Tq[..., :3, :3])  # R_t R^T
    axis = np.stack(
        [M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], -1
    )
    # atan2(sin, cos), not arccos(cos): exact near 0 (arccos loses half the digits there)
    eo = np.arctan2(np.linalg.norm(axis, axis=-1), np.trace(M, axis1=-2, axis2=-1) - 1.0)
    eo = eo.max(axis=1)
    return ep, eo


def is_solved(ep: np.ndarray, eo: np.ndarray) -> np.ndarray:
    """Per target whether every frame is within ``TOL_M`` and ``TOL_RAD`` of its target."""
    return (ep <= TOL_M) & (eo <= TOL_RAD)


def make_targets(name: str, n: int) -> tuple[jk.Robot, list[str], np.ndarray]:
    """The robot (float64, free-flyer root), its frames and (n, k, 4, 4) reachable targets: the
    frames' poses at ``n`` configurations drawn by ``jk.sample_configurations`` (fixed key)."""
    path, frames = ROBOTS[name]
    robot = jk.robots.load(path, floating_base=True, dtype=np.float64)
    qs = jk.sample_configurations(robot, n, key=2026)
    T = np.asarray(jax.jit(jax.vmap(lambda q: jk.fk(robot, q, frame=frames)))(qs))
    return robot, frames, T


def run_robot(name: str, n: int, repeats: int, **solve_args) -> dict:
    path = ROBOTS[name][0]
    robot, frames, T = make_targets(name, n)
    q0 = jk.neutral(robot)

    def solve():
        sol = jk.solve_ik(robot, T, q0, frame=frames, throw=False, **solve_args)
        jax.block_until_ready(sol.q)
        return sol

    log(f"{name}: {n} targets, {len(frames)} frames, nq = {robot.nq}, nv = {robot.nv}")
    timing = first_and_repeats(solve, repeats)
    sol = timing.pop("result")
    ep, eo = frame_errors(robot, np.asarray(sol.q), T, frames)
    solved = is_solved(ep, eo)
    steps = np.asarray(sol.steps)
    seed, conv = np.asarray(sol.seed), np.asarray(sol.converged)
    first = conv & (seed == 0)  # q0 converged
    # the answer is the first converging start in order: among the targets q0 missed, start 1
    # (the first restart) converged exactly where it is the answer
    restart = conv & (seed == 1)
    return {
        "robot": name,
        "file": path,
        "frames": frames,
        "n": n,
        "nq": robot.nq,
        "nv": robot.nv,
        "solved": float(np.mean(solved)),
        "converged": float(np.mean(np.asarray(sol.converged))),
        "results": np.bincount(np.asarray(sol.result), minlength=5).tolist(),
        "first_start_converged": float(np.mean(first)),
        "first_restart_converged": float(np.sum(restart) / max(1, np.sum(~first))),
        "steps_mean": float(np.mean(steps)),
        "steps_median": float(np.median(steps)),
        "steps_max": int(steps.max()),
        "starts_max": int(np.asarray(sol.seed).max()) + 1,
        "max_position_error_m": float(ep.max()),
        "max_orientation_error_rad": float(eo.max()),
        "first_call_s": timing["first_call_s"],
        "steady_s": timing["steady_s"],
        "per_target_ms": 1e3 * timing["steady_s"] / n,
    }


def main(argv: list[str] | None = None) -> None:
    jax.config.update("jax_enable_x64", True)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=500)
    parser.add_argument("--robots", default="g1,talos,solo12")
    parser.add_argument("--repeats", type=int, default=2)
    # what the solver's docstrings cite (defaults: the library's)
    parser.add_argument("--max-steps", type=int, default=None, help="solve_ik max_steps")
    parser.add_argument("--damping", type=float, default=None, help="solve_ik damping")
    parser.add_argument(
        "--restart-ramp", type=int, default=None, help="override jaxkin.ik.RESTART_RAMP"
    )
    parser.add_argument(
        "--start-slots", type=int, default=None, help="override jaxkin.ik.START_SLOTS"
    )
    args = parser.parse_args(argv)
    overrides = {
        k: v
        for k in ("max_steps", "damping", "restart_ramp", "start_slots")
        if (v := getattr(args, k)) is not None
    }
    for name in ("restart_ramp", "start_slots"):
        if name in overrides:  # module constants, read when the solver is traced
            setattr(jk.ik, name.upper(), overrides[name])
    solve_args = {k: overrides[k] for k in ("max_steps", "damping") if k in overrides}
    info = machine_info()
    rows = [run_robot(r, args.n, args.repeats, **solve_args) for r in args.robots.split(",")]
    load = os.getloadavg()
    header = [
        "robot (frames)",
        "targets",
        "solved (1e-6 m, rad)",
        "converged",
        "q0 converged",
        "first restart converged (of the rest)",
        "mean / median steps",
        "most starts",
        "first call (s)",
        "per target (ms)",
    ]
    table = markdown_table(
        header,
        [
            [
                f"{r['robot']} ({len(r['frames'])})",
                str(r["n"]),
                f"{100 * r['solved']:.1f}%",
                f"{100 * r['converged']:.1f}%",
                f"{100 * r['first_start_converged']:.1f}%",
                f"{100 * r['first_restart_converged']:.1f}%",
                f"{r['steps_mean']:.0f} / {r['steps_median']:.0f}",
                str(r["starts_max"]),
                f"{r['first_call_s']:.1f}",
                f"{r['per_target_ms']:.2f}",
            ]
            for r in rows
        ],
        "lrrrrrrrrr",
    )
    cpu = ", ".join(info["cpu_model"])
    what = f"overrides {overrides}" if overrides else "default arguments"
    print(
        f"jk.solve_ik, whole body, {what}, from jk.neutral, float64 ({cpu}, "
        f"{info['cpus_usable']} CPUs; load {load[0]:.1f} {load[1]:.1f} {load[2]:.1f})\n"
    )
    print(table)
    # the committed results are the defaults' run; a run with overrides is written beside them
    name = "wholebody_ik_overrides.json" if overrides else "wholebody_ik.json"
    result = {"machine": info, "load": load, "overrides": overrides, "rows": rows}
    write_json(RESULTS_DIR / name, result)


if __name__ == "__main__":
    main()
