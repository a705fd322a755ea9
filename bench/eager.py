"""Eager calls, one frame of a 10,000-joint tree, and pytorch_kinematics' compiled Jacobian.

``python3 -m bench.eager [--quick] [--write-readme]`` measures three things the main comparison
(:mod:`bench.jacobians`) does not, on example-robot-data's Panda (float64, tip
``panda_hand_tcp``, the URDF of :func:`bench.peers.robot_sources`):

1. **Eager public calls** (a notebook, a property test): ``jk.fk``, ``jk.geometric_jacobian``,
   ``jk.analytical_jacobian`` (rpy), ``jk.twist``, ``jk.jacobian_dot`` and
   ``jk.kinematic_hessian`` called outside any ``jit`` on one configuration. The first call (in
   this process; JAX's backend is started before by a trivial operation) is timed apart from the
   median of later calls on *other* configurations of the same shape. Each answer is compared
   with the same function under ``jax.jit`` (largest difference), and fk and the geometric
   Jacobian with Pinocchio (``framesForwardKinematics``, ``computeFrameJacobian``
   LOCAL_WORLD_ALIGNED), whose one-call times are the reference column.
2. **One frame of a 10,000-joint tree**: :func:`random_tree` (``jk.Robot.from_joints``, a fixed
   seed); ``jk.fk`` and ``jk.geometric_jacobian`` of its deepest frame, eager, first call
   included, then the median of later calls; both checked against Pinocchio on the same tree
   written by ``jk.to_urdf``.
3. **pytorch_kinematics in its fastest documented mode**: ``torch.compile(chain.jacobian_tensor,
   fullgraph=True)`` (its README, 0.10: "Compiled ``jacobian_tensor``"), batched, float32 and
   float64, N = 1 ... 100k, against jaxkin's ``jax.jit(jax.vmap(jk.geometric_jacobian))`` in the
   same run, samples interleaved; compile (first call per shape) timed apart; results compared
   with jaxkin's.

Writes ``bench/results/eager.json`` (``eager_quick.json`` with ``--quick``) and prints markdown
tables; ``--write-readme`` puts them into bench/README.md between the ``eager:start`` /
``eager:end`` markers; ``--from-json PATH`` reports an earlier run without measuring. This module
measures; :mod:`bench.eager_report` writes the tables.
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk

from .eager_report import report
from .peers import Pinocchio, quiet, robot_sources
from .report import (
    HERE,
    RESULTS_DIR,
    exit_without_teardown,
    fmt_rate,
    log,
    machine_info,
    median,
    timed,
    utc_now,
    write_json,
)

TREE_JOINTS = 10_000
TREE_SEED = 12
Q_SEED = 3


# ---------------------------------------------------------------------------- 1. eager calls
def eager_functions(robot: jk.Robot) -> dict[str, Callable[..., Any]]:
    """Each public function on (q, qd): what a user types in a notebook."""
    return {
        "fk": lambda q, qd: jk.fk(robot, q),
        "geometric_jacobian": lambda q, qd: jk.geometric_jacobian(robot, q),
        "analytical_jacobian (rpy)": lambda q, qd: jk.analytical_jacobian(robot, q, "rpy"),
        "twist": lambda q, qd: jk.twist(robot, q, qd),
        "jacobian_dot": lambda q, qd: jk.jacobian_dot(robot, q, qd),
        "kinematic_hessian": lambda q, qd: jk.kinematic_hessian(robot, q),
    }


def _calls(fn: Callable[[], Any], repeats: int, budget_s: float) -> list[float]:
    """Seconds of up to ``repeats`` calls of ``fn`` (each blocked), fewer if ``budget_s`` runs
    out (at least 3)."""
    times: list[float] = []
    t_start = time.perf_counter()
    while len(times) < repeats and (len(times) < 3 or time.perf_counter() - t_start < budget_s):
        _, t = timed(lambda: jax.block_until_ready(fn()))
        times.append(t)
    return times


def measure_eager(robot: jk.Robot, pin: Pinocchio, repeats: int) -> list[dict[str, Any]]:
    import pinocchio as pinocchio_lib

    qs = np.asarray(jk.sample_configurations(robot, repeats + 1, Q_SEED))
    qds = np.random.default_rng(Q_SEED).uniform(-1, 1, qs.shape)
    jax.block_until_ready(jnp.zeros(3) + 1.0)  # start the backend outside every row
    rows = []
    for name, f in eager_functions(robot).items():
        log(f"eager: {name}")
        first_out, first = timed(lambda f=f: jax.block_until_ready(f(qs[0], qds[0])))
        k = iter(range(1, repeats + 1))

        def later(f=f, k=k):
            i = next(k, repeats)
            return f(qs[i], qds[i])

        times = _calls(later, repeats, budget_s=20.0)
        jitted = jax.jit(f)(qs[0], qds[0])
        row = dict(
            function=name,
            first_call_s=first,
            per_call_s=median(times),
            per_call_min_s=float(np.min(times)),
            samples_s=times,
            max_abs_diff_vs_jit=float(np.max(np.abs(np.asarray(first_out) - np.asarray(jitted)))),
        )
        if name == "fk":
            row["max_abs_diff_vs_pinocchio"] = float(
                np.abs(np.asarray(first_out) - pin.pose(qs[0])).max()
            )
            row["pinocchio_s"] = _pin_time(
                lambda q: pinocchio_lib.framesForwardKinematics(pin.model, pin.data, q), qs
            )
        if name == "geometric_jacobian":
            row["max_abs_diff_vs_pinocchio"] = float(
                np.abs(np.asarray(first_out) - pin.geometric(qs[0])).max()
            )
            row["pinocchio_s"] = _pin_time(pin.geometric, qs)
        rows.append(row)
    return rows


def _pin_time(call: Callable[[np.ndarray], Any], qs: np.ndarray) -> float:
    """Median seconds of one Pinocchio call from Python (7 samples of loops over ``qs``)."""
    out = []
    for _ in range(7):
        t = time.perf_counter()
        for _ in range(20):
            for q in qs:
                call(q)
        out.append((time.perf_counter() - t) / (20 * len(qs)))
    return median(out)


# ---------------------------------------------------------------------------- 2. large tree
def random_tree(n: int = TREE_JOINTS, seed: int = TREE_SEED) -> tuple[jk.Robot, str, int, list]:
    """A float64 tree of ``n`` revolute joints (``j0 ...``, links ``l1 ...``): each joint hangs
    off the previous joint's link with probability 0.9 (long branches), else off a uniformly
    drawn earlier link; random unit axes, 2 - 10 cm offsets, random rpy, limits +-pi. Returns
    the robot, its deepest link, that link's depth (joints from the root) and the joint specs."""
    rng = np.random.default_rng(seed)
    depth = [0]  # of link l<i>; l0 is the root "base"
    joints = []
    for i in range(n):
        parent = i if rng.random() < 0.9 else int(rng.integers(0, i + 1))
        axis = rng.normal(size=3)
        joints.append(
            dict(
                name=f"j{i}",
                type="revolute",
                parent="base" if parent == 0 else f"l{parent}",
                child=f"l{i + 1}",
                xyz=tuple(rng.uniform(-0.1, 0.1, 3)),
                rpy=tuple(rng.uniform(-np.pi, np.pi, 3)),
                axis=tuple(axis / np.linalg.norm(axis)),
                lower=-math.pi,
                upper=math.pi,
            )
        )
        depth.append(depth[parent] + 1)
    deepest = int(np.argmax(depth))
    robot = jk.Robot.from_joints(joints, root="base", name=f"tree{n}", dtype=np.float64)
    return robot, f"l{deepest}", depth[deepest], joints


def ancestor_chain(joints: list[dict[str, Any]], frame: str) -> list[dict[str, Any]]:
    """The joints from the root to ``frame``, root first: all that ``frame``'s pose depends on."""
    by_child = {j["child"]: j for j in joints}
    chain, link = [], frame
    while link in by_child:
        chain.append(by_child[link])
        link = by_child[link]["parent"]
    return chain[::-1]


def measure_tree_bounded(n: int, repeats: int, limit_s: float) -> dict[str, Any]:
    """:func:`measure_tree` in a fresh process (so its first call is a new process's), stopped
    after ``limit_s`` seconds: a row that does not finish says so instead of stalling the run."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tree.json"
        cmd = [
            sys.executable,
            "-m",
            "bench.eager",
            "--tree-only",
            str(n),
            "--repeats",
            str(repeats),
        ]
        t0 = time.perf_counter()
        try:
            subprocess.run(
                [*cmd, "--out", str(path)],
                cwd=HERE.parent,
                timeout=limit_s,
                check=True,
                stdout=subprocess.DEVNULL,
            )
        except subprocess.TimeoutExpired:
            out = json.loads(path.read_text()) if path.exists() else dict(joints=n)
            out["error"] = f"stopped after {limit_s:.0f} s"
            return out
        except subprocess.CalledProcessError as e:
            return dict(joints=n, error=f"failed (exit status {e.returncode})")
        out = json.loads(path.read_text())
        out["process_s"] = time.perf_counter() - t0
        return out


def measure_tree(n: int, repeats: int, path: Path) -> dict[str, Any]:
    """Written to ``path`` after every step, so a stopped run keeps what it measured."""
    import pinocchio as pin

    (robot, frame, depth, joints), build_s = timed(lambda: random_tree(n))
    log(f"tree: {n} joints built in {build_s:.2f} s; frame {frame} at depth {depth}")
    qs = np.random.default_rng(Q_SEED).uniform(-math.pi, math.pi, (repeats + 1, robot.dof))
    out: dict[str, Any] = dict(joints=n, frame=frame, depth=depth, build_s=build_s)
    write_json(path, out)
    # The oracle: Pinocchio on the frame's ancestor chain alone (written by jk.to_urdf), which
    # is all its pose depends on (Pinocchio's data for the whole 10,000-joint tree does not fit
    # in memory: MemoryError in createData). Joints are matched by name.
    chain = jk.Robot.from_joints(ancestor_chain(joints, frame), root="base", dtype=np.float64)
    model = pin.buildModelFromXML(jk.to_urdf(chain))
    cols = [robot.joint_names.index(name) for name in list(model.names)[1:]]
    if model.nq != len(cols) or len(cols) != depth:
        raise RuntimeError("Pinocchio's ancestor chain is not the tree's")
    data = model.createData()
    fid = model.getFrameId(frame)
    q_pin = qs[0][cols]
    pin.framesForwardKinematics(model, data, q_pin)
    oracle = {
        "fk": np.array(data.oMf[fid].homogeneous),
        "geometric_jacobian": lambda: pin.computeFrameJacobian(
            model, data, q_pin, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        ),
    }
    others = np.setdiff1d(np.arange(robot.dof), cols)
    for name, f in (
        ("fk", lambda q: jk.fk(robot, q, frame)),
        ("geometric_jacobian", lambda q: jk.geometric_jacobian(robot, q, frame)),
    ):
        log(f"tree: {name}")
        result, first = timed(lambda f=f: np.asarray(f(qs[0])))
        k = iter(range(1, repeats + 1))
        times = _calls(lambda f=f, k=k: f(qs[next(k, repeats)]), repeats, budget_s=30.0)
        if name == "fk":
            diff = np.abs(result - oracle["fk"]).max()
        else:  # Pinocchio's column i is jaxkin's column cols[i]; the others must be 0
            diff = max(
                np.abs(result[:, cols] - oracle[name]()).max(), np.abs(result[:, others]).max()
            )
        out[name] = dict(
            first_call_s=first,
            per_call_s=median(times),
            samples_s=times,
            max_abs_diff_vs_pinocchio=float(diff),
        )
        write_json(path, out)
    write_json(path, out)
    return out


# ---------------------------------------------------------------------------- 3. pk compiled
def _per_config(call: Callable[[], Any], n: int, repeats: int, target_s: float) -> list[float]:
    """``repeats`` samples of seconds per configuration: loops of ``call`` lasting >= target_s."""
    call()
    _, t1 = timed(call)
    inner = max(1, math.ceil(target_s / max(t1, 1e-7)))
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(inner):
            call()
        out.append((time.perf_counter() - t) / (inner * n))
    return out


def measure_pk_compiled(
    src, robot: jk.Robot, ns: list[int], repeats: int, target_s: float
) -> dict[str, Any]:
    import pytorch_kinematics as pk
    import torch

    with quiet():
        chain0 = pk.build_serial_chain_from_urdf(src.urdf.encode(), src.tip)
    if tuple(chain0.get_joint_parameter_names()) != tuple(robot.joint_names):
        raise RuntimeError("pytorch_kinematics' joint order differs from jaxkin's")
    default_threads = torch.get_num_threads()
    out: dict[str, Any] = dict(
        how="torch.compile(chain.jacobian_tensor, fullgraph=True), torch.no_grad(), CPU tensors",
        torch_default_threads=default_threads,
        rows=[],
    )
    for dtype in ("float32", "float64"):
        tdtype = getattr(torch, dtype)
        chain = chain0.to(dtype=tdtype)
        compiled = torch.compile(chain.jacobian_tensor, fullgraph=True)
        rj = jk.load_urdf(src.urdf, tip=src.tip, dtype=np.dtype(dtype), name=src.name)
        jk_fn = jax.jit(jax.vmap(lambda q, rj=rj: jk.geometric_jacobian(rj, q)))
        for n in ns:
            q64 = np.asarray(jk.sample_configurations(robot, n, n))
            th = torch.as_tensor(np.ascontiguousarray(q64, dtype=dtype))
            qj = jnp.asarray(q64.astype(dtype))
            # threads: 1 or torch's default, whichever is faster here (OpenMP spinning on a
            # loaded machine can make 2 threads far slower than 1)
            with torch.no_grad():
                torch.set_num_threads(default_threads)
                J_pk, compile_s = timed(lambda c=compiled, t=th: c(t))  # first call of this shape
                probe = {}
                for threads in sorted({1, default_threads}):
                    torch.set_num_threads(threads)
                    probe[threads] = min(timed(lambda c=compiled, t=th: c(t))[1] for _ in range(3))
                threads = min(probe, key=probe.get)
                torch.set_num_threads(threads)

            def jk_call(f=jk_fn, q=qj):
                return jax.block_until_ready(f(q))

            J_jk, jk_first_s = timed(jk_call)
            diff = float(
                np.abs(J_pk.numpy().astype(np.float64) - np.asarray(J_jk, np.float64)).max()
            )
            pk_s, jk_s = [], []

            def pk_call(c=compiled, t=th):
                with torch.no_grad():
                    c(t)

            for _ in range(repeats):  # interleaved: both see the same load
                pk_s += _per_config(pk_call, n, 1, target_s)
                jk_s += _per_config(jk_call, n, 1, target_s)
            row = dict(
                dtype=dtype,
                n=n,
                pk_rate=1.0 / median(pk_s),
                jaxkin_rate=1.0 / median(jk_s),
                pk_first_call_s=compile_s,
                jaxkin_first_call_s=jk_first_s,
                pk_threads=threads,
                max_abs_diff=diff,
                pk_samples_s=pk_s,
                jaxkin_samples_s=jk_s,
            )
            log(
                f"pk compiled {dtype} N={n}: {fmt_rate(row['pk_rate'])}/s ({threads} thr), "
                f"jaxkin {fmt_rate(row['jaxkin_rate'])}/s, diff {diff:.1e}"
            )
            out["rows"].append(row)
        torch.set_num_threads(default_threads)
    return out


# ---------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats, a 1,000-joint tree")
    ap.add_argument("--write-readme", action="store_true")
    ap.add_argument("--no-pk", action="store_true", help="skip pytorch_kinematics")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--tree-limit", type=float, default=240.0, help="seconds per tree process")
    ap.add_argument("--tree-only", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument(
        "--update-trees", type=Path, default=None, help="re-measure only the trees of this result"
    )
    ap.add_argument("--repeats", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument(
        "--from-json", type=Path, default=None, help="report an earlier run (no measuring)"
    )
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    warnings.simplefilter("ignore", DeprecationWarning)
    if args.tree_only is not None:  # the child of measure_tree_bounded
        measure_tree(args.tree_only, args.repeats, args.out)
        return 0
    repeats = 5 if args.quick else 15
    ns = [1, 1000] if args.quick else [1, 100, 10_000, 100_000]

    if args.update_trees is not None:
        res = json.loads(args.update_trees.read_text())
        res["trees"] = [measure_tree_bounded(n, 3, args.tree_limit) for n in (30, TREE_JOINTS)]
        res["trees_date"] = utc_now()
        res["trees_load_average_after"] = os.getloadavg()
        write_json(args.update_trees, res)
        report(res, args.write_readme)
        return 0
    if args.from_json is not None:
        report(json.loads(args.from_json.read_text()), args.write_readme)
        return 0
    src = robot_sources(["panda"])[0]
    robot = jk.load_urdf(src.urdf, tip=src.tip, dtype=np.float64, name=src.name)
    pin = Pinocchio(src, robot)
    res: dict[str, Any] = dict(
        benchmark="eager",
        date=utc_now(),
        machine=machine_info(),
        load_average_before=os.getloadavg(),
    )
    gc.disable()
    res["eager"] = measure_eager(robot, pin, repeats)
    gc.enable()
    res["trees"] = [
        measure_tree_bounded(n, 3, args.tree_limit)
        for n in ([30] if args.quick else [30, TREE_JOINTS])
    ]
    if not args.no_pk:
        try:
            res["pk_compiled"] = measure_pk_compiled(src, robot, ns, 3 if args.quick else 7, 0.05)
        except Exception as e:  # a peer that fails is reported, not fatal
            res["pk_compiled"] = dict(error=f"{type(e).__name__}: {e}")
            log(f"pytorch_kinematics compiled failed: {e}")
    res["load_average_after"] = os.getloadavg()
    out = args.out or RESULTS_DIR / ("eager_quick.json" if args.quick else "eager.json")
    write_json(out, res)
    report(res, args.write_readme)
    log(f"wrote {out}")
    return 0


if __name__ == "__main__":
    exit_without_teardown(main())
