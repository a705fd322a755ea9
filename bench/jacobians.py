"""Jacobian benchmark: jaxkin against Pinocchio, pytorch_kinematics, MuJoCo and the Robotics
Toolbox, on the same URDFs (Panda, UR5, a 32-joint chain; Talos and G1 with free-flyer roots).

For each robot (see :mod:`bench.peers`), quantity and dtype:

* jaxkin, batched: ``jax.jit(jax.vmap(f))`` with ``f`` one of ``jk.geometric_jacobian(robot, q)``
  (tip, world-aligned), ``jk.analytical_jacobian(robot, q, "rpy", return_margin=True)`` and
  ``jk.twist(robot, q, qd)``, for N = 1, 100, 10k, 100k, 1M; compile apart (``lower`` and
  ``compile`` timed), the optimised HLO profiled (fusions, loops, sin/cos, temporaries);
* jaxkin, into a preallocated array (float64 geometric Jacobians, N >= :data:`CHUNKED_FROM_N`):
  ``jk.batch.chunked_map(f, q, out=out)`` with its default chunks (:meth:`Bench.chunked_rows`),
  the comparison with Pinocchio's stored loop on equal terms;
* page faults per call of every jaxkin row (:func:`faults_per_call`), and what one costs on
  this machine (``bench.report.page_fault_us``, once per run);
* jaxkin, one configuration from Python: ``jax.jit(lambda q: jk.geometric_jacobian(robot, q))(q)``;
* peers (geometric Jacobian): pytorch_kinematics batched (float32, float64), MuJoCo (a Python
  loop, and ``mujoco.batch.Batch``), Robotics Toolbox ETS (a Python loop); Python loops time
  ``min(N, cap)`` configurations;
* Pinocchio from Python, one call per configuration on pre-built q arrays, is the reference:
  one Pinocchio sample of the same quantity follows every sample of every row, in the same
  process, and each row's ratio is the row's rate over the Pinocchio rate measured beside it;
  for geometric Jacobians two loops are sampled (:class:`PinReference`): each result stored into
  a preallocated array (``ratio_vs_pin_stored``, the loop of a user who wants the N Jacobians)
  and results dropped (``ratio_vs_pin``);
* free-flyer humanoids (:class:`FreeFlyerBench`, ``bench.peers.HUMANOIDS``): Talos one hand in
  ``world_aligned`` and ``local``, G1 both feet and both hands in one
  ``jk.geometric_jacobian(robot, q, frame=[...])`` call, float64, against
  ``bench.peers.PinocchioFrames`` (both loops);
* every row is checked numerically before it is timed: jaxkin against Pinocchio (a float64 row
  whose largest difference over ``max(1, max |value|)`` exceeds :data:`CHECK_TOL` is marked
  failed and not timed), peers against jaxkin (float64).

Configurations come from ``jk.sample_configurations`` (fixed keys), joint rates from
:func:`bench.report.joint_rates`. This module measures; :mod:`bench.jacobian_report` prints the
tables, writes the README section and plots.

Usage: ``python3 -m bench [--quick] [--robots panda,ur5,chain32,talos,g1] [--ns 1,100]
[--write-readme] [--from-json PATH]``. Writes ``bench/results/latest.json`` and ``latest.png``
(``quick.*`` with ``--quick``), prints the tables; ``--write-readme`` replaces the generated
section of bench/README.md.
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
    page_fault_us,
    page_faults,
    timed,
    write_json,
)

SEED = 20240607  # configurations and joint rates of every robot
CHECK_TOL = 1e-12  # float64 rows: largest difference from Pinocchio over max(1, max |value|)

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
    """Counts in the optimised HLO (fusions, while loops, dots, multiplies, sin and cos) against
    the sin/cos jaxkin emitted (StableHLO), the widest concatenate (XLA's CPU compiler fuses
    nothing into one of more than 8 operands: each operand is then a loop of its own), and the
    compiled kernel's memory per configuration."""
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
        multiplies=len(re.findall(r" multiply\(", text)),
        widest_concatenate=max(
            (c.count("%") for c in re.findall(r" concatenate\(([^)]*)\)", text)), default=0
        ),
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
        if row.get("pin_stored_samples_s"):
            pin = median(row["pin_stored_samples_s"])
            row["pin_stored_per_s"] = 1.0 / pin
            row["ratio_vs_pin_stored"] = pin / per
    return row


def check(row: dict[str, Any], got: np.ndarray, want: np.ndarray, against: str) -> None:
    """Record the largest difference of ``got`` from ``want``; a float64 row whose difference
    over ``max(1, max |want|)`` exceeds :data:`CHECK_TOL` is marked failed (and not timed)."""
    diff = float(np.abs(got - want).max())
    scaled = diff / max(1.0, float(np.abs(want).max()))
    row.update(max_abs_diff=diff, scaled_diff=scaled, diff_against=against)
    if row["dtype"] == "float64" and not scaled <= CHECK_TOL:
        row["status"] = f"failed: differs from {against} by {scaled:.1e} (scaled) > {CHECK_TOL:g}"


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
    if "ratio_vs_pin_stored" in row:
        ratio += f" ({row['ratio_vs_pin_stored']:.2f}x its stored loop)"
    diff = row.get("max_abs_diff", math.nan)
    log(f"{what}: {comp}{fmt_rate(row['per_s'])}/s{ratio}, diff {diff:.1e}")


def faults_per_call(call: Callable[[], Any], calls: int = 3) -> float:
    """Page faults (first writes to new pages) per ``call()``, over ``calls`` calls after one
    warm-up: for a jitted kernel, its output and temporaries paged in anew on every call."""
    call()
    before = page_faults()
    for _ in range(calls):
        call()
    return (page_faults() - before) / calls


CHUNKED_FROM_N = 10_000
"""``jk.batch.chunked_map`` rows are measured from this N up (below it one chunk is the whole
batch: the ``jit(vmap)`` row plus a copy)."""


def _too_slow(per_config: float | None, n: int, cfg: dict[str, Any]) -> str | None:
    """The skip status of an N whose call, predicted from the last rate, would be too long."""
    if per_config is None or per_config * n <= cfg["max_call_s"]:
        return None
    return f"skipped: predicted {per_config * n:.1f} s per call > {cfg['max_call_s']} s"


# ---------------------------------------------------------------------------- Pinocchio


class PinReference:
    """Interleaved Pinocchio samples (seconds per configuration): calling it times the loop
    without storing the results (returned: the ``Timer`` reference, ``pin_samples_s``) and, when
    there is one, the loop that stores each result into a preallocated array (collected in
    ``stored``: ``pin_stored_samples_s``), the two taking turns at going first. Each loop runs
    over the first ``m`` prepared configurations, ``m`` chosen so that a sample lasts about
    ``pin_target_s``."""

    def __init__(
        self,
        cfg: dict[str, Any],
        make: Callable[[int], tuple[Callable, Callable | None]],
        inputs: tuple[list, ...],
    ):
        bare, _ = make(50)
        _, t = timed(lambda: bare(*(x[:50] for x in inputs)))
        m = int(min(len(inputs[0]), max(200, cfg["pin_target_s"] / max(t / 50, 1e-9))))
        self.bare, self.stored_loop = make(m)
        self.inputs = tuple(x[:m] for x in inputs)
        self.stored: list[float] = []
        self.calls = 0

    def _time(self, loop: Callable) -> float:
        return timed(lambda: loop(*self.inputs))[1] / len(self.inputs[0])

    def __call__(self) -> float:
        if self.stored_loop is None:
            return self._time(self.bare)
        self.calls += 1
        if self.calls % 2:
            self.stored.append(self._time(self.stored_loop))
            return self._time(self.bare)
        bare = self._time(self.bare)
        self.stored.append(self._time(self.stored_loop))
        return bare

    def take(self) -> dict[str, list[float]]:
        """The stored loop's samples since the last call (for the row just timed)."""
        out, self.stored = self.stored, []
        return dict(pin_stored_samples_s=out) if out else {}


# ---------------------------------------------------------------------------- one robot


class Bench:
    """What the per-robot benchmarks share: timing against an interleaved reference, the
    compiled jaxkin row (compile apart, HLO profile, numerical check before timing)."""

    def __init__(self, cfg: dict[str, Any]):
        self.cfg = cfg
        self.timer = Timer(cfg)
        self.rows: list[dict[str, Any]] = []

    def add(self, row: dict[str, Any]) -> dict[str, Any]:
        _finish(row)
        self.rows.append(row)
        _progress(row)
        return row

    def samples(self, call: Callable[[], Any], n: int, ref: PinReference | None) -> dict:
        """``Timer.samples`` and, with a reference, its stored-loop samples."""
        out = self.timer.samples(call, n, ref)
        if ref is not None:
            out.update(ref.take())
        return out

    def compiled_row(self, row, fn, args, want: Callable[[int], np.ndarray], ref, pick=None):
        """Lower and compile ``fn`` for ``args`` (timed apart), profile its HLO, skip it when it
        needs more than ``mem_limit``, check its first ``check`` answers against ``want(k)``
        (Pinocchio) and time it against ``ref`` if they agree."""
        cfg, n = self.cfg, row["n"]
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
        k = min(n, cfg["check"])
        got = np.asarray(out if pick is None else pick(out), dtype=np.float64)[:k]
        del out
        check(row, got, want(k), "Pinocchio")
        if row["status"] == "ok":
            row.update(self.samples(lambda: jax.block_until_ready(fn(*args)), n, ref))
            row["page_faults_per_call"] = faults_per_call(lambda: jax.block_until_ready(fn(*args)))

    def chunked_rows(self, robot: str, quantity: str, f, q_pool: np.ndarray, want, ref) -> None:
        """``jk.batch.chunked_map(f, q, out=out)`` (float64, default chunks) for every N >=
        :data:`CHUNKED_FROM_N`: the N results written into a preallocated numpy array, as
        Pinocchio's stored loop writes them. The first call (trace, compile, run) is timed
        apart (``first_call_s``; ``chunk_compile_s`` from its stats) and its results allocate
        ``out``, which every later call fills again; ``want(q, k)`` is Pinocchio's first ``k``
        answers for configurations ``q``."""
        cfg, per_config = self.cfg, None
        for n in (n for n in cfg["ns"] if n >= CHUNKED_FROM_N):
            row = _row(robot, "jaxkin chunked_map", quantity, "float64", n)
            q = q_pool[:n]
            spec = jax.eval_shape(f, q[0])
            out_bytes = n * math.prod(spec.shape) * np.dtype(spec.dtype).itemsize
            row["status"] = _too_slow(per_config, n, cfg) or "ok"
            if out_bytes > cfg["mem_limit"]:
                limit = cfg["mem_limit"] / 1e9
                row["status"] = f"skipped: the results take {out_bytes / 1e9:.1f} GB > {limit:g} GB"
            if row["status"] == "ok":
                (out, stats), row["first_call_s"] = timed(
                    lambda q=q: jk.batch.chunked_map(f, q, return_stats=True)
                )
                row.update(chunk_size=stats.chunk_size, chunk_compile_s=stats.compile_seconds)
                k = min(n, cfg["check"])
                check(row, out[:k], want(q, k), "Pinocchio")
            if row["status"] == "ok":

                def call(q=q, out=out):
                    jk.batch.chunked_map(f, q, out=out)

                row.update(self.samples(call, n, ref))
                row["page_faults_per_call"] = faults_per_call(call)
                per_config = median(row["samples_s"])
                del out
            self.add(row)


class RobotBench(Bench):
    """Everything measured for one robot."""

    def __init__(self, src: P.RobotSource, cfg: dict[str, Any], seed: int):
        super().__init__(cfg)
        self.src = src
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

    def _configurations(self, n: int, key) -> np.ndarray:
        return np.asarray(jk.sample_configurations(self.r64, n, key), dtype=np.float64)

    def pin_ref(self, quantity: str) -> PinReference:
        """Interleaved Pinocchio samples of ``quantity`` (the geometric Jacobian also with each
        result stored into a preallocated array)."""
        loop = self.pin.loop(quantity)

        def make(m: int):
            return loop, (self.pin.stored_loop(m) if quantity == "geometric" else None)

        return PinReference(self.cfg, make, (self.pin_q, self.pin_qd))

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
                if (quantity, dtype) == ("geometric", "float64"):
                    self.chunked_rows(
                        self.src.name,
                        quantity,
                        lambda q, robot=robot: jk.geometric_jacobian(robot, q),
                        self.q_pool,
                        lambda q, k: _pin_values(self.pin, "geometric", q[:k], None),
                        ref,
                    )
                jax.clear_caches()

    def _jaxkin_row(self, row, fn, ref) -> None:
        n, quantity, dtype = row["n"], row["quantity"], row["dtype"]
        q64, qd64 = self.q_pool[:n], self.qd_pool[:n]
        args = [jnp.asarray(q64.astype(dtype))]
        if quantity == "twist":
            args.append(jnp.asarray(qd64.astype(dtype)))

        def want(k: int) -> np.ndarray:
            return _pin_values(self.pin, quantity, q64[:k], qd64[:k])

        pick = (lambda out: out[0]) if quantity == "analytical" else None
        self.compiled_row(row, fn, args, want, ref, pick)

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
            check(row, J, self.pin.geometric(q64), "Pinocchio")
            if row["status"] == "ok":
                row.update(self.samples(lambda fn=fn, q=q: jax.block_until_ready(fn(q)), 1, ref))
            self.add(row)
        # Pinocchio, one call for one configuration (per-call microseconds)
        pin_one = self.pin.loop("geometric")
        q1 = [np.ascontiguousarray(q64)]
        row = _row(self.src.name, "pinocchio single", "geometric", "float64", 1)
        row.update(self.samples(lambda: pin_one(q1, q1), 1, None))
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
                row.update(self.samples(lambda p=prepared: peer.run(p), n, ref))
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
                measured[m] = self.samples(lambda p=prepared: peer.run(p), m, ref)
            else:
                row["reused_from_n_timed"] = m
            row.update(measured[m])
            self.add(row)


class FreeFlyerBench(Bench):
    """A free-flyer humanoid (``bench.peers.HUMANOIDS``): for each of its cases, jaxkin
    ``jax.jit(jax.vmap(lambda q: jk.geometric_jacobian(robot, q, frame=..., reference=...)))``
    in float64 against Pinocchio's loops on the same configurations (:class:`PinReference`:
    results dropped, and stored into a preallocated array), each row checked against Pinocchio
    before it is timed."""

    def __init__(self, src: P.RobotSource, cfg: dict[str, Any], seed: int):
        super().__init__(cfg)
        self.src = src
        self.r64, how = P.jaxkin_robot(src, np.float64)
        key = jax.random.key(seed)
        self.q_pool = self._configurations(max(cfg["ns"]), jax.random.fold_in(key, 0))
        self.pin_q = self._configurations(cfg["pin_configs"], jax.random.fold_in(key, 1))
        self.info = dict(
            urdf=src.origin,
            tip=src.tip,
            dof=self.r64.nv,
            nq=self.r64.nq,
            n_joints=self.r64.n_joints,
            jaxkin=how,
            floating_base=True,
            scan_path=bool(jk.kinematics.uses_scan(self.r64)),
            cases={},
            peers={},
            peers_failed={},
        )

    def _configurations(self, n: int, key) -> np.ndarray:
        return np.asarray(jk.sample_configurations(self.r64, n, key), dtype=np.float64)

    def peers(self) -> None:
        """Record why each batched peer is not timed on a free-flyer robot (and what checks
        were possible)."""
        try:
            why = P.torch_free_flyer_check(self.src, self.r64, self.q_pool[:2])
        except Exception as e:
            why = f"{type(e).__name__}: {e}"
        self.info["peers_failed"]["pytorch_kinematics"] = why
        log(f"  {self.src.name}: pytorch_kinematics: {why}")

    def run(self) -> None:
        for case in self.src.cases:
            try:
                pin = P.PinocchioFrames(self.src, self.r64, case)
            except Exception as e:  # reported, not fatal
                self.info["cases"][case.quantity] = dict(error=f"{type(e).__name__}: {e}")
                log(f"  {self.src.name} {case.quantity}: Pinocchio failed: {e}")
                continue
            self._case(case, pin)
            jax.clear_caches()

    def _case(self, case: P.Case, pin: P.PinocchioFrames) -> None:
        cfg, robot = self.cfg, self.r64
        frame = list(case.frames) if case.several else case.frames[0]
        q4 = self.q_pool[:4]
        poses = np.stack([np.asarray(jk.fk(robot, q, frame=list(case.frames))) for q in q4])
        J4 = pin.jacobians(q4)
        self.info["cases"][case.quantity] = dict(
            frames=list(case.frames),
            reference=case.reference,
            jaxkin=f"jax.jit(jax.vmap(lambda q: jk.geometric_jacobian(robot, q, frame={frame!r}, "
            f"reference={case.reference!r})))",
            pinocchio=pin.how,
            pose_diff_vs_pinocchio=float(np.abs(poses - pin.poses(q4)).max()),
            nonzero_columns=int((np.abs(J4).max(axis=tuple(range(J4.ndim - 1))) > 0).sum()),
        )
        pin_qs = pin.prepare(self.pin_q)
        ref = PinReference(cfg, lambda m: (pin.loop(False, m), pin.loop(True, m)), (pin_qs,))
        fn = jax.jit(
            jax.vmap(
                lambda q: jk.geometric_jacobian(robot, q, frame=frame, reference=case.reference)
            )
        )
        per_config = None  # seconds per configuration at the last N >= 100
        for n in cfg["ns"]:
            row = _row(self.src.name, "jaxkin", case.quantity, "float64", n)
            skip = _too_slow(per_config, n, cfg)
            if skip:
                row["status"] = skip
            else:
                q64 = self.q_pool[:n]
                self.compiled_row(
                    row, fn, [jnp.asarray(q64)], lambda k, q=q64: pin.jacobians(q[:k]), ref
                )
                if row["status"] == "ok" and n >= 100:
                    per_config = median(row["samples_s"])
            self.add(row)
        del fn
        self.chunked_rows(
            self.src.name,
            case.quantity,
            lambda q: jk.geometric_jacobian(robot, q, frame=frame, reference=case.reference),
            self.q_pool,
            lambda q, k: pin.jacobians(q[:k]),
            ref,
        )


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
    parser.add_argument(
        "--robots", default="", help="comma-separated subset of panda,ur5,chain32,talos,g1"
    )
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
    fault_us = page_fault_us()
    rows: list[dict[str, Any]] = []
    robots: dict[str, Any] = {}
    names = [x for x in args.robots.split(",") if x] or None
    for src in P.robot_sources(names):
        log(f"{src.name}: {src.origin}")
        if src.floating_base:
            rb = FreeFlyerBench(src, cfg, SEED)
            robots[src.name] = rb.info
            rb.run()
            if not args.no_peers:
                rb.peers()
        else:
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
        page_fault_us=fault_us,
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
