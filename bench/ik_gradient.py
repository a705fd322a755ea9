"""Cost of differentiating ``jk.solve_ik`` (implicit function theorem) against the solve itself.

For each arm: N random reachable targets (``jk.sample_configurations`` -> ``jk.fk``, fixed key),
one start at the middle of the limits, default arguments, float64, all targets in one jitted
call. Timed (steady state: median of repeats after a first call that compiles):

* ``solve``: ``solve_ik(robot, T, q0).q``;
* ``jvp``: ``jax.jvp`` of the same with one tangent ``T_dot`` per target (solve + dq);
* ``grad``: ``jax.grad`` of ``sum(w * q)`` with respect to the targets (solve + the transposed
  rule);
* ``jacobian``: every target's full ``dq/dT`` (dof x 4 x 4): ``jax.jvp`` vmapped over the 16
  unit tangents (the primal solve is not batched, so it runs once).

The ratios are each row's time over ``solve`` (the issue's target: <= 2x). The derivative rule
is the same whatever the solver did, so the ratio falls as targets get harder.

Usage: ``python3 -m bench.ik_gradient [--n N] [--robots panda,ur5,niryo_one] [--repeats R]
[--write-md]``; prints a markdown table with the machine and the load (``os.getloadavg``), writes
``results/ik_gradient.json`` and, with ``--write-md``, the gradient section of ``IK.md``.
"""

from __future__ import annotations

import argparse
import os

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk

from .ik_harness import ROBOTS, random_targets, sampling_middle
from .report import (
    RESULTS_DIR,
    first_and_repeats,
    log,
    machine_info,
    markdown_table,
    replace_section,
    utc_now,
    write_json,
)


def _cases(robot: jk.Robot, n: int):
    _, T = random_targets(robot, n, jax.random.key(1))
    q0 = sampling_middle(robot)
    X = jnp.zeros((n, 4, 4)).at[:, 0, 3].set(1.0).at[:, 1, 2].set(-1.0).at[:, 2, 1].set(1.0)
    T_dot = T @ X  # move along x and turn about x in the target's own axes
    w = jax.random.normal(jax.random.key(2), (n, robot.dof))
    return T, q0, T_dot, w


def measure(name: str, n: int, repeats: int) -> dict:
    robot = ROBOTS[name]()
    T, q0, T_dot, w = _cases(robot, n)

    def q_of(T):
        return jk.solve_ik(robot, T, q0, throw=False).q

    solve = jax.jit(q_of)
    jvp = jax.jit(lambda T, Td: jax.jvp(q_of, (T,), (Td,)))
    grad = jax.jit(jax.grad(lambda T: jnp.sum(w * q_of(T))))
    basis = jnp.eye(16, dtype=T.dtype).reshape(16, 1, 4, 4)  # d/dT_ab, the same for every target

    @jax.jit
    def jac(T):  # (16, N, dof): the solve runs once, the rule 16 times
        return jax.vmap(lambda E: jax.jvp(q_of, (T,), (jnp.broadcast_to(E, T.shape),))[1])(basis)

    rows = {}
    for label, fn in (
        ("solve", lambda: solve(T)),
        ("jvp", lambda: jvp(T, T_dot)),
        ("grad", lambda: grad(T)),
        ("jacobian", lambda: jac(T)),
    ):
        log(f"{name}: {label}")
        r = first_and_repeats(lambda fn=fn: jax.block_until_ready(fn()), repeats)
        rows[label] = r
        assert np.all(np.isfinite(np.asarray(jax.tree_util.tree_leaves(r["result"])[0])))
    sol = jk.solve_ik(robot, T, q0, throw=False)
    rows["converged"] = float(np.mean(np.asarray(sol.converged)))
    return rows


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--robots", default="panda,ur5,niryo_one")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--write-md", action="store_true", help="update the gradient section of IK.md")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    load0 = os.getloadavg()
    table, raw = [], {}
    for name in args.robots.split(","):
        r = measure(name, args.n, args.repeats)
        raw[name] = {k: v if k == "converged" else _numbers(v) for k, v in r.items()}
        base = r["solve"]["steady_s"]
        for label in ("solve", "jvp", "grad", "jacobian"):
            t = r[label]["steady_s"]
            table.append(
                [
                    name,
                    label,
                    f"{r[label]['first_call_s']:.1f}",
                    f"{t * 1e3:.1f}",
                    f"{t / args.n * 1e6:.1f}",
                    f"{t / base:.2f}x",
                    f"{100 * r['converged']:.1f}%",
                ]
            )
    load1 = os.getloadavg()
    info = machine_info()
    header = ["robot", "what", "first call (s)", "steady (ms)", "per target (us)", "vs solve"]
    text = (
        f"`python3 -m bench.ik_gradient`: jk.solve_ik derivatives, {args.n:,} targets per arm, "
        f"float64, {utc_now()}; jax {info['jax']}, jaxkin {info['jaxkin']}; "
        f"{info['cpu_model'][0]}, {info['cpus_usable']} usable cores; load average (1 min) "
        f"{load0[0]:.1f} before, {load1[0]:.1f} after.\n\n"
        + markdown_table([*header, "converged"], table, align="llrrrrr")
    )
    print(text)
    write_json(
        RESULTS_DIR / "ik_gradient.json",
        dict(n=args.n, machine=info, load_before=load0, load_after=load1, rows=raw),
    )
    if args.write_md:
        here = RESULTS_DIR.parent
        replace_section(here / "IK.md", text, "<!-- gradient:start -->", "<!-- gradient:end -->")


def _numbers(row: dict) -> dict:
    """The JSON-able part of a :func:`first_and_repeats` result (the arrays dropped)."""
    return {k: v for k, v in row.items() if k != "result"}


if __name__ == "__main__":
    main()
