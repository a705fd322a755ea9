"""Jacobian benchmark: jaxkin against Pinocchio, pytorch_kinematics, MuJoCo and the Robotics
Toolbox, on the same URDFs (Panda, UR5, a 32-joint chain).

For each robot (see :mod:`bench.peers`), quantity and dtype:

* jaxkin, batched: ``jax.jit(jax.vmap(f))`` with ``f`` one of ``jk.geometric_jacobian(robot, q)``
  (tip, world-aligned), ``jk.analytical_jacobian(robot, q, "rpy", return_margin=True)`` and
  ``jk.twist(robot, q, qd)``, for N = 1, 100, 10k, 100k, 1M; compile apart (``lower`` and
  ``compile`` timed), the optimised HLO profiled (fusions, loops, sin/cos, temporaries);
* jaxkin, one configuration from Python: ``jax.jit(lambda q: jk.geometric_jacobian(robot, q))(q)``;
* peers (geometric Jacobian): pytorch_kinematics batched (float32, float64), MuJoCo (a Python
  loop, and ``mujoco.batch.Batch``), Robotics Toolbox ETS (a Python loop); Python loops time
  ``min(N, cap)`` configurations;
* Pinocchio from Python, one call per configuration, is the reference: one Pinocchio sample of
  the same quantity follows every sample of every row, in the same process, and each row's ratio
  is the row's rate over the Pinocchio rate measured beside it;
* every row is checked numerically: jaxkin against Pinocchio, peers against jaxkin (float64).

Configurations come from ``jk.sample_configurations`` (fixed keys), joint rates from
:func:`bench.report.joint_rates`. This module measures; :mod:`bench.jacobian_report` prints the
tables, writes the README section and plots.

Usage: ``python3 -m bench [--quick] [--robots panda,ur5] [--ns 1,100] [--write-readme]
[--from-json PATH]``. Writes ``bench/results/latest.json`` and ``latest.png`` (``quick.*``
with ``--quick``), prints the tables; ``--write-readme`` replaces the generated section of
bench/README.md.
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk

from . import peers as P
from .jacobian_report import DTYPES, QUANTITIES, README, plot, print_tables, write_readme
from .report import (
    RESULTS_DIR,
    Timer,
    fmt_rate,
    joint_rates,
    log,
    machine_info,
    median,
    timed,
    write_json,
)

SEED = 20240607  # configurations and joint rates of every robot

FULL = dict(
    ns=(1, 100, 10_000, 100_000, 1_000_000),
    repeats=7,  # samples per row
    big_repeats=3,  # samples per row when one call takes longer than big_call_s
    big_call_s=0.2,
    target_s=0.05,  # a sample lasts at least this long (a loop of calls)
    pin_configs=5_000,  # most configurations per interleaved Pinocchio sample ...
    pin_target_s=0.02,  # ... and about this long at most
    loop_cap=20_000,  # most configurations a Python-loop peer times per sample
    loop_target_s=0.1,  # ... and about this long at most
    max_call_s=2.5,  # skip an N whose predicted call time is longer
    mem_limit=3e9,  # skip an N whose compiled kernel (or peer) needs more memory (bytes)
    check=16,  # configurations of every row checked numerically
    tune_configs=2_000,  # probe batch on which a peer picks its settings (torch threads)
)
QUICK = dict(
    FULL,
    ns=(1_000,),
    repeats=2,
    big_repeats=2,
    target_s=0.005,
    pin_configs=500,
    pin_target_s=0.005,
    loop_cap=500,
    loop_target_s=0.02,
    max_call_s=0.5,
    mem_limit=1e9,
    check=4,
    tune_configs=500,
)

# ---------------------------------------------------------------------------- rows


def _hlo_stats(lowered, compiled, n: int) -> dict[str, Any]:
    """Counts in the optimised HLO (fusions, while loops, dots, sin and cos) against the
    sin/cos jaxkin emitted (StableHLO), and the compiled kernel's memory per configuration."""
    out: dict[str, Any] = {}
    try:
        text = compiled.as_text()
        emitted = lowered.as_text()
    except Exception:
        return out
    m = re.search(r"^ENTRY .*?\{\n(.*?)^\}", text, flags=re.S | re.M)
    entry = m.group(1) if m else ""
    # an instruction reads "%name = <shape, possibly a tuple with spaces> opcode(operands)"
    out.update(
        entry_fusions=len(re.findall(r" fusion\(", entry)),
        fusions=len(re.findall(r" fusion\(", text)),
        whiles=len(re.findall(r" while\(", text)),
        dots=len(re.findall(r" dot\(", text)),
        sincos_compiled=len(re.findall(r" (?:sine|cosine)\(", text)),
        sincos_emitted=len(re.findall(r"stablehlo\.(?:sine|cosine)\b", emitted)),
    )
    try:
        mem = compiled.memory_analysis()
        out.update(
            temp_bytes=int(mem.temp_size_in_bytes),
            out_bytes=int(mem.output_size_in_bytes),
            arg_bytes=int(mem.argument_size_in_bytes),
            temp_bytes_per_config=mem.temp_size_in_bytes / n,
            io_bytes_per_config=(mem.output_size_in_bytes + mem.argument_size_in_bytes) / n,
        )
    except Exception:
        pass
    return out


def _kernel(robot: jk.Robot, quantity: str):
    if quantity == "geometric":
        return jax.jit(jax.vmap(lambda q: jk.geometric_jacobian(robot, q)))
    if quantity == "analytical":
        return jax.jit(
            jax.vmap(lambda q: jk.analytical_jacobian(robot, q, "rpy", return_margin=True))
        )
    return jax.jit(jax.vmap(lambda q, qd: jk.twist(robot, q, qd)))


def _pin_values(pin: P.Pinocchio, quantity: str, q64, qd64) -> np.ndarray:
    if quantity == "geometric":
        return np.stack([pin.geometric(q) for q in q64])
    if quantity == "analytical":
        return np.stack([pin.analytical(q) for q in q64])
    return np.stack([pin.twist(q, qd) for q, qd in zip(q64, qd64, strict=True)])


def _row(robot: str, impl: str, quantity: str, dtype: str, n: int, **kw) -> dict[str, Any]:
    row = dict(robot=robot, impl=impl, quantity=quantity, dtype=dtype, n=n, n_timed=n)
    row.update(status="ok", samples_s=[], pin_samples_s=[])
    row.update(kw)
    return row


def _finish(row: dict[str, Any]) -> dict[str, Any]:
    if row["status"] == "ok" and row["samples_s"]:
        per = median(row["samples_s"])
        row["per_s"] = 1.0 / per
        row["us_each"] = per * 1e6
        if row["pin_samples_s"]:
            pin = median(row["pin_samples_s"])
            row["pin_per_s"] = 1.0 / pin
            row["ratio_vs_pin"] = pin / per
    return row


def _progress(row: dict[str, Any]) -> None:
    what = f"  {row['robot']:8s} {row['impl']:26.26s} {row['quantity']:10s} {row['dtype']} "
    what += f"N={row['n']:>9,}"
    if row["status"] != "ok":
        log(f"{what}: {row['status']}")
        return
    comp = ""
    if "compile_s" in row:
        comp = f"compile {row['lower_s'] + row['compile_s']:5.2f} s, "
    ratio = f", {row['ratio_vs_pin']:.2f}x Pinocchio" if "ratio_vs_pin" in row else ""
    diff = row.get("max_abs_diff", math.nan)
    log(f"{what}: {comp}{fmt_rate(row['per_s'])}/s{ratio}, diff {diff:.1e}")


def _too_slow(per_config: float | None, n: int, cfg: dict[str, Any]) -> str | None:
    """The skip status of an N whose call, predicted from the last rate, would be too long."""
    if per_config is None or per_config * n <= cfg["max_call_s"]:
        return None
    return f"skipped: predicted {per_config * n:.1f} s per call > {cfg['max_call_s']} s"


# ---------------------------------------------------------------------------- one robot


class RobotBench:
    """Everything measured for one robot."""

    def __init__(self, src: P.RobotSource, cfg: dict[str, Any], seed: int):
        self.src, self.cfg = src, cfg
        self.timer = Timer(cfg)
        self.r64, self.how = P.jaxkin_robot(src, np.float64)
        self.r32, _ = P.jaxkin_robot(src, np.float32)
        self.pin = P.Pinocchio(src, self.r64)
        n_max, n_pin, dof = max(cfg["ns"]), cfg["pin_configs"], self.r64.dof
        key = jax.random.key(seed)
        self.q_pool = self._configurations(n_max, jax.random.fold_in(key, 0))
        self.qd_pool = joint_rates(n_max, dof, [seed, 0])
        pin_q = self._configurations(n_pin, jax.random.fold_in(key, 1))
        self.pin_q = [np.ascontiguousarray(q) for q in pin_q]
        self.pin_qd = [np.ascontiguousarray(q) for q in joint_rates(n_pin, dof, [seed, 1])]
        pose_err = max(
            float(np.abs(self.pin.pose(q) - np.asarray(jk.fk(self.r64, q))).max())
            for q in self.q_pool[:4]
        )
        self.info = dict(
            urdf=src.origin,
            tip=src.tip,
            dof=self.r64.dof,
            n_joints=self.r64.n_joints,
            jaxkin=self.how,
            scan_path=bool(jk.kinematics.uses_scan(self.r64)),
            pinocchio=self.pin.how,
            tip_pose_diff_vs_pinocchio=pose_err,
            peers={},
            peers_failed={},
        )
        self.rows: list[dict[str, Any]] = []

    def _configurations(self, n: int, key) -> np.ndarray:
        return np.asarray(jk.sample_configurations(self.r64, n, key), dtype=np.float64)

    def pin_ref(self, quantity: str) -> Callable[[], float]:
        """One interleaved Pinocchio sample of ``quantity``: seconds per configuration of a loop
        over about ``pin_target_s`` worth of configurations."""
        loop = self.pin.loop(quantity)
        _, t = timed(lambda: loop(self.pin_q[:50], self.pin_qd[:50]))
        m = int(min(len(self.pin_q), max(200, self.cfg["pin_target_s"] / max(t / 50, 1e-9))))
        qs, qds = self.pin_q[:m], self.pin_qd[:m]

        def sample() -> float:
            return timed(lambda: loop(qs, qds))[1] / len(qs)

        return sample

    def add(self, row: dict[str, Any]) -> dict[str, Any]:
        _finish(row)
        self.rows.append(row)
        _progress(row)
        return row

    # -------------------------------------------------------------- jaxkin, batched
    def jaxkin(self) -> None:
        cfg = self.cfg
        for quantity in QUANTITIES:
            ref = self.pin_ref(quantity)
            for dtype in DTYPES:
                robot = self.r64 if dtype == "float64" else self.r32
                fn = _kernel(robot, quantity)
                per_config = None  # seconds per configuration at the last N >= 100
                for n in cfg["ns"]:
                    row = _row(self.src.name, "jaxkin", quantity, dtype, n)
                    skip = _too_slow(per_config, n, cfg)
                    if skip:
                        row["status"] = skip
                    else:
                        self._jaxkin_row(row, fn, ref)
                        if row["status"] == "ok" and n >= 100:  # N = 1 is all overhead
                            per_config = median(row["samples_s"])
                    self.add(row)
                del fn
                jax.clear_caches()

    def _jaxkin_row(self, row, fn, ref) -> None:
        cfg, n, quantity, dtype = self.cfg, row["n"], row["quantity"], row["dtype"]
        q64, qd64 = self.q_pool[:n], self.qd_pool[:n]
        args = [jnp.asarray(q64.astype(dtype))]
        if quantity == "twist":
            args.append(jnp.asarray(qd64.astype(dtype)))
        lowered, lower_s = timed(lambda: fn.lower(*args))
        compiled, compile_s = timed(lowered.compile)
        row.update(lower_s=lower_s, compile_s=compile_s, hlo=_hlo_stats(lowered, compiled, n))
        need = sum(row["hlo"].get(k, 0) for k in ("temp_bytes", "out_bytes", "arg_bytes"))
        if need > cfg["mem_limit"]:
            limit = cfg["mem_limit"] / 1e9
            row["status"] = f"skipped: the kernel needs {need / 1e9:.1f} GB > {limit:g} GB"
            return
        del lowered, compiled
        # served from the executable compiled above
        out, row["first_call_s"] = timed(lambda: jax.block_until_ready(fn(*args)))
        got = np.asarray(out[0] if quantity == "analytical" else out, dtype=np.float64)
        k = min(n, cfg["check"])
        want = _pin_values(self.pin, quantity, q64[:k], qd64[:k])
        row["max_abs_diff"] = float(np.abs(got[:k] - want).max())
        row["diff_against"] = "Pinocchio"
        del out, got
        row.update(self.timer.samples(lambda: jax.block_until_ready(fn(*args)), n, ref))

    # -------------------------------------------------------------- jaxkin, one q from Python
    def single(self) -> None:
        ref = self.pin_ref("geometric")
        q64 = self.q_pool[0]
        for dtype in DTYPES:
            robot = self.r64 if dtype == "float64" else self.r32
            fn = jax.jit(lambda q, robot=robot: jk.geometric_jacobian(robot, q))
            q = jnp.asarray(q64.astype(dtype))
            row = _row(self.src.name, "jaxkin single", "geometric", dtype, 1)
            # first call: trace + compile + run
            J, row["first_call_s"] = timed(lambda fn=fn, q=q: jax.block_until_ready(fn(q)))
            J = np.asarray(J, dtype=np.float64)
            row["max_abs_diff"] = float(np.abs(J - self.pin.geometric(q64)).max())
            row["diff_against"] = "Pinocchio"
            row.update(self.timer.samples(lambda fn=fn, q=q: jax.block_until_ready(fn(q)), 1, ref))
            self.add(row)
        # Pinocchio, one call for one configuration (per-call microseconds)
        pin_one = self.pin.loop("geometric")
        q1 = [np.ascontiguousarray(q64)]
        row = _row(self.src.name, "pinocchio single", "geometric", "float64", 1)
        row.update(self.timer.samples(lambda: pin_one(q1, q1), 1, None))
        self.add(row)

    # -------------------------------------------------------------- peers
    def peers(self) -> None:
        peers, failed = P.build_peers(self.src, self.r64)
        self.info["peers_failed"] = failed
        for name, why in failed.items():
            log(f"  {self.src.name}: peer {name} unavailable: {why}")
        ref = self.pin_ref("geometric")
        q_check = self.q_pool[: self.cfg["check"]]
        J_ref = {
            rf: np.stack(
                [np.asarray(jk.geometric_jacobian(self.r64, q, reference=rf)) for q in q_check]
            )
            for rf in ("world_aligned", "world")
        }
        for peer in peers:
            try:
                peer.tune(self.q_pool[: self.cfg["tune_configs"]])  # may change the label
                key = f"{peer.label} [{peer.dtype}]"
                diff = float(np.abs(peer.jacobians(q_check) - J_ref[peer.reference]).max())
            except Exception as e:
                failed[f"{peer.label} [{peer.dtype}]"] = f"check failed: {type(e).__name__}: {e}"
                continue
            self.info["peers"][key] = dict(
                how=peer.how, version=peer.version, reference=peer.reference, max_abs_diff=diff
            )
            try:
                timing = self._batched_peer if peer.batched else self._loop_peer
                timing(peer, diff, ref)
            except Exception as e:  # a peer that fails while timed is reported, not fatal
                failed[key] = f"timing failed: {type(e).__name__}: {e}"
                log(f"  {self.src.name}: {key}: {failed[key]}")
            finally:
                peer.close()
                gc.collect()

    def _peer_row(self, peer: P.Peer, diff: float, n: int, **kw) -> dict[str, Any]:
        row = _row(self.src.name, peer.label, "geometric", peer.dtype, n, **kw)
        row.update(max_abs_diff=diff, diff_against=f"jaxkin float64 ({peer.reference})")
        return row

    def _batched_peer(self, peer: P.Peer, diff: float, ref) -> None:
        cfg = self.cfg
        per_config = None
        for n in cfg["ns"]:
            row = self._peer_row(peer, diff, n)
            need = peer.bytes_per_config() * n
            skip = _too_slow(per_config, n, cfg)
            if skip:
                row["status"] = skip
            elif need > cfg["mem_limit"]:
                row["status"] = f"skipped: needs about {need / 1e9:.1f} GB"
            else:
                prepared = peer.prepare(self.q_pool[:n])
                row.update(self.timer.samples(lambda p=prepared: peer.run(p), n, ref))
                if n >= 100:  # N = 1 is all overhead: no prediction from it
                    per_config = median(row["samples_s"])
                del prepared
            self.add(row)

    def _loop_peer(self, peer: P.Peer, diff: float, ref) -> None:
        cfg = self.cfg
        probe = peer.prepare(self.q_pool[:20])
        _, t = timed(lambda: peer.run(probe))
        per = t / len(probe)
        cap = int(min(cfg["loop_cap"], max(100, cfg["loop_target_s"] / max(per, 1e-9))))
        measured: dict[int, dict[str, Any]] = {}
        for n in cfg["ns"]:
            m = min(n, cap)
            row = self._peer_row(peer, diff, n, n_timed=m)
            if m not in measured:
                prepared = peer.prepare(self.q_pool[:m])
                measured[m] = self.timer.samples(lambda p=prepared: peer.run(p), m, ref)
            else:
                row["reused_from_n_timed"] = m
            row.update(measured[m])
            self.add(row)


def dispatch_floor_s(cfg: dict[str, Any]) -> float:
    """Seconds per call of a trivial jitted function on a (6,) input (the dispatch floor)."""
    fn = jax.jit(lambda q: q + 1.0)
    q = jnp.zeros(6)
    res = Timer(cfg).samples(lambda: jax.block_until_ready(fn(q)), 1, None)
    return median(res["samples_s"])


# ---------------------------------------------------------------------------- main


def _parse_ns(text: str) -> tuple[int, ...]:
    return tuple(int(float(x)) for x in text.split(",") if x)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python3 -m bench", description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smoke run: N in (1, 1000), 2 repeats")
    parser.add_argument("--robots", default="", help="comma-separated subset of panda,ur5,chain32")
    parser.add_argument("--ns", default="", help="comma-separated batch sizes (override)")
    parser.add_argument("--no-peers", action="store_true", help="jaxkin and Pinocchio only")
    parser.add_argument("--out", type=Path, default=None, help="where to write the JSON results")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG plot")
    parser.add_argument(
        "--write-readme", action="store_true", help="replace bench/README.md's results section"
    )
    parser.add_argument(
        "--from-json", type=Path, default=None, help="report an earlier run (no measuring)"
    )
    return parser


def measure(cfg: dict[str, Any], args: argparse.Namespace, out_name: str) -> dict[str, Any]:
    """Every robot of ``args.robots`` (all by default): the result written as JSON."""
    t_start = time.perf_counter()
    load_before = os.getloadavg()
    machine = machine_info()  # before any peer changes torch's thread count
    floor = dispatch_floor_s(cfg)
    rows: list[dict[str, Any]] = []
    robots: dict[str, Any] = {}
    names = [x for x in args.robots.split(",") if x] or None
    for src in P.robot_sources(names):
        log(f"{src.name}: {src.origin}")
        rb = RobotBench(src, cfg, SEED)
        robots[src.name] = rb.info
        rb.single()
        rb.jaxkin()
        if not args.no_peers:
            rb.peers()
        rows += rb.rows
        del rb
        gc.collect()
    return dict(
        benchmark="Jacobians and twists: jaxkin vs Pinocchio (Python), pytorch_kinematics, "
        "MuJoCo, Robotics Toolbox on the same URDFs",
        mode="quick" if args.quick else "full",
        config={k: v for k, v in cfg.items()},
        machine=machine,
        load_average_1_5_15min=dict(before=load_before, after=os.getloadavg()),
        dispatch_floor_us=floor * 1e6,
        robots=robots,
        elapsed_s=time.perf_counter() - t_start,
        json_name=out_name,
        rows=rows,
    )


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.from_json is not None:
        result = json.loads(args.from_json.read_text())
        result.setdefault("json_name", args.from_json.name)
        out_path = args.from_json
    else:
        # A bench process may change the global JAX configuration (jaxkin itself never does).
        jax.config.update("jax_enable_x64", True)
        cfg = dict(QUICK if args.quick else FULL)
        if args.ns:
            cfg["ns"] = _parse_ns(args.ns)
        out_path = args.out or RESULTS_DIR / ("quick.json" if args.quick else "latest.json")
        result = measure(cfg, args, out_path.name)
        write_json(out_path, result)
    if not args.no_plot:
        plot(result["rows"], out_path.with_suffix(".png"))
    print_tables(result, out_path)
    if args.write_readme:
        write_readme(result)
        if args.from_json is None:
            print(f"-> {README} (results section)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
