"""Whole-body inverse kinematics against a peer: pink (Pinocchio-based task IK) on the same targets
as ``bench/wholebody_ik.py`` (issue 23 item 6).

Protocol: the targets and the judge are ``bench/wholebody_ik.py``'s (``make_targets``,
``frame_errors``, ``is_solved``): N reachable four-frame targets per robot, a target solved when
``jk.fk`` at the answer puts every frame within 1e-6 m and 1e-6 rad of its target.

pink, one target at a time, the way its examples do: a ``FrameTask`` per frame (position and
orientation cost 1), a ``PostureTask`` (target the start; one row per cost in
``--posture-cost``: 1e-3 as in pink's examples, and 1e-6), from
Pinocchio's neutral configuration (``pin.neutral``: free-flyer at the origin, joints at 0, clipped
into the joint limits where 0 lies outside them so that pink's limit check accepts it); each step
``pink.solve_ik(configuration, tasks, dt, solver=...)`` with pink's default limits (joint position
and velocity) then ``configuration.integrate_inplace(velocity, dt)``, up to ``--steps`` steps or
until every frame is within the tolerance (checked on Pinocchio's frame placements, part of the
timed loop). The answer is mapped from Pinocchio's q (x, y, z, qx, qy, qz, qw, joints in
Pinocchio's order) to jaxkin's (x, y, z, qw, qx, qy, qz, joints in ``robot.joint_names`` order) and
judged by the same jaxkin judge. ``dt`` (default 0.1 s) only matters through the velocity limits
(a step moves a joint at most ``v_max * dt``); with gain 1 an unconstrained step is a full
Gauss-Newton step whatever ``dt``. The posture term biases the fixed point: a frame error of
about posture cost x the posture error remains (1.4e-5 on a G1 target at cost 1e-3, 1e-11 at
1e-6), so at pink's example cost 1e-3 few targets meet 1e-6 m / 1e-6 rad.

jaxkin's row is ``bench.wholebody_ik.run_robot`` in the same run: one batched
``jk.solve_ik`` call, default arguments from ``jk.neutral``, time per target = steady-state call /
N (compile time apart, in its own column).

Usage: ``python3 -m bench.wholebody_ik_peers [--n 50] [--robots g1,talos,solo12]``.
"""

from __future__ import annotations

import argparse
import os
import time

import jax
import numpy as np

from jaxkin.robots import example_robot_data as erd

from .report import RESULTS_DIR, log, machine_info, markdown_table, version, write_json
from .wholebody import pinocchio_order
from .wholebody_ik import (
    ROBOTS,
    TOL_M,
    TOL_RAD,
    frame_errors,
    is_solved,
    make_targets,
    run_robot,
)


def pink_start(model) -> np.ndarray:
    """Pinocchio's neutral configuration, clipped into the finite joint limits."""
    import pinocchio as pin

    q = pin.neutral(model)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    finite = (lo > -1e300) & (hi < 1e300)
    q[finite] = np.clip(q[finite], lo[finite], hi[finite])
    return q


def within_tolerance(configuration, frames: list[str], targets: list) -> bool:
    """Whether every frame's placement (Pinocchio's) is within the tolerance of its target."""
    import pinocchio as pin

    for f, t in zip(frames, targets, strict=True):
        cur = configuration.get_transform_frame_to_world(f)
        if np.linalg.norm(cur.translation - t.translation) > TOL_M:
            return False
        if np.linalg.norm(pin.log3(t.rotation @ cur.rotation.T)) > TOL_RAD:
            return False
    return True


def pink_solve(model, frames, Tk, q_start, args, posture_cost: float) -> tuple[np.ndarray, int]:
    """One target (k, 4, 4) with pink's differential IK: the final q (Pinocchio's order) and the
    number of steps taken."""
    import pink
    import pinocchio as pin

    configuration = pink.Configuration(model, model.createData(), q_start.copy())
    tasks = []
    targets = [pin.SE3(T[:3, :3].copy(), T[:3, 3].copy()) for T in Tk]
    for f, t in zip(frames, targets, strict=True):
        task = pink.tasks.FrameTask(f, position_cost=1.0, orientation_cost=1.0)
        task.set_target(t)
        tasks.append(task)
    posture = pink.tasks.PostureTask(cost=posture_cost)
    posture.set_target_from_configuration(configuration)
    tasks.append(posture)
    steps = 0
    while steps < args.steps and not within_tolerance(configuration, frames, targets):
        velocity = pink.solve_ik(configuration, tasks, args.dt, solver=args.solver)
        configuration.integrate_inplace(velocity, args.dt)
        steps += 1
    return configuration.q.copy(), steps


def run_pink(name: str, n: int, args, posture_cost: float) -> dict:
    import pinocchio as pin

    path = ROBOTS[name][0]
    robot, frames, T = make_targets(name, n)
    model = pin.buildModelFromUrdf(str(erd.path(path)), pin.JointModelFreeFlyer())
    q_src, _ = pinocchio_order(robot, model)
    q_start = pink_start(model)
    qp = np.zeros((n, model.nq))
    steps = np.zeros(n, dtype=int)
    failed = 0
    t0 = time.perf_counter()
    for i in range(n):
        try:
            qp[i], steps[i] = pink_solve(model, frames, T[i], q_start, args, posture_cost)
        except Exception as e:  # a QP the backend reports infeasible, a limit violated
            log(f"pink {name} target {i}: {type(e).__name__}: {e}")
            qp[i], steps[i], failed = q_start, args.steps, failed + 1
    elapsed = time.perf_counter() - t0
    qs = np.zeros((n, robot.nq))
    qs[:, q_src] = qp  # Pinocchio's order into jaxkin's
    ep, eo = frame_errors(robot, qs, T, frames)
    solved = is_solved(ep, eo)
    log(
        f"pink {name} (posture {posture_cost:g}): solved {solved.mean():.1%}, "
        f"{elapsed / n * 1e3:.1f} ms per target"
    )
    return {
        "robot": name,
        "posture_cost": posture_cost,
        "n": n,
        "solved": float(np.mean(solved)),
        "exceptions": failed,
        "steps_median": float(np.median(steps)),
        "max_position_error_m": float(ep.max()),
        "max_orientation_error_rad": float(eo.max()),
        "per_target_ms": 1e3 * elapsed / n,
    }


def table(pairs: list[tuple[dict, list[dict]]], args) -> str:
    header = [
        "robot",
        "targets",
        "solver",
        "solved (1e-6 m, rad)",
        "median iterations",
        "most starts",
        "per target (ms)",
        "compile (s)",
    ]
    rows = []
    for jk_row, pink_rows in pairs:
        rows.append(
            [
                jk_row["robot"],
                str(jk_row["n"]),
                "jaxkin (batched)",
                f"{100 * jk_row['solved']:.1f}%",
                f"{jk_row['steps_median']:.0f}",
                str(jk_row["starts_max"]),
                f"{jk_row['per_target_ms']:.2f}",
                f"{jk_row['first_call_s']:.1f}",
            ]
        )
        rows += [
            [
                r["robot"],
                str(r["n"]),
                f"pink ({args.solver}, posture {r['posture_cost']:g})",
                f"{100 * r['solved']:.1f}%",
                f"{r['steps_median']:.0f}",
                "1",
                f"{r['per_target_ms']:.2f}",
                "-",
            ]
            for r in pink_rows
        ]
    return markdown_table(header, rows, "lllrrrrr")


def main(argv: list[str] | None = None) -> None:
    jax.config.update("jax_enable_x64", True)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=50)
    parser.add_argument("--robots", default="g1,talos,solo12")
    parser.add_argument("--repeats", type=int, default=2, help="jaxkin's steady-state calls")
    parser.add_argument("--steps", type=int, default=200, help="pink's most steps per target")
    parser.add_argument("--dt", type=float, default=0.1, help="pink's step duration (s)")
    parser.add_argument("--posture-cost", default="1e-3,1e-6", help="pink's posture costs")
    parser.add_argument("--solver", default="daqp", help="qpsolvers backend for pink")
    args = parser.parse_args(argv)
    info = machine_info()
    costs = [float(c) for c in args.posture_cost.split(",")]
    pairs = []
    for name in args.robots.split(","):
        ours = run_robot(name, args.n, args.repeats)
        pairs.append((ours, [run_pink(name, args.n, args, c) for c in costs]))
    load = os.getloadavg()
    cpu = ", ".join(info["cpu_model"])
    print(
        f"Whole-body IK, same targets and judge as bench/wholebody_ik.py; "
        f"jaxkin {version('jaxkin')} vs pink {version('pin-pink')} (dt {args.dt}, "
        f"at most {args.steps} steps), float64 ({cpu}, {info['cpus_usable']} CPUs; "
        f"load {load[0]:.1f} {load[1]:.1f} {load[2]:.1f})\n"
    )
    print(table(pairs, args))
    write_json(
        RESULTS_DIR / "wholebody_ik_peers.json",
        {
            "machine": info,
            "load": load,
            "pink": {"dt": args.dt, "steps": args.steps, "solver": args.solver},
            "rows": [{"jaxkin": a, "pink": b} for a, b in pairs],
        },
    )


if __name__ == "__main__":
    main()
