"""A long whole-body motion retargeted in bounded memory: ``jk.motion.retarget`` on a humanoid.

``python3 -m bench.motion`` builds ``--steps`` (default 100,000) time steps of a four-frame
target (both feet and both hands of example-robot-data's G1, ``--robot`` for another) from the
forward kinematics of a smooth random joint trajectory (the floating base moving too, joints
clipped to their limits, 100 Hz), written chunk by chunk to ``.npy`` files by
``jaxkin.batch.chunked_map``. It then retargets the whole sequence from the first step's
configuration (the posture term pulling toward it, default weight), reading the targets
through ``np.load(..., mmap_mode="r")`` and writing the per-step results (``q``, residuals,
codes...) to a directory of ``.npy`` files chunk by chunk (``jaxkin.batch.chunked_scan``), with
a progress bar, and reports the time per step (compile
excluded), the iterations, the share of converged steps, the largest residual, and the peak
memory: the process's peak resident set (``resource.getrusage``, JAX and XLA included) and the
peak of Python-side allocations during the retargeting (``tracemalloc``, numpy buffers
included). Files are deleted at the end (``--keep`` keeps them).
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk
from jaxkin import motion
from jaxkin.batch import chunked_map

G1 = "erd/g1_29dof_rev_1_0"
FRAMES = {
    G1: ["left_ankle_roll_link", "right_ankle_roll_link", "left_rubber_hand", "right_rubber_hand"],
    "erd/talos_reduced": [
        "left_sole_link",
        "right_sole_link",
        "gripper_left_base_link",
        "gripper_right_base_link",
    ],
}
FREQUENCIES = (0.5, 1.1, 1.7, 2.3)  # rad/s of the trajectory's velocity components


def peak_rss_mb() -> float:
    """Peak resident set of this process so far, in MiB (Linux reports KiB)."""
    kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kib / 1024 if sys.platform != "darwin" else kib / 2**20


def source_motion(robot: jk.Robot, frames: list[str], steps: int, dt: float, seed: int, work):
    """``(q.npy, T.npy)`` paths: the smooth trajectory ``q(t) = integrate(neutral, v(t))`` with
    ``v(t) = sum_i sin(w_i t) V_i`` (random ``V``, joints clipped to their limits) and the
    frames' poses at each step, written chunk by chunk."""
    V = np.random.default_rng(seed).normal(size=(len(FREQUENCIES), robot.nv)) * 0.3
    V = jnp.asarray(V, robot.dtype)
    w = jnp.asarray(FREQUENCIES, robot.dtype)
    q0 = jk.neutral(robot)
    lo, hi = robot.lower, robot.upper

    def row(t):
        q = jnp.clip(jk.integrate(robot, q0, jnp.sin(w * t) @ V), lo, hi)
        return {"q": q, "T": jk.fk(robot, q, frame=frames)}

    times = np.arange(steps, dtype=np.dtype(robot.dtype)) * dt
    out = chunked_map(row, times, chunk_size=8192, out=work / "source")
    return Path(out) / "q.npy", Path(out) / "T.npy"


def run(args: argparse.Namespace) -> dict[str, Any]:
    if args.dtype == "float64":
        jax.config.update("jax_enable_x64", True)
    robot = jk.robots.load(args.robot, floating_base=True, dtype=np.dtype(args.dtype))
    frames = FRAMES.get(args.robot) or list(args.frames)
    work = Path(tempfile.mkdtemp(prefix="jaxkin-motion-", dir=args.dir))
    info: dict[str, Any] = dict(
        robot=args.robot,
        nq=robot.nq,
        frames=frames,
        steps=args.steps,
        dtype=args.dtype,
        chunk_size=args.chunk,
        load_average_1min=os.getloadavg()[0],
    )
    try:
        t0 = time.perf_counter()
        q_path, T_path = source_motion(robot, frames, args.steps, 0.01, args.seed, work)
        info["targets_s"] = time.perf_counter() - t0
        T = np.load(T_path, mmap_mode="r")
        q_first = np.load(q_path, mmap_mode="r")[0].copy()
        info["rss_mb_before"] = peak_rss_mb()
        tracemalloc.start()
        t0 = time.perf_counter()
        out, stats = motion.retarget(
            robot,
            T,
            q_first,
            frames,
            posture=q_first,
            chunk_size=args.chunk,
            progress=not args.quiet,
            out=work / "motion",
            return_stats=True,
        )
        info["retarget_wall_s"] = time.perf_counter() - t0
        info["tracemalloc_peak_mb"] = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
        info["peak_rss_mb"] = peak_rss_mb()
        info["compile_s"] = stats.compile_seconds
        info["run_s"] = stats.run_seconds
        info["us_per_step"] = stats.run_seconds / args.steps * 1e6
        res = {
            k: np.load(Path(out) / f"{k}.npy", mmap_mode="r")
            for k in ("converged", "residual", "iterations", "position_error", "orientation_error")
        }
        info["converged_share"] = float(np.mean(res["converged"]))
        info["max_residual"] = float(np.nanmax(res["residual"]))
        info["max_position_error_m"] = float(np.nanmax(res["position_error"]))
        info["max_orientation_error_rad"] = float(np.nanmax(res["orientation_error"]))
        info["mean_iterations"] = float(np.mean(res["iterations"]))
        info["max_iterations"] = int(np.max(res["iterations"]))
        info["out_bytes"] = sum(p.stat().st_size for p in Path(out).iterdir())
    finally:
        if args.keep:
            info["kept"] = str(work)
        else:
            shutil.rmtree(work, ignore_errors=True)
    return info


def summary(info: dict[str, Any]) -> str:
    return "\n".join(
        [
            f"jk.motion.retarget: {info['steps']:,} steps of {len(info['frames'])} frames "
            f"({', '.join(info['frames'])}) of {info['robot']} (nq={info['nq']}), {info['dtype']}, "
            f"chunks of {info['chunk_size']:,} steps (load average at start "
            f"{info['load_average_1min']:.1f})",
            f"  targets (fk of a smooth random trajectory, to disk): {info['targets_s']:.1f} s",
            f"  compile {info['compile_s']:.1f} s, run {info['run_s']:.1f} s: "
            f"{info['us_per_step']:.0f} us per step, {info['mean_iterations']:.2f} iterations "
            f"per step on average (max {info['max_iterations']})",
            f"  converged {100 * info['converged_share']:.3f}% of steps; largest residual "
            f"{info['max_residual']:.1e}, position error {info['max_position_error_m']:.1e} m, "
            f"orientation error {info['max_orientation_error_rad']:.1e} rad",
            f"  peak memory: resident set {info['peak_rss_mb']:.0f} MiB (process, JAX included; "
            f"{info['rss_mb_before']:.0f} MiB before retargeting), Python allocations during "
            f"retargeting {info['tracemalloc_peak_mb']:.1f} MiB (tracemalloc); results on disk "
            f"{info['out_bytes'] / 2**20:.0f} MiB",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python3 -m bench.motion", description=__doc__.split("\n")[0])
    p.add_argument("--steps", type=lambda s: int(float(s)), default=100_000)
    p.add_argument("--robot", default=G1)
    p.add_argument("--frames", nargs="*", default=(), help="frames (for another --robot)")
    p.add_argument("--dtype", choices=("float64", "float32"), default="float64")
    p.add_argument("--chunk", type=int, default=motion.MOTION_CHUNK_SIZE, help="steps per call")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--dir", default=None, help="where to write (default: the temp directory)")
    p.add_argument("--keep", action="store_true", help="keep the files (default: delete)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    print(summary(run(args)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
