"""Whole-body kinematics against Pinocchio: centre of mass, its Jacobian and several frames'
Jacobians of free-flyer humanoids, batched (issue 23 item 6).

For each robot (example-robot-data's G1 and Talos, free-flyer root) and each quantity, N random
configurations (numpy, fixed seed; the free joint anywhere in [-1, 1]^3 m with any orientation,
the joints uniform within their limits) are computed by

* jaxkin: ``jax.jit(jax.vmap(f))`` over the (N, nq) array, ``f`` one of ``jk.center_of_mass``,
  ``jk.com_jacobian`` and ``jk.geometric_jacobian(robot, q, frame=[four frames])`` (world-aligned);
  the first call (trace + compile + run) is timed apart from the steady state;
* Pinocchio from Python, the way a user who wants the N answers in an array writes it: pre-built
  q arrays in Pinocchio's order (``bench.peers.PinocchioLayout``), one ``centerOfMass`` /
  ``jacobianCenterOfMass`` per configuration, or ``computeJointJacobians`` +
  ``updateFramePlacements`` + one ``getFrameJacobian`` (``LOCAL_WORLD_ALIGNED``) per frame, each
  result stored into a preallocated array.

Rounds alternate (jaxkin, Pinocchio, jaxkin, ...); each rate is the median of ``--repeats``
rounds. Every jaxkin answer is compared with Pinocchio's (largest difference printed; the
columns mapped to Pinocchio's velocity order), so the table also checks the numbers.

Usage: ``python3 -m bench.wholebody [--n 10000] [--robots g1,talos] [--repeats 5]``. Prints a
markdown table with the machine and its load (``os.getloadavg``); writes
``results/wholebody.json``.
"""

from __future__ import annotations

import argparse
import functools
import os

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk
from jaxkin.robots import example_robot_data as erd

from .peers import PinocchioLayout
from .report import (
    RESULTS_DIR,
    fmt_rate,
    log,
    machine_info,
    markdown_table,
    median,
    timed,
    write_json,
)
from .wholebody_ik import ROBOTS


def random_q(robot: jk.Robot, n: int, seed: int = 0) -> np.ndarray:
    """(n, nq) configurations within the limits; free joints: position in [-1, 1]^3, a uniformly
    random unit quaternion."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(np.asarray(robot.lower, dtype=float), -np.pi)
    hi = np.minimum(np.asarray(robot.upper, dtype=float), np.pi)
    Q = rng.uniform(lo, hi, (n, robot.nq))
    for j in robot.multi_dof_joints:
        qi = robot.q_index[j]
        Q[:, qi : qi + 3] = rng.uniform(-1.0, 1.0, (n, 3))
        g = rng.normal(size=(n, 4))
        Q[:, qi + 3 : qi + 7] = g / np.linalg.norm(g, axis=1, keepdims=True)
    return Q


def pinocchio_order(robot: jk.Robot, model) -> tuple[np.ndarray, np.ndarray]:
    """For each Pinocchio q entry the jaxkin q index, for each v entry the jaxkin v index
    (``bench.peers.PinocchioLayout``'s ``q_src`` and ``v_src``)."""
    layout = PinocchioLayout(robot, model)
    return layout.q_src, layout.v_src


def pinocchio_runners(model, frames: list[str], qp: np.ndarray) -> dict:
    """Per quantity a function computing all N answers with Pinocchio into a preallocated array
    (in Pinocchio's velocity order)."""
    import pinocchio as pin

    data = model.createData()
    n = qp.shape[0]
    ids = [model.getFrameId(f) for f in frames]
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    def com():
        out = np.empty((n, 3))
        for i in range(n):
            out[i] = pin.centerOfMass(model, data, qp[i])
        return out

    def com_jacobian():
        out = np.empty((n, 3, model.nv))
        for i in range(n):
            out[i] = pin.jacobianCenterOfMass(model, data, qp[i])
        return out

    def frames_jacobian():
        out = np.empty((n, len(ids), 6, model.nv))
        for i in range(n):
            pin.computeJointJacobians(model, data, qp[i])
            pin.updateFramePlacements(model, data)
            for k, fid in enumerate(ids):
                out[i, k] = pin.getFrameJacobian(model, data, fid, lwa)
        return out

    return {
        "centre of mass": com,
        "CoM Jacobian": com_jacobian,
        "4 frames' Jacobians": frames_jacobian,
    }


def jaxkin_kernels(robot: jk.Robot, frames: list[str]) -> dict:
    return {
        "centre of mass": lambda q: jk.center_of_mass(robot, q),
        "CoM Jacobian": lambda q: jk.com_jacobian(robot, q),
        "4 frames' Jacobians": lambda q: jk.geometric_jacobian(robot, q, frame=frames),
    }


def batched(fn, Q):
    """All N answers of the jitted batch, computed (blocks until they are)."""
    return jax.block_until_ready(fn(Q))


def measure(name: str, n: int, repeats: int) -> list[dict]:
    import pinocchio as pin

    path, frames = ROBOTS[name]
    file = erd.path(path)
    robot = jk.load_urdf(file, floating_base=True, dtype=np.float64)
    model = pin.buildModelFromUrdf(str(file), pin.JointModelFreeFlyer())
    Q = random_q(robot, n, seed=7)
    layout = PinocchioLayout(robot, model)
    qp = layout.q(Q)
    peers = pinocchio_runners(model, frames, qp)
    rows = []
    for quantity, kernel in jaxkin_kernels(robot, frames).items():
        run = functools.partial(batched, jax.jit(jax.vmap(kernel)), jnp.asarray(Q))
        out, first = timed(run)
        ours, theirs = [], []
        for _ in range(repeats):
            out, t = timed(run)
            ours.append(t)
            ref, t = timed(peers[quantity])
            theirs.append(t)
        mine = np.asarray(out)
        if mine.shape[-1] == robot.nv:  # Jacobian columns into Pinocchio's velocity order
            mine = layout.columns_to_pinocchio(mine)
        diff = float(np.max(np.abs(mine - ref)))
        rows.append(
            dict(
                robot=name,
                nv=robot.nv,
                quantity=quantity,
                n=n,
                jaxkin_rate=n / median(ours),
                pinocchio_rate=n / median(theirs),
                first_call_s=first,
                max_abs_diff=diff,
            )
        )
        r = rows[-1]
        log(f"{name} {quantity}: {r['jaxkin_rate']:.0f}/s vs {r['pinocchio_rate']:.0f}/s")
    return rows


def table(rows: list[dict]) -> str:
    body = [
        (
            f"{r['robot']} (nv = {r['nv']})",
            r["quantity"],
            f"{fmt_rate(r['jaxkin_rate'])}/s",
            f"{fmt_rate(r['pinocchio_rate'])}/s",
            f"{r['jaxkin_rate'] / r['pinocchio_rate']:.2f}x",
            f"{r['first_call_s']:.2f} s",
            f"{r['max_abs_diff']:.1e}",
        )
        for r in rows
    ]
    header = (
        "robot",
        "quantity",
        "jaxkin jit(vmap)",
        "Pinocchio loop",
        "ratio",
        "first call",
        "largest difference",
    )
    return markdown_table(header, body, "llrrrrr")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=10_000)
    parser.add_argument("--robots", default="g1,talos")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    rows = [r for name in args.robots.split(",") for r in measure(name, args.n, args.repeats)]
    info = machine_info()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"Whole-body kinematics, float64, N = {args.n:,} (load average {load})\n")
    print(table(rows))
    write_json(RESULTS_DIR / "wholebody.json", dict(machine=info, rows=rows))


if __name__ == "__main__":
    main()
