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

Usage: ``python3 -m bench [--quick] [--robots panda,ur5] [--ns 1,100] [--write-readme]
[--from-json PATH]``. Writes ``bench/results/latest.json`` and ``latest.png`` (``quick.*``
with ``--quick``), prints the tables; ``--write-readme`` replaces the generated section of
bench/README.md.
"""

from __future__ import annotations

import argparse
import datetime
import gc
import json
import math
import os
import platform
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

HERE = Path(__file__).resolve().parent
RESULTS_DIR = HERE / "results"
README = HERE / "README.md"
MARK_START, MARK_END = "<!-- results:start -->", "<!-- results:end -->"

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
    ns=(1_000,),
    repeats=2,
    big_repeats=2,
    big_call_s=0.2,
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
QUANTITIES = ("geometric", "analytical", "twist")
DTYPES = ("float64", "float32")
HEADLINE = dict(robot="panda", quantity="geometric", n=100_000)
# PERFORMANCE.md: the machine's bounds for a folded 7-DOF Panda Jacobian
BOUNDS = dict(
    sincos_float64=10e6,
    sincos_float32=(15e6, 23e6),
    memory_float64=35e6,
    memory_float32=65e6,
)


# ---------------------------------------------------------------------------- measurement


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


class Timer:
    """Samples of a call interleaved with samples of a reference (Pinocchio), GC off."""

    def __init__(self, cfg: dict[str, Any]):
        self.cfg = cfg

    def samples(
        self, call: Callable[[], Any], n: int, ref: Callable[[], float] | None
    ) -> dict[str, Any]:
        """``call()`` computes ``n`` configurations (and blocks). Returns seconds per
        configuration of each sample, the reference's, and the calls per sample."""
        cfg = self.cfg
        call()  # warm-up
        t = time.perf_counter()
        call()
        t_call = time.perf_counter() - t
        inner = max(1, math.ceil(cfg["target_s"] / max(t_call, 1e-7)))
        repeats = cfg["big_repeats"] if t_call > cfg["big_call_s"] else cfg["repeats"]
        own, refs = [], []
        enabled = gc.isenabled()
        gc.disable()
        try:
            for _ in range(repeats):
                t = time.perf_counter()
                for _ in range(inner):
                    call()
                own.append((time.perf_counter() - t) / (inner * n))
                if ref is not None:
                    refs.append(ref())
        finally:
            if enabled:
                gc.enable()
        return dict(samples_s=own, pin_samples_s=refs, calls_per_sample=inner)


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
        per = float(np.median(row["samples_s"]))
        row["per_s"] = 1.0 / per
        row["us_each"] = per * 1e6
        if row["pin_samples_s"]:
            pin = float(np.median(row["pin_samples_s"]))
            row["pin_per_s"] = 1.0 / pin
            row["ratio_vs_pin"] = pin / per
    return row


def _report(row: dict[str, Any]) -> None:
    what = f"  {row['robot']:8s} {row['impl']:26.26s} {row['quantity']:10s} {row['dtype']} "
    what += f"N={row['n']:>9,}"
    if row["status"] != "ok":
        _log(f"{what}: {row['status']}")
        return
    comp = ""
    if "compile_s" in row:
        comp = f"compile {row['lower_s'] + row['compile_s']:5.2f} s, "
    ratio = f", {row['ratio_vs_pin']:.2f}x Pinocchio" if "ratio_vs_pin" in row else ""
    diff = row.get("max_abs_diff", math.nan)
    _log(f"{what}: {comp}{_fmt_rate(row['per_s'])}/s{ratio}, diff {diff:.1e}")


class RobotBench:
    """Everything measured for one robot."""

    def __init__(self, src: P.RobotSource, cfg: dict[str, Any], rng: np.random.Generator):
        self.src, self.cfg, self.rng = src, cfg, rng
        self.timer = Timer(cfg)
        self.r64, self.how = P.jaxkin_robot(src, np.float64)
        self.r32, _ = P.jaxkin_robot(src, np.float32)
        self.pin = P.Pinocchio(src, self.r64)
        n_max = max(cfg["ns"])
        self.q_pool = self._sample_q(n_max)
        self.qd_pool = rng.uniform(-1.0, 1.0, size=(n_max, self.r64.dof))
        self.pin_q = [np.ascontiguousarray(q) for q in self._sample_q(cfg["pin_configs"])]
        self.pin_qd = [
            np.ascontiguousarray(q)
            for q in rng.uniform(-1.0, 1.0, (cfg["pin_configs"], self.r64.dof))
        ]
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

    def _sample_q(self, n: int) -> np.ndarray:
        lo = np.asarray(self.r64.lower, dtype=np.float64)
        hi = np.asarray(self.r64.upper, dtype=np.float64)
        lo = np.where(np.isfinite(lo), lo, -np.pi)
        hi = np.where(np.isfinite(hi), hi, np.pi)
        return self.rng.uniform(lo, hi, size=(n, self.r64.dof))

    def pin_ref(self, quantity: str) -> Callable[[], float]:
        loop = self.pin.loop(quantity)
        t = time.perf_counter()
        loop(self.pin_q[:50], self.pin_qd[:50])
        per = (time.perf_counter() - t) / 50
        m = int(min(len(self.pin_q), max(200, self.cfg["pin_target_s"] / max(per, 1e-9))))
        qs, qds = self.pin_q[:m], self.pin_qd[:m]

        def sample() -> float:
            t = time.perf_counter()
            loop(qs, qds)
            return (time.perf_counter() - t) / len(qs)

        return sample

    def add(self, row: dict[str, Any]) -> dict[str, Any]:
        _finish(row)
        self.rows.append(row)
        _report(row)
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
                    if per_config is not None and per_config * n > cfg["max_call_s"]:
                        row["status"] = (
                            f"skipped: predicted {per_config * n:.1f} s per call "
                            f"> {cfg['max_call_s']} s"
                        )
                        self.add(row)
                        continue
                    self._jaxkin_row(row, fn, robot, ref)
                    if row["status"] == "ok" and n >= 100:  # N = 1 is all overhead
                        per_config = float(np.median(row["samples_s"]))
                    self.add(row)
                del fn
                jax.clear_caches()

    def _jaxkin_row(self, row, fn, robot, ref) -> None:
        cfg, n, quantity, dtype = self.cfg, row["n"], row["quantity"], row["dtype"]
        q64, qd64 = self.q_pool[:n], self.qd_pool[:n]
        args = [jnp.asarray(q64.astype(dtype))]
        if quantity == "twist":
            args.append(jnp.asarray(qd64.astype(dtype)))
        t0 = time.perf_counter()
        lowered = fn.lower(*args)
        t1 = time.perf_counter()
        compiled = lowered.compile()
        t2 = time.perf_counter()
        row.update(lower_s=t1 - t0, compile_s=t2 - t1, hlo=_hlo_stats(lowered, compiled, n))
        need = sum(row["hlo"].get(k, 0) for k in ("temp_bytes", "out_bytes", "arg_bytes"))
        if need > cfg["mem_limit"]:
            limit = cfg["mem_limit"] / 1e9
            row["status"] = f"skipped: the kernel needs {need / 1e9:.1f} GB > {limit:g} GB"
            return
        del lowered, compiled
        t = time.perf_counter()
        out = jax.block_until_ready(fn(*args))  # served from the executable compiled above
        row["first_call_s"] = time.perf_counter() - t
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
        for dtype in DTYPES:
            robot = self.r64 if dtype == "float64" else self.r32
            fn = jax.jit(lambda q, robot=robot: jk.geometric_jacobian(robot, q))
            q64 = self.q_pool[0]
            q = jnp.asarray(q64.astype(dtype))
            row = _row(self.src.name, "jaxkin single", "geometric", dtype, 1)
            t = time.perf_counter()
            J = np.asarray(jax.block_until_ready(fn(q)), dtype=np.float64)
            row["first_call_s"] = time.perf_counter() - t  # trace + compile + run
            row["max_abs_diff"] = float(np.abs(J - self.pin.geometric(q64)).max())
            row["diff_against"] = "Pinocchio"
            row.update(self.timer.samples(lambda fn=fn, q=q: jax.block_until_ready(fn(q)), 1, ref))
            self.add(row)
        # Pinocchio, one call for one configuration (per-call microseconds)
        pin_one = self.pin.loop("geometric")
        q1 = [np.ascontiguousarray(self.q_pool[0])]
        row = _row(self.src.name, "pinocchio single", "geometric", "float64", 1)
        row.update(self.timer.samples(lambda: pin_one(q1, q1), 1, None))
        self.add(row)

    # -------------------------------------------------------------- peers
    def peers(self) -> None:
        cfg = self.cfg
        peers, failed = P.build_peers(self.src, self.r64)
        self.info["peers_failed"] = failed
        for name, why in failed.items():
            _log(f"  {self.src.name}: peer {name} unavailable: {why}")
        ref = self.pin_ref("geometric")
        k = cfg["check"]
        q_check = self.q_pool[:k]
        J_ref = {
            rf: np.stack(
                [np.asarray(jk.geometric_jacobian(self.r64, q, reference=rf)) for q in q_check]
            )
            for rf in ("world_aligned", "world")
        }
        for peer in peers:
            try:
                peer.tune(self.q_pool[: cfg["tune_configs"]])
                key = f"{peer.label} [{peer.dtype}]"
                diff = float(np.abs(peer.jacobians(q_check) - J_ref[peer.reference]).max())
            except Exception as e:
                failed[f"{peer.label} [{peer.dtype}]"] = f"check failed: {type(e).__name__}: {e}"
                continue
            self.info["peers"][key] = dict(
                how=peer.how, version=peer.version, reference=peer.reference, max_abs_diff=diff
            )
            try:
                if peer.batched:
                    self._batched_peer(peer, diff, ref)
                else:
                    self._loop_peer(peer, diff, ref)
            except Exception as e:  # a peer that fails while timed is reported, not fatal
                failed[key] = f"timing failed: {type(e).__name__}: {e}"
                _log(f"  {self.src.name}: {key}: {failed[key]}")
            finally:
                peer.close()
                gc.collect()

    def _batched_peer(self, peer: P.Peer, diff: float, ref) -> None:
        cfg = self.cfg
        per_config = None
        for n in cfg["ns"]:
            row = _row(self.src.name, peer.label, "geometric", peer.dtype, n)
            row.update(max_abs_diff=diff, diff_against=f"jaxkin float64 ({peer.reference})")
            need = peer.bytes_per_config() * n
            if per_config is not None and per_config * n > cfg["max_call_s"]:
                row["status"] = (
                    f"skipped: predicted {per_config * n:.1f} s per call > {cfg['max_call_s']} s"
                )
            elif need > cfg["mem_limit"]:
                row["status"] = f"skipped: needs about {need / 1e9:.1f} GB"
            else:
                prepared = peer.prepare(self.q_pool[:n])
                row.update(self.timer.samples(lambda p=prepared: peer.run(p), n, ref))
                if n >= 100:  # N = 1 is all overhead: no prediction from it
                    per_config = float(np.median(row["samples_s"]))
                del prepared
            self.add(row)

    def _loop_peer(self, peer: P.Peer, diff: float, ref) -> None:
        cfg = self.cfg
        probe = peer.prepare(self.q_pool[:20])
        t = time.perf_counter()
        peer.run(probe)
        per = (time.perf_counter() - t) / len(probe)
        cap = int(min(cfg["loop_cap"], max(100, cfg["loop_target_s"] / max(per, 1e-9))))
        measured: dict[int, dict[str, Any]] = {}
        for n in cfg["ns"]:
            m = min(n, cap)
            row = _row(self.src.name, peer.label, "geometric", peer.dtype, n, n_timed=m)
            row.update(max_abs_diff=diff, diff_against=f"jaxkin float64 ({peer.reference})")
            if m not in measured:
                prepared = peer.prepare(self.q_pool[:m])
                measured[m] = self.timer.samples(lambda p=prepared: peer.run(p), m, ref)
            else:
                row["reused_from_n_timed"] = m
            row.update(measured[m])
            self.add(row)


# ---------------------------------------------------------------------------- environment


def _version(dist: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(dist)
    except PackageNotFoundError:
        return "not installed"


def machine_info() -> dict[str, Any]:
    import jaxlib

    cpu_models, mem, mhz, flags = [], None, None, set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                key, value = key.strip(), value.strip()
                if key == "model name":
                    cpu_models.append(value)
                elif key == "cpu MHz" and mhz is None:
                    mhz = value
                elif key == "flags" and not flags:
                    flags = set(value.split())
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal"):
                    mem = line.split(":", 1)[1].strip()
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = None
    try:
        import torch

        torch_threads = torch.get_num_threads()
    except Exception:
        torch_threads = None
    return dict(
        date_utc=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        cpu_model=sorted(set(cpu_models)),
        cpu_mhz=mhz,
        simd=[x for x in ("sse4_2", "avx", "avx2", "fma", "avx512f") if x in flags],
        logical_cpus=os.cpu_count(),
        cpus_usable=affinity,
        mem_total=mem,
        platform=platform.platform(),
        python=platform.python_version(),
        jax=jax.__version__,
        jaxlib=jaxlib.__version__,
        numpy=np.__version__,
        jaxkin=getattr(jk, "__version__", "?"),
        jaxkin_load_urdf=hasattr(jk, "load_urdf"),
        pinocchio=_version("pin"),
        example_robot_data=_version("example-robot-data"),
        pytorch_kinematics=_version("pytorch-kinematics"),
        torch=_version("torch"),
        torch_threads=torch_threads,
        mujoco=_version("mujoco"),
        roboticstoolbox=_version("roboticstoolbox-python"),
        jax_devices=[str(d) for d in jax.devices()],
        xla_flags=os.environ.get("XLA_FLAGS", ""),
    )


def dispatch_floor_s(cfg: dict[str, Any]) -> float:
    """Seconds per call of a trivial jitted function on a (6,) input (the dispatch floor)."""
    fn = jax.jit(lambda q: q + 1.0)
    q = jnp.zeros(6)
    res = Timer(cfg).samples(lambda: jax.block_until_ready(fn(q)), 1, None)
    return float(np.median(res["samples_s"]))


# ---------------------------------------------------------------------------- reporting


def _fmt_rate(x: float) -> str:
    if x >= 1e6:
        return f"{x / 1e6:.2f} M"
    if x >= 1e3:
        return f"{x / 1e3:.1f} k"
    return f"{x:.0f}"


def _fmt_n(n: int) -> str:
    if n >= 1_000_000 and n % 1_000_000 == 0:
        return f"{n // 1_000_000}M"
    if n >= 1000 and n % 1000 == 0:
        return f"{n // 1000}k"
    return str(n)


def _fmt_us(x: float) -> str:
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


def _cell(row: dict[str, Any] | None) -> str:
    if row is None:
        return ""
    if row["status"] != "ok":
        return "skipped" if row["status"].startswith("skipped") else "failed"
    cell = _fmt_rate(row["per_s"])
    if "ratio_vs_pin" in row:
        cell += f" ({row['ratio_vs_pin']:.2f}x)"
    if row.get("n_timed", row["n"]) != row["n"]:
        cell += "*"
    return cell


IMPL_ORDER = ("jaxkin", "pytorch_kinematics", "MuJoCo Batch", "MuJoCo (Python", "Robotics")


def _impl_key(impl: str) -> int:
    for i, prefix in enumerate(IMPL_ORDER):
        if impl.startswith(prefix):
            return i
    return len(IMPL_ORDER)


def pivot(rows: list[dict[str, Any]], robot: str, quantities: tuple[str, ...]) -> str:
    """Rates per N for one robot: one line per (implementation, quantity, dtype)."""
    sel = [
        r
        for r in rows
        if r["robot"] == robot and r["quantity"] in quantities and not r["impl"].endswith("single")
    ]
    ns = sorted({r["n"] for r in sel})
    keys: list[tuple[str, str, str]] = []
    for r in sel:
        key = (r["impl"], r["quantity"], r["dtype"])
        if key not in keys:
            keys.append(key)
    keys.sort(key=lambda k: (QUANTITIES.index(k[1]), _impl_key(k[0]), k[0], DTYPES.index(k[2])))
    head = "| implementation | quantity | dtype | " + " | ".join(f"N = {_fmt_n(n)}" for n in ns)
    head += " | max abs diff |\n|---|---|---|" + "---:|" * len(ns) + "---:|"
    lines = [head]
    for impl, quantity, dtype in keys:
        cells, diff, against = [], math.nan, ""
        for n in ns:
            match = [
                r
                for r in sel
                if (r["impl"], r["quantity"], r["dtype"], r["n"]) == (impl, quantity, dtype, n)
            ]
            row = match[0] if match else None
            cells.append(_cell(row))
            if row is not None and math.isnan(diff) and "max_abs_diff" in row:
                diff, against = row["max_abs_diff"], row.get("diff_against", "")
        label = impl if impl != "jaxkin" else "jaxkin jit(vmap)"
        d = f"{diff:.1e}" if not math.isnan(diff) else ""
        if against and not against.startswith("Pinocchio"):
            d += " (vs jaxkin)" if "world_aligned" in against else " (vs jaxkin WORLD)"
        lines.append(f"| {label} | {quantity} | {dtype} | " + " | ".join(cells) + f" | {d} |")
    # Pinocchio itself: the pooled interleaved reference samples of each quantity
    for quantity in quantities:
        pins = [
            s
            for r in sel
            if r["quantity"] == quantity and r["status"] == "ok"
            for s in r["pin_samples_s"]
        ]
        if pins:
            rate = _fmt_rate(1.0 / float(np.median(pins)))
            lines.append(
                f"| Pinocchio (Python loop, reference) | {quantity} | float64 | "
                + " | ".join(rate for _ in ns)
                + " | reference |"
            )
    return "\n".join(lines)


def single_table(rows: list[dict[str, Any]], floor_us: float) -> str:
    lines = [
        "| robot | dtype | jaxkin `jit(f)(q)` us/call (min - max) | jaxkin `jit(vmap(f))` N = 1 "
        "| Pinocchio one call | target |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        if r["impl"] != "jaxkin single" or r["status"] != "ok":
            continue
        vm = [
            x
            for x in rows
            if (x["robot"], x["impl"], x["quantity"], x["dtype"], x["n"])
            == (r["robot"], "jaxkin", "geometric", r["dtype"], 1)
            and x["status"] == "ok"
        ]
        pin = [x for x in rows if (x["robot"], x["impl"]) == (r["robot"], "pinocchio single")]
        lo, hi = min(r["samples_s"]) * 1e6, max(r["samples_s"]) * 1e6
        lines.append(
            f"| {r['robot']} | {r['dtype']} | {_fmt_us(r['us_each'])} ({_fmt_us(lo)} - "
            f"{_fmt_us(hi)}) | {_fmt_us(vm[0]['us_each']) + ' us' if vm else ''} "
            f"| {_fmt_us(pin[0]['us_each']) + ' us' if pin else ''} | <= 15 us |"
        )
    lines.append("")
    lines.append(f"Dispatch floor (a trivial jitted call on a (6,) array): {floor_us:.1f} us.")
    return "\n".join(lines)


def compile_table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| robot | quantity | dtype | trace + lower s (median; max) | XLA compile s (median; max) "
        "| first call after compile s (largest N) |",
        "|---|---|---|---:|---:|---:|",
    ]
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in rows:
        if r["impl"] == "jaxkin" and "compile_s" in r:
            groups.setdefault((r["robot"], r["quantity"], r["dtype"]), []).append(r)
    for (robot, quantity, dtype), rs in groups.items():
        low = [r["lower_s"] for r in rs]
        comp = [r["compile_s"] for r in rs]
        ok = [r for r in rs if "first_call_s" in r]
        first = f"{ok[-1]['first_call_s']:.3f} (N = {_fmt_n(ok[-1]['n'])})" if ok else ""
        lines.append(
            f"| {robot} | {quantity} | {dtype} | {np.median(low):.2f}; {max(low):.2f} "
            f"| {np.median(comp):.2f}; {max(comp):.2f} | {first} |"
        )
    singles = [r for r in rows if r["impl"] == "jaxkin single" and "first_call_s" in r]
    if singles:
        lines.append("")
        lines.append(
            "Single-configuration `jax.jit(lambda q: jk.geometric_jacobian(robot, q))`, first "
            "call (trace + compile + run): "
            + ", ".join(f"{r['robot']} {r['dtype']} {r['first_call_s']:.2f} s" for r in singles)
            + "."
        )
    return "\n".join(lines)


def _profile_n(rows: list[dict[str, Any]]) -> int:
    ns = sorted({r["n"] for r in rows if r["impl"] == "jaxkin" and r.get("hlo")})
    return 100_000 if 100_000 in ns else (ns[-1] if ns else 0)


def profile_table(rows: list[dict[str, Any]]) -> str:
    n = _profile_n(rows)
    lines = [
        f"Optimised HLO of each batched kernel at N = {_fmt_n(n)}: loop fusions (each one pass "
        "over the batch; `while` loops for the scan path), sin + cos ops compiled vs emitted by "
        "jaxkin (for the scan path: in the loop body, i.e. per joint step), and the compiled "
        "kernel's temporaries against its input + output per configuration (XLA's memory "
        "analysis).",
        "",
        "| robot | quantity | dtype | fusions | while loops | sin+cos compiled / emitted "
        "| temp bytes / config | in + out bytes / config | rate |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if r["impl"] != "jaxkin" or r["n"] != n or not r.get("hlo"):
            continue
        h = r["hlo"]
        rate = _fmt_rate(r["per_s"]) + "/s" if r["status"] == "ok" else r["status"].split(":")[0]
        lines.append(
            f"| {r['robot']} | {r['quantity']} | {r['dtype']} | {h.get('fusions', '')} "
            f"| {h.get('whiles', '')} | {h.get('sincos_compiled', '')} / "
            f"{h.get('sincos_emitted', '')} | {h.get('temp_bytes_per_config', math.nan):.0f} "
            f"| {h.get('io_bytes_per_config', math.nan):.0f} | {rate} |"
        )
    return "\n".join(lines)


def _find(rows, **kw) -> dict[str, Any] | None:
    for r in rows:
        if all(r.get(k) == v for k, v in kw.items()) and r["status"] == "ok":
            return r
    return None


def headline(result: dict[str, Any]) -> str:
    rows = result["rows"]
    h = HEADLINE
    parts = []
    where = dict(robot=h["robot"], impl="jaxkin", quantity=h["quantity"], n=h["n"])
    r64 = _find(rows, dtype="float64", **where)
    r32 = _find(rows, dtype="float32", **where)
    if r64 is None:
        return (
            f"**Headline**: not available from this run (no Panda geometric row at N = "
            f"{_fmt_n(h['n'])}; this run stopped at N = {_fmt_n(max(result['config']['ns']))})."
        )
    parts.append(
        f"**Headline** (Panda from example-robot-data's URDF, 6x7 geometric Jacobian, N = "
        f"{_fmt_n(h['n'])}): jaxkin computes **{_fmt_rate(r64['per_s'])} Jacobians/s in float64, "
        f"{r64['ratio_vs_pin']:.2f}x Pinocchio called from Python** "
        f"({_fmt_rate(r64['pin_per_s'])}/s, measured interleaved in the same process)"
    )
    if r32 is not None:
        parts.append(
            f", and **{_fmt_rate(r32['per_s'])}/s in float32** ({r32['ratio_vs_pin']:.2f}x)"
        )
    s = _find(rows, robot=h["robot"], impl="jaxkin single", dtype="float64")
    if s is not None:
        parts.append(
            f". One configuration from Python (`jax.jit(lambda q: jk.geometric_jacobian(robot, "
            f"q))(q)`): {_fmt_us(s['us_each'])} us per call (target <= 15 us; dispatch floor "
            f"{result['dispatch_floor_us']:.1f} us)"
        )
    return "".join(parts) + "."


def limits(result: dict[str, Any]) -> str:
    rows = result["rows"]
    h = HEADLINE
    out = []
    for dtype in DTYPES:
        where = dict(robot=h["robot"], impl="jaxkin", quantity=h["quantity"], n=h["n"])
        r = _find(rows, dtype=dtype, **where)
        if r is None:
            continue
        rate = r["per_s"]
        sc = BOUNDS[f"sincos_{dtype}"]
        sc_txt = (
            f"{rate / sc:.0%} of the ~{sc / 1e6:.0f} M/s sin/cos bound"
            if not isinstance(sc, tuple)
            else f"{rate / sc[1]:.0%} - {rate / sc[0]:.0%} of the {sc[0] / 1e6:.0f} - "
            f"{sc[1] / 1e6:.0f} M/s sin/cos bound"
        )
        mem = BOUNDS[f"memory_{dtype}"]
        hlo = r.get("hlo", {})
        out.append(
            f"- Panda geometric, {dtype}, N = {_fmt_n(h['n'])}: {_fmt_rate(rate)}/s = {sc_txt}, "
            f"{rate / mem:.0%} of the ~{mem / 1e6:.0f} M/s memory-bandwidth bound. Compiled: "
            f"{hlo.get('fusions', '?')} loop fusions, {hlo.get('sincos_compiled', '?')} sin/cos "
            f"ops for the {hlo.get('sincos_emitted', '?')} jaxkin emits, "
            f"{hlo.get('temp_bytes_per_config', math.nan):.0f} bytes of temporaries per "
            f"Jacobian besides {hlo.get('io_bytes_per_config', math.nan):.0f} bytes of input "
            "and output."
        )
    return "\n".join(out)


def machine_line(result: dict[str, Any]) -> str:
    m = result["machine"]
    la = result["load_average_1_5_15min"]
    return (
        f"Run: {result['mode']}, {m['date_utc']}, {result['elapsed_s']:.0f} s. Machine: "
        f"{', '.join(m['cpu_model'])} ({m['cpu_mhz']} MHz; {', '.join(m['simd'])}), "
        f"{m['cpus_usable']} usable CPUs, {m['mem_total']} RAM, {', '.join(m['jax_devices'])}; "
        f"{m['platform']}. Load average (1 min) {la['before'][0]:.2f} before, "
        f"{la['after'][0]:.2f} after. Versions: Python {m['python']}, jax {m['jax']}, jaxlib "
        f"{m['jaxlib']}, NumPy {m['numpy']}, jaxkin {m['jaxkin']}, pin {m['pinocchio']}, "
        f"example-robot-data {m['example_robot_data']}, pytorch-kinematics "
        f"{m['pytorch_kinematics']} (torch {m['torch']}, default {m['torch_threads']} "
        f"threads), mujoco {m['mujoco']}, roboticstoolbox-python {m['roboticstoolbox']}."
    )


def results_markdown(result: dict[str, Any]) -> str:
    rows = result["rows"]
    parts = [
        "_Generated by `python3 -m bench --write-readme` from "
        f"`results/{result.get('json_name', 'latest.json')}`; do not edit by hand._",
        "",
        headline(result),
        "",
        machine_line(result),
        "",
    ]
    if result["mode"] != "full":
        parts += [
            "**This is a `--quick` smoke run (small N, 2 repeats, possibly a loaded machine): "
            "its numbers only show that everything runs. Run `python3 -m bench --write-readme` "
            "on a quiet machine for the real tables.**",
            "",
        ]
    parts += [
        "Cells: Jacobians (or twists) per second, median of the samples, and in brackets the "
        "ratio to Pinocchio from Python measured interleaved with that row (above 1: faster). "
        "`*`: a Python-loop peer timed over fewer configurations than N (its rate does not "
        "depend on N). `skipped`: predicted call time or memory over the limits (JSON: "
        "`status`). max abs diff: jaxkin rows against Pinocchio (same frame, float64 "
        "reference); peer rows against jaxkin float64.",
        "",
    ]
    for name, info in result["robots"].items():
        parts += [
            f"### {name} ({info['dof']} DOF)",
            "",
            f"URDF: {info['urdf']}. jaxkin: `{info['jaxkin']}`"
            + (" (lax.scan path)" if info.get("scan_path") else "")
            + f"; tip pose vs Pinocchio {info['tip_pose_diff_vs_pinocchio']:.1e}.",
        ]
        if info.get("peers_failed"):
            parts.append(
                "Unavailable peers: "
                + "; ".join(f"{k}: {v}" for k, v in info["peers_failed"].items())
                + "."
            )
        parts += ["", pivot(rows, name, QUANTITIES), ""]
    parts += [
        "### One configuration from Python (N = 1)",
        "",
        single_table(rows, result["dispatch_floor_us"]),
        "",
        "### Compile times (jaxkin, per batch shape)",
        "",
        compile_table(rows),
        "",
        "### Profile of the compiled kernels",
        "",
        profile_table(rows),
        "",
        "### Distance from the machine limits (PERFORMANCE.md)",
        "",
        limits(result) or "Not available from this run (no Panda row at N = 100k).",
        "",
        "### Scale: 10 million configurations",
        "",
        scale_markdown(),
    ]
    return "\n".join(parts)


def scale_markdown(path: Path = RESULTS_DIR / "scale.json") -> str:
    """The last ``python3 -m bench.scale`` run (results/scale.json), if there is one."""
    if not path.is_file():
        return "No `python3 -m bench.scale` result yet (results/scale.json)."
    s = json.loads(path.read_text())
    compile_s = s.get("compile_s", s.get("first_chunk_s", math.nan))
    return (
        f"`python3 -m bench.scale` (results/scale.json, {s.get('date_utc', 'date not recorded')}, "
        f"load average {s.get('load_average_1min', math.nan):.2f}): {s['n']:,} Panda "
        f"configurations -> {s['what']} ({s['dtype']}), inputs {s['inputs']}, chunks of "
        f"{s['chunk_size']:,}: map {s['map_s']:.1f} s = "
        f"**{s['throughput_per_s'] / 1e6:.2f} M/s** (compile {compile_s:.2f} s), wall "
        f"{s['wall_s']:.1f} s ({s['throughput_wall_per_s'] / 1e6:.2f} M/s, input generation and "
        f"packing included); output {s['out_bytes'] / 1e9:.2f} GB on disk, spot check max abs "
        f"diff {s['spot_check_max_abs_diff']:.1e}; **peak RSS {s['peak_rss_mb']:.0f} MiB** "
        f"(target <= {s.get('target_peak_rss_mb', 2048)} MiB; {s['rss_mb_after_imports']:.0f} "
        "MiB after imports); files deleted afterwards."
    )


def write_readme(result: dict[str, Any], path: Path = README) -> None:
    text = path.read_text()
    if MARK_START not in text or MARK_END not in text:
        raise SystemExit(f"{path} has no {MARK_START} ... {MARK_END} markers")
    head, rest = text.split(MARK_START, 1)
    _, tail = rest.split(MARK_END, 1)
    body = results_markdown(result)
    path.write_text(f"{head}{MARK_START}\n{body}\n{MARK_END}{tail}")


# ---------------------------------------------------------------------------- plot

STYLES = {
    "float64": "-",
    "float32": "--",
}


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robots = list(dict.fromkeys(r["robot"] for r in rows))
    fig, axes = plt.subplots(2, len(robots), figsize=(5.6 * len(robots), 8.5), squeeze=False)
    colors: dict[str, str] = {}
    for col, name in enumerate(robots):
        for row_i, quantities in enumerate((("geometric",), ("analytical", "twist"))):
            ax = axes[row_i][col]
            sel = [
                r
                for r in rows
                if r["robot"] == name
                and r["quantity"] in quantities
                and r["status"] == "ok"
                and not r["impl"].endswith("single")
            ]
            keys = list(dict.fromkeys((r["impl"], r["quantity"], r["dtype"]) for r in sel))
            for impl, quantity, dtype in keys:
                pts = sorted(
                    (r["n"], r["per_s"])
                    for r in sel
                    if (r["impl"], r["quantity"], r["dtype"]) == (impl, quantity, dtype)
                )
                ckey = impl if row_i == 0 else f"{impl} {quantity}"
                if ckey not in colors:
                    colors[ckey] = f"C{len(colors) % 10}"
                label = f"{impl} {dtype}" if row_i == 0 else f"{impl} {quantity} {dtype}"
                ax.loglog(
                    [p[0] for p in pts],
                    [p[1] for p in pts],
                    STYLES[dtype],
                    marker="o" if dtype == "float64" else "s",
                    color=colors[ckey],
                    label=label,
                    markersize=4,
                )
            for quantity, ls in zip(quantities, (":", "-."), strict=False):
                pins = [
                    s
                    for r in sel
                    if r["quantity"] == quantity and r["impl"] == "jaxkin"
                    for s in r["pin_samples_s"]
                ]
                if pins:
                    ax.axhline(
                        1.0 / float(np.median(pins)),
                        color="k",
                        linestyle=ls,
                        label=f"Pinocchio {quantity} (Python loop)",
                    )
            ax.set_title(f"{name}: {' and '.join(quantities)}")
            ax.set_xlabel("batch size N")
            ax.set_ylabel("per second (median)")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------------------- main


def _print_tables(result: dict[str, Any], out_path: Path) -> None:
    print()
    print(headline(result))
    print()
    print(machine_line(result))
    for name in result["robots"]:
        print(f"\n### {name}\n")
        print(pivot(result["rows"], name, QUANTITIES))
    print("\n### One configuration from Python\n")
    print(single_table(result["rows"], result["dispatch_floor_us"]))
    print("\n### Compile times\n")
    print(compile_table(result["rows"]))
    print("\n### Profile\n")
    print(profile_table(result["rows"]))
    lim = limits(result)
    if lim:
        print("\n### Machine limits\n")
        print(lim)
    print(f"\n-> {out_path}")


def _parse_ns(text: str) -> tuple[int, ...]:
    return tuple(int(float(x)) for x in text.split(",") if x)


def main(argv: list[str] | None = None) -> int:
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
    args = parser.parse_args(argv)

    if args.from_json is not None:
        result = json.loads(args.from_json.read_text())
        result.setdefault("json_name", args.from_json.name)
        if not args.no_plot:
            plot(result["rows"], args.from_json.with_suffix(".png"))
        _print_tables(result, args.from_json)
        if args.write_readme:
            write_readme(result)
        return 0

    # A bench process may change the global JAX configuration (jaxkin itself never does).
    jax.config.update("jax_enable_x64", True)
    cfg = dict(QUICK if args.quick else FULL)
    if args.ns:
        cfg["ns"] = _parse_ns(args.ns)
    out_path = args.out or RESULTS_DIR / ("quick.json" if args.quick else "latest.json")
    t_start = time.perf_counter()
    load_before = os.getloadavg()
    machine = machine_info()  # before any peer changes torch's thread count
    floor = dispatch_floor_s(cfg)

    rng = np.random.default_rng(20240607)
    rows: list[dict[str, Any]] = []
    robots: dict[str, Any] = {}
    names = [x for x in args.robots.split(",") if x] or None
    for src in P.robot_sources(names):
        _log(f"{src.name}: {src.origin}")
        rb = RobotBench(src, cfg, rng)
        robots[src.name] = rb.info
        rb.single()
        rb.jaxkin()
        if not args.no_peers:
            rb.peers()
        rows += rb.rows
        del rb
        gc.collect()
    elapsed = time.perf_counter() - t_start

    result = dict(
        benchmark="Jacobians and twists: jaxkin vs Pinocchio (Python), pytorch_kinematics, "
        "MuJoCo, Robotics Toolbox on the same URDFs",
        mode="quick" if args.quick else "full",
        config={k: v for k, v in cfg.items()},
        machine=machine,
        load_average_1_5_15min=dict(before=load_before, after=os.getloadavg()),
        dispatch_floor_us=floor * 1e6,
        robots=robots,
        elapsed_s=elapsed,
        json_name=out_path.name,
        rows=rows,
    )
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps(result, indent=1, default=float) + "\n")
    if not args.no_plot:
        plot(rows, out_path.with_suffix(".png"))
    _print_tables(result, out_path)
    if args.write_readme:
        write_readme(result)
        print(f"-> {README} (results section)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
