"""Where the scan path's time goes: the 32-joint chain's Jacobian against ``lax.scan`` loops of the
same shape doing next to nothing (issue 24, the chain's row).

The chain (``bench.peers.chain_robot``) runs through :func:`jaxkin._forward.scan_steps`: one
``lax.scan`` step per joint (33: the fixed tip joint is one), a carry of 12 scalars (the pose)
and 6 stacked outputs per step (the joint's axis and origin, from which the columns are formed
after the loop). Under ``jax.vmap`` each scalar is an (N,) array. Timed per loop step, one
``jit(vmap)`` call of N configurations (default 4,096; the results stay under glibc's 32 MiB,
so no page faults):

* the Jacobian (``jk.geometric_jacobian``), as ``jax.vmap`` lays it out (N, 6, 32) and batch
  last (``out_axes=-1``: (6, 32, N), each entry a contiguous row over the batch, as the scan's
  stacked axes and origins are), and the forward kinematics of the tip (``jk.fk``);
* a loop with the same carry and no outputs (each step ``c * 1.0001 + t`` per entry), and with
  6 and 12 stacked outputs: the floor of the loop structure, and what writing the per-joint
  outputs costs by itself.

Usage: ``python3 -m bench.scan_profile [--n 4096] [--repeats 100]``; prints a markdown table.
"""

from __future__ import annotations

import argparse
import os
import time

import jax
import jax.numpy as jnp

import jaxkin as jk

from .peers import chain_robot
from .report import machine_info, markdown_table


def per_call_s(fn, x, repeats: int) -> float:
    """The best of three means over ``repeats`` calls (compiled by a first call)."""
    jax.block_until_ready(fn(x))
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        for _ in range(repeats):
            out = fn(x)
        jax.block_until_ready(out)
        best = min(best, (time.perf_counter() - t) / repeats)
    return best


def bare_loop(steps: int, outputs: int):
    """``q -> lax.scan`` over ``steps`` with a 12-scalar carry and ``outputs`` stacked outputs,
    each step one multiply-add per entry."""
    ts = jnp.linspace(0.0, 1.0, steps)

    def f(q):
        def step(c, t):
            c = tuple(ci * 1.0001 + t for ci in c)
            return c, c[:outputs]

        return jax.lax.scan(step, (q,) * 12, ts)

    return f


def main(argv: list[str] | None = None) -> None:
    jax.config.update("jax_enable_x64", True)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=100)
    args = parser.parse_args(argv)
    robot = chain_robot()
    steps = len(robot.ancestors(robot.tip_frame))  # one per joint on the tip's path
    q = jk.sample_configurations(robot, args.n, key=0)
    jac = lambda x: jk.geometric_jacobian(robot, x)  # noqa: E731
    cases = [
        ("chain32 Jacobian, (N, 6, 32)", jax.vmap(jac), q),
        ("chain32 Jacobian, (6, 32, N): the same, batch last", jax.vmap(jac, out_axes=-1), q),
        ("chain32 forward kinematics (tip)", jax.vmap(lambda x: jk.fk(robot, x)), q),
    ]
    scalar = q[:, 0]
    for outputs in (0, 6, 12):
        f = jax.vmap(bare_loop(steps, outputs))
        cases.append((f"bare loop, {outputs} stacked outputs", f, scalar))
    lines = []
    for label, f, x in cases:
        s = per_call_s(jax.jit(f), x, args.repeats)
        lines.append([label, f"{s * 1e6:.0f}", f"{s / steps * 1e6:.1f}", f"{s / args.n * 1e9:.0f}"])
    info = machine_info()
    load = os.getloadavg()
    print(
        f"{steps} loop steps, N = {args.n:,}, float64, one jit(vmap) call "
        f"({', '.join(info['cpu_model'])}, {info['cpus_usable']} CPUs; load "
        f"{load[0]:.1f} {load[1]:.1f} {load[2]:.1f})\n"
    )
    header = ["kernel", "us per call", "us per step", "ns per configuration"]
    print(markdown_table(header, lines, "lrrr"))


if __name__ == "__main__":
    main()
