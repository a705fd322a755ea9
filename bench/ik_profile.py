"""Where the time of a batched ``jk.solve_ik`` goes (bench/IK.md, "Where the time per target goes").

For the Panda and the UR5: 10,000 random reachable targets (``jk.sample_configurations`` ->
``jk.fk``), one start at the middle of the limits, default arguments, float64, one jitted call.
Prints the steady time per target, the distribution of solver steps per target and the share of
targets (and of steps) that needed restarts, both from the solution's own ``steps`` and ``seed``
fields; the wall time per lane-step if every lane were busy; and, for scale, the time of a batched
pose + Jacobian (``frame_jacobian``) per configuration on as many configurations as the solver
has lanes.

``--trace`` also records one solve with JAX's profiler (a Perfetto trace in a temporary
directory) and prints, per iteration of the solver's loop (the count shared by most kernels),
the number of compiled kernels (thunks) run, their summed time and the largest of them.

Usage: ``python3 -m bench.ik_profile [--n N] [--trace]``.
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk
from jaxkin import ik as ik_module

from .ik_harness import ROBOTS, random_targets, sampling_middle

PROFILED = ("panda", "ur5")


def problem(name: str, n: int):
    """``(robot, qs, T, solve)``: n random reachable targets and the jitted default solve from
    the middle of the limits, compiled (one call made)."""
    robot = ROBOTS[name]()
    qs, T = random_targets(robot, n, jax.random.key(0))
    q0 = sampling_middle(robot)
    solve = jax.jit(lambda T: jk.solve_ik(robot, T, q0, throw=False))
    jax.block_until_ready(solve(T))
    return robot, qs, T, solve


def profile(name: str, n: int) -> str:
    robot, qs, T, solve = problem(name, n)
    sol = jax.block_until_ready(solve(T))
    times = []
    for _ in range(3):
        t = time.perf_counter()
        sol = jax.block_until_ready(solve(T))
        times.append(time.perf_counter() - t)
    total = min(times)
    steps, seeds = np.asarray(sol.steps), np.asarray(sol.seed)
    lanes = ik_module._lanes(n)
    jac = jax.jit(jax.vmap(lambda q: jk.jacobians.frame_jacobian(robot, q)))
    Q = jnp.asarray(np.asarray(qs)[:lanes])
    jax.block_until_ready(jac(Q))
    t = time.perf_counter()
    for _ in range(50):
        jax.block_until_ready(jac(Q))
    per_config = (time.perf_counter() - t) / 50 / lanes
    restarted = seeds > 0
    return (
        f"{name}: {n} targets in {total * 1e3:.0f} ms = {total / n * 1e6:.0f} us per target; "
        f"{lanes} lanes; steps per target mean {steps.mean():.1f}, median {np.median(steps):.0f}, "
        f"p99 {np.percentile(steps, 99):.0f}, max {steps.max()} (steps of abandoned parallel "
        f"starts included); the work would fill {steps.sum() / lanes:.0f} iterations of all "
        f"lanes; targets restarted "
        f"{100 * restarted.mean():.1f}%, their share of the steps "
        f"{100 * steps[restarted].sum() / steps.sum():.0f}%; wall time per lane-step if every "
        f"lane were busy {total / steps.sum() * 1e6:.2f} us; pose + Jacobian alone "
        f"{per_config * 1e6:.2f} us per configuration; load average {os.getloadavg()[0]:.1f}"
    )


def kernels(name: str, n: int) -> str:
    """Kernels per loop iteration of one traced solve (see the module doc)."""
    _, _, T, solve = problem(name, n)
    with tempfile.TemporaryDirectory() as d:
        jax.profiler.start_trace(d, create_perfetto_trace=True)
        jax.block_until_ready(solve(T))
        jax.profiler.stop_trace()
        (path,) = glob.glob(os.path.join(d, "**", "*.trace.json.gz"), recursive=True)
        with gzip.open(path) as f:
            events = [e for e in json.load(f)["traceEvents"] if e.get("ph") == "X"]
    total: collections.Counter[str] = collections.Counter()
    count: collections.Counter[str] = collections.Counter()
    for e in events:
        if not e["name"].startswith(("Thunk", "$", "end: ")):
            total[e["name"]] += e["dur"]
            count[e["name"]] += 1
    iters = collections.Counter(count.values()).most_common(1)[0][0]
    loop = {k: v / iters for k, v in total.items() if count[k] == iters}
    trig = sum(v for k, v in loop.items() if "sine" in k or "cosine" in k)
    top = ", ".join(f"{k} {v:.0f}" for k, v in sorted(loop.items(), key=lambda kv: -kv[1])[:6])
    return (
        f"{name}: {iters} loop iterations; per iteration {len(loop)} kernels, "
        f"{sum(loop.values()):.0f} us of kernel time (summed over threads), of which sin/cos "
        f"kernels {trig:.0f} us; largest (us): {top}"
    )


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=10_000)
    p.add_argument("--trace", action="store_true", help="kernels per loop iteration")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    for name in PROFILED:
        print(profile(name, args.n), flush=True)
    if args.trace:
        for name in PROFILED:
            print(kernels(name, args.n), flush=True)


if __name__ == "__main__":
    main()
