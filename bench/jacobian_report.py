"""What the Jacobian benchmark reports: the tables it prints, the generated results section of
bench/README.md (between :data:`MARK_START` and :data:`MARK_END`), and the plot.

Everything here reads a result (the dictionary :mod:`bench.jacobians` measures and writes as JSON,
or an earlier run's JSON: ``python3 -m bench --from-json PATH``) and measures nothing.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .report import (
    HERE,
    RESULTS_DIR,
    fmt_diff,
    fmt_n,
    fmt_rate,
    fmt_us,
    markdown_table,
    median,
    replace_section,
)

README = HERE / "README.md"
MARK_START, MARK_END = "<!-- results:start -->", "<!-- results:end -->"

QUANTITIES = ("geometric", "analytical", "twist")
DTYPES = ("float64", "float32")
HEADLINE = dict(robot="panda", quantity="geometric", n=100_000)
# Bounds of this machine for a constant-folded 7-DOF Panda Jacobian (jacobians per second):
# XLA's CPU sin/cos throughput for the 7 sin/cos pairs, and memory bandwidth (about 25 GB/s)
# for its 392 bytes of input and output in float64 (196 in float32). See bench/README.md.
BOUNDS = dict(
    sincos_float64=10e6,
    sincos_float32=(15e6, 23e6),
    memory_float64=35e6,
    memory_float32=65e6,
)
Rows = list[dict[str, Any]]

# ---------------------------------------------------------------------------- tables


def _cell(row: dict[str, Any] | None) -> str:
    if row is None:
        return ""
    if row["status"] != "ok":
        return "skipped" if row["status"].startswith("skipped") else "failed"
    cell = fmt_rate(row["per_s"]) + _ratios(row)
    if row.get("n_timed", row["n"]) != row["n"]:
        cell += "*"
    return cell


IMPL_ORDER = ("jaxkin", "pytorch_kinematics", "MuJoCo Batch", "MuJoCo (Python", "Robotics")


def _impl_key(impl: str) -> int:
    for i, prefix in enumerate(IMPL_ORDER):
        if impl.startswith(prefix):
            return i
    return len(IMPL_ORDER)


def _pivot_line(key: tuple[str, str, str], ns: list[int], by_key: dict) -> list[str]:
    """One implementation's cells (a rate per N) and its check against the reference."""
    impl, quantity, dtype = key
    cells, diff, against = [], math.nan, ""
    for n in ns:
        row = by_key.get((*key, n))
        cells.append(_cell(row))
        if row is not None and math.isnan(diff) and "max_abs_diff" in row:
            diff, against = row["max_abs_diff"], row.get("diff_against", "")
    d = fmt_diff(diff)
    if against and not against.startswith("Pinocchio"):
        d += " (vs jaxkin)" if "world_aligned" in against else " (vs jaxkin WORLD)"
    label = impl if impl != "jaxkin" else "jaxkin jit(vmap)"
    return [label, quantity, dtype, *cells, d]


def pivot(rows: Rows, robot: str, quantities: tuple[str, ...]) -> str:
    """Rates per N for one robot: one line per (implementation, quantity, dtype), then the
    Pinocchio reference of each quantity (its interleaved samples pooled)."""
    sel = [
        r
        for r in rows
        if r["robot"] == robot and r["quantity"] in quantities and not r["impl"].endswith("single")
    ]
    ns = sorted({r["n"] for r in sel})
    keys = list(dict.fromkeys((r["impl"], r["quantity"], r["dtype"]) for r in sel))
    keys.sort(key=lambda k: (QUANTITIES.index(k[1]), _impl_key(k[0]), k[0], DTYPES.index(k[2])))
    # the first row of each (impl, quantity, dtype, n) counts
    by_key = {(r["impl"], r["quantity"], r["dtype"], r["n"]): r for r in reversed(sel)}
    lines = [_pivot_line(key, ns, by_key) for key in keys]
    for quantity in quantities:
        for key, ref in (
            ("pin_stored_samples_s", "Pinocchio (Python loop, results stored)"),
            ("pin_samples_s", "Pinocchio (Python loop, results dropped)"),
        ):
            pins = [
                s
                for r in sel
                if r["quantity"] == quantity and r["status"] == "ok"
                for s in r.get(key, [])
            ]
            if pins:
                rate = fmt_rate(1.0 / median(pins))
                lines.append([ref, quantity, "float64", *(rate for _ in ns), "reference"])
    header = ["implementation", "quantity", "dtype", *(f"N = {fmt_n(n)}" for n in ns)]
    return markdown_table([*header, "max abs diff"], lines, "lll" + "r" * (len(ns) + 1))


def free_flyer(info: dict[str, Any]) -> bool:
    """Whether a robot of the result is a free-flyer humanoid (its rows are cases, not
    :data:`QUANTITIES`)."""
    return bool(info.get("floating_base"))


def _ratios(row: dict[str, Any]) -> str:
    """``(a.aax / b.bbx)``: the row's rate over Pinocchio's stored loop and over its loop
    without storing (measured beside it); older runs have only the second."""
    if "ratio_vs_pin_stored" in row:
        return f" ({row['ratio_vs_pin_stored']:.2f}x / {row['ratio_vs_pin']:.2f}x)"
    return f" (- / {row['ratio_vs_pin']:.2f}x)" if "ratio_vs_pin" in row else ""


def _pooled_rate(rows: Rows, key: str) -> str:
    samples = [s for r in rows if r["status"] == "ok" for s in r.get(key, [])]
    return f"{fmt_rate(1.0 / median(samples))}/s" if samples else ""


def case_table(rows: Rows, robot: str) -> str:
    """A free-flyer robot's cases: jaxkin's rate per N (``jit(vmap)``, then
    ``chunked_map`` into an array) with its ratios to Pinocchio's stored and unstored loops,
    the two Pinocchio loops (samples pooled over N), compile time at the largest N and the
    check."""
    sel = [r for r in rows if r["robot"] == robot and r["impl"] in ("jaxkin", CHUNKED)]
    ns = sorted({r["n"] for r in sel})
    lines = []
    present = {(r["quantity"], r["impl"]) for r in sel}
    quantities = dict.fromkeys(r["quantity"] for r in sel)
    keys = [(q, i) for q in quantities for i in ("jaxkin", CHUNKED) if (q, i) in present]
    for quantity, impl in keys:
        rs = {r["n"]: r for r in sel if (r["quantity"], r["impl"]) == (quantity, impl)}
        compiled = [r for r in rs.values() if "compile_s" in r or "chunk_compile_s" in r]
        comp = compiled[-1] if compiled else None
        diffs = [r["max_abs_diff"] for r in rs.values() if "max_abs_diff" in r]
        cells = []
        for n in ns:
            r = rs.get(n)
            if r is None:
                cells.append("")
            elif r["status"] != "ok":
                cells.append(r["status"].split(":")[0])
            else:
                cells.append(fmt_rate(r["per_s"]) + _ratios(r))
        lines.append(
            [
                quantity,
                "jit(vmap)" if impl == "jaxkin" else "chunked_map into an array",
                *cells,
                _pooled_rate(list(rs.values()), "pin_stored_samples_s"),
                _pooled_rate(list(rs.values()), "pin_samples_s"),
                f"{_compile_s(comp):.2f}" if comp else "",
                fmt_diff(max(diffs)) if diffs else "",
            ]
        )
    header = [
        "quantity",
        "jaxkin",
        *(f"N = {fmt_n(n)}" for n in ns),
        "Pinocchio stored",
        "Pinocchio unstored",
        "compile s",
        "max abs diff",
    ]
    return markdown_table(header, lines, "ll" + "r" * (len(ns) + 4))


def _compile_s(row: dict[str, Any]) -> float:
    """A row's compile seconds: ``lower`` + ``compile`` of a ``jit(vmap)`` row, or the trace,
    lowering and compile a :data:`CHUNKED` row's first call reported."""
    if "chunk_compile_s" in row:
        return row["chunk_compile_s"]
    return row["lower_s"] + row["compile_s"]


CHUNKED = "jaxkin chunked_map"
"""The impl of the rows that write the N results into a preallocated array through
``jk.batch.chunked_map`` (``bench.jacobians.Bench.chunked_rows``)."""


def _summary_row(
    rows: Rows, robot: str, quantity: str, impl: str = "jaxkin"
) -> dict[str, Any] | None:
    """The float64 ``impl`` row of ``robot``/``quantity`` at N = 100k, else the largest N."""
    sel = [
        r
        for r in rows
        if (r["robot"], r["impl"], r["quantity"], r["dtype"]) == (robot, impl, quantity, "float64")
        and r["status"] == "ok"
    ]
    if not sel:
        return None
    at = [r for r in sel if r["n"] == HEADLINE["n"]]
    return at[0] if at else max(sel, key=lambda r: r["n"])


PATH_COSTS = (
    # (robot, quantity, the row it is compared with, what the bar is)
    ("talos", "hand, world-aligned", ("panda", "geometric"), "a 7-joint arm's"),
    ("g1", "feet + hands, world-aligned", ("g1", "left hand, world-aligned"), "one frame's"),
)
"""The issue's bars on how a Jacobian's cost grows (each within 1.5x of the row it is compared
with): a humanoid hand (9 joints and the free-flyer on its path, 15 of 38 columns) against the
Panda's tip, and the G1's four end frames in one call against one of them alone."""


def path_costs(rows: Rows) -> str:
    """Per :data:`PATH_COSTS` pair, the time per Jacobian of the row against the one it is
    compared with (float64, N = 100k or the largest N, through :data:`CHUNKED` and one
    ``jit(vmap)`` call), as markdown lines; empty when the rows are missing."""
    lines = []
    for robot, quantity, (base_robot, base_quantity), what in PATH_COSTS:
        cells = []
        for impl, label in ((CHUNKED, "chunked_map"), ("jaxkin", "jit(vmap)")):
            r = _summary_row(rows, robot, quantity, impl)
            b = _summary_row(rows, base_robot, base_quantity, impl)
            if r is None or b is None or r["n"] != b["n"]:
                continue
            cells.append(
                f"{label} {b['per_s'] / r['per_s']:.2f}x ({fmt_rate(r['per_s'])}/s against "
                f"{fmt_rate(b['per_s'])}/s, N = {fmt_n(r['n'])})"
            )
        if cells:
            name = "tip" if base_quantity == "geometric" else base_quantity
            lines.append(
                f"- {robot} {quantity} against {base_robot} {name} ({what}; bar <= 1.5x): "
                + "; ".join(cells)
            )
    return "\n".join(lines)


def _verdict(stored: float, compile_s: float, target: float) -> str:
    if math.isnan(stored):  # a run from before the stored loop was measured
        return "stored loop not measured"
    return "yes" if stored >= target and compile_s <= 1.5 else "no"


def summary_table(result: dict[str, Any]) -> str:
    """The issue's comparison: every robot's float64 Jacobian (arms and the chain: the tip,
    world-aligned; humanoids: each case) against Pinocchio's stored and unstored loops measured
    beside it, compile time and the targets (>= 3x for arms and chains, >= 2x for
    humanoids, against the stored loop; compile <= 1.5 s); then the same N written into a
    preallocated array by ``jk.batch.chunked_map`` (:data:`CHUNKED`), against the stored loop
    measured beside that row."""
    rows, lines = result["rows"], []
    for robot, info in result["robots"].items():
        quantities = list(info.get("cases", {})) if free_flyer(info) else ["geometric"]
        for quantity in quantities:
            r = _summary_row(rows, robot, quantity)
            if r is None:
                continue
            target = 2.0 if free_flyer(info) else 3.0
            stored = r.get("ratio_vs_pin_stored", math.nan)
            comp = r.get("lower_s", math.nan) + r.get("compile_s", math.nan)
            c = _summary_row(rows, robot, quantity, CHUNKED)
            chunked = ["", "", ""]
            met = f"jit(vmap): {_verdict(stored, comp, target)}"
            if c is not None and c["n"] == r["n"]:
                c_stored = c.get("ratio_vs_pin_stored", math.nan)
                chunked = [
                    f"{fmt_rate(c['per_s'])}/s",
                    f"{c_stored:.2f}x",
                    f"{c['chunk_compile_s']:.2f} s",
                ]
                met += f"; chunked_map: {_verdict(c_stored, c['chunk_compile_s'], target)}"
            lines.append(
                [
                    robot,
                    "tip, world-aligned" if quantity == "geometric" else quantity,
                    fmt_n(r["n"]),
                    f"{fmt_rate(r['per_s'])}/s",
                    f"{fmt_rate(r['pin_stored_per_s'])}/s" if "pin_stored_per_s" in r else "",
                    "" if math.isnan(stored) else f"{stored:.2f}x",
                    f"{fmt_rate(r['pin_per_s'])}/s" if "pin_per_s" in r else "",
                    f"{r.get('ratio_vs_pin', math.nan):.2f}x",
                    f"{comp:.2f} s",
                    *chunked,
                    f">= {target:g}x, <= 1.5 s: {met}",
                ]
            )
    header = [
        "robot",
        "Jacobian",
        "N",
        "jaxkin jit(vmap)",
        "Pinocchio stored",
        "ratio",
        "Pinocchio unstored",
        "ratio",
        "lower + compile",
        "jaxkin chunked_map into an array",
        "ratio to stored",
        "compile",
        "target",
    ]
    return markdown_table(header, lines, "lllrrrrrrrrrl")


def _has_single(rows: Rows) -> bool:
    return any(r["impl"] == "jaxkin single" for r in rows)


def single_table(rows: Rows, floor_us: float) -> str:
    lines = []
    for r in rows:
        if r["impl"] != "jaxkin single" or r["status"] != "ok":
            continue
        vm = _find(
            rows, robot=r["robot"], impl="jaxkin", quantity="geometric", n=1, dtype=r["dtype"]
        )
        pin = [x for x in rows if (x["robot"], x["impl"]) == (r["robot"], "pinocchio single")]
        lo, hi = min(r["samples_s"]) * 1e6, max(r["samples_s"]) * 1e6
        lines.append(
            [
                r["robot"],
                r["dtype"],
                f"{fmt_us(r['us_each'])} ({fmt_us(lo)} - {fmt_us(hi)})",
                fmt_us(vm["us_each"]) + " us" if vm else "",
                fmt_us(pin[0]["us_each"]) + " us" if pin else "",
                "<= 15 us",
            ]
        )
    header = [
        "robot",
        "dtype",
        "jaxkin `jit(f)(q)` us/call (min - max)",
        "jaxkin `jit(vmap(f))` N = 1",
        "Pinocchio one call",
        "target",
    ]
    floor = f"Dispatch floor (a trivial jitted call on a (6,) array): {floor_us:.1f} us."
    return markdown_table(header, lines, "llrrrr") + "\n\n" + floor


def compile_table(rows: Rows) -> str:
    groups: dict[tuple[str, str, str], Rows] = {}
    for r in rows:
        if r["impl"] == "jaxkin" and "compile_s" in r:
            groups.setdefault((r["robot"], r["quantity"], r["dtype"]), []).append(r)
    lines = []
    for (robot, quantity, dtype), rs in groups.items():
        low = [r["lower_s"] for r in rs]
        comp = [r["compile_s"] for r in rs]
        ok = [r for r in rs if "first_call_s" in r]
        first = f"{ok[-1]['first_call_s']:.3f} (N = {fmt_n(ok[-1]['n'])})" if ok else ""
        lines.append(
            [
                robot,
                quantity,
                dtype,
                f"{np.median(low):.2f}; {max(low):.2f}",
                f"{np.median(comp):.2f}; {max(comp):.2f}",
                first,
            ]
        )
    header = [
        "robot",
        "quantity",
        "dtype",
        "trace + lower s (median; max)",
        "XLA compile s (median; max)",
        "first call after compile s (largest N)",
    ]
    out = markdown_table(header, lines, "lllrrr")
    singles = [r for r in rows if r["impl"] == "jaxkin single" and "first_call_s" in r]
    if singles:
        out += (
            "\n\nSingle-configuration `jax.jit(lambda q: jk.geometric_jacobian(robot, q))`, first "
            "call (trace + compile + run): "
            + ", ".join(f"{r['robot']} {r['dtype']} {r['first_call_s']:.2f} s" for r in singles)
            + "."
        )
    return out


def _profile_n(rows: Rows) -> int:
    ns = sorted({r["n"] for r in rows if r["impl"] == "jaxkin" and r.get("hlo")})
    return 100_000 if 100_000 in ns else (ns[-1] if ns else 0)


def profile_table(rows: Rows, fault_us: float | None = None) -> str:
    n = _profile_n(rows)
    intro = (
        f"Optimised HLO of each batched kernel at N = {fmt_n(n)}: loop fusions (each one pass "
        "over the batch; `while` loops for the scan path), multiplies (each fusion recomputes "
        "what it does not read from another's buffer), the widest concatenate (XLA fuses "
        "nothing into one of more than 8 operands), sin + cos ops compiled vs emitted by "
        "jaxkin (for the scan path: in the loop body, i.e. per joint step), and the compiled "
        "kernel's temporaries against its input + output per configuration (XLA's memory "
        "analysis); then the page faults of one call (first writes to newly allocated pages: "
        "XLA allocates each call's output and temporaries anew), and the bytes so paged in per "
        "configuration (4 KiB a fault; filling a new page cost "
        + (f"{fault_us:.2f} us" if fault_us else "?")
        + " more than refilling one already in memory, measured at the start of the run)."
    )
    lines = []
    for r in rows:
        if r["impl"] != "jaxkin" or r["n"] != n or not r.get("hlo"):
            continue
        h = r["hlo"]
        rate = fmt_rate(r["per_s"]) + "/s" if r["status"] == "ok" else r["status"].split(":")[0]
        lines.append(
            [
                r["robot"],
                r["quantity"],
                r["dtype"],
                f"{h.get('fusions', '')}",
                f"{h.get('whiles', '')}",
                f"{h.get('multiplies', '')}",
                f"{h.get('widest_concatenate', '')}",
                f"{h.get('sincos_compiled', '')} / {h.get('sincos_emitted', '')}",
                f"{h.get('temp_bytes_per_config', math.nan):.0f}",
                f"{h.get('io_bytes_per_config', math.nan):.0f}",
                *_fault_cells(r),
                rate,
            ]
        )
    header = [
        "robot",
        "quantity",
        "dtype",
        "fusions",
        "while loops",
        "multiplies",
        "widest concat",
        "sin+cos compiled / emitted",
        "temp bytes / config",
        "in + out bytes / config",
        "page faults / call",
        "paged-in bytes / config",
        "rate",
    ]
    return intro + "\n\n" + markdown_table(header, lines, "lll" + "r" * 10)


def _fault_cells(row: dict[str, Any]) -> list[str]:
    """Page faults per call and the bytes they page in per configuration (4 KiB pages)."""
    faults = row.get("page_faults_per_call")
    if faults is None:
        return ["", ""]
    return [f"{faults:,.0f}", f"{faults * 4096 / row['n']:,.0f}"]


# ---------------------------------------------------------------------------- prose


def _find(rows: Rows, **kw) -> dict[str, Any] | None:
    """The first measured (status ok) row whose fields equal ``kw``."""
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
            f"{fmt_n(h['n'])}; this run stopped at N = {fmt_n(max(result['config']['ns']))})."
        )
    if "ratio_vs_pin_stored" in r64:
        against = (
            f"{r64['ratio_vs_pin_stored']:.2f}x Pinocchio called from Python** with each "
            f"result stored into a preallocated array ({fmt_rate(r64['pin_stored_per_s'])}/s; "
            f"{r64['ratio_vs_pin']:.2f}x its loop that drops the results, "
            f"{fmt_rate(r64['pin_per_s'])}/s; both measured interleaved in the same process)"
        )
    else:  # a run from before the stored loop was measured
        against = (
            f"{r64['ratio_vs_pin']:.2f}x Pinocchio called from Python** without storing the "
            f"results ({fmt_rate(r64['pin_per_s'])}/s, measured interleaved in the same process)"
        )
    parts.append(
        f"**Headline** (Panda from example-robot-data's URDF, 6x7 geometric Jacobian, N = "
        f"{fmt_n(h['n'])}): jaxkin computes **{fmt_rate(r64['per_s'])} Jacobians/s in float64, "
        + against
    )
    if r32 is not None:
        parts.append(f", and **{fmt_rate(r32['per_s'])}/s in float32**{_ratios(r32)}")
    c = _find(rows, dtype="float64", **dict(where, impl=CHUNKED))
    if c is not None and "ratio_vs_pin_stored" in c:
        parts.append(
            f"; written into a preallocated array by `jk.batch.chunked_map`, **"
            f"{fmt_rate(c['per_s'])}/s in float64, {c['ratio_vs_pin_stored']:.2f}x the stored "
            "loop** beside it"
        )
    s = _find(rows, robot=h["robot"], impl="jaxkin single", dtype="float64")
    if s is not None:
        parts.append(
            f". One configuration from Python (`jax.jit(lambda q: jk.geometric_jacobian(robot, "
            f"q))(q)`): {fmt_us(s['us_each'])} us per call (target <= 15 us; dispatch floor "
            f"{result['dispatch_floor_us']:.1f} us)"
        )
    return "".join(parts) + "."


def limits(result: dict[str, Any]) -> str:
    """Where the headline rows stand against :data:`BOUNDS`, and their compiled profile."""
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
            f"- Panda geometric, {dtype}, N = {fmt_n(h['n'])}: {fmt_rate(rate)}/s = {sc_txt}, "
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
        f"{m['platform']}. Load average (1, 5, 15 min; `os.getloadavg`) "
        f"{', '.join(f'{x:.2f}' for x in la['before'])} before, "
        f"{', '.join(f'{x:.2f}' for x in la['after'])} after. Versions: Python {m['python']}, "
        f"jax {m['jax']}, jaxlib "
        f"{m['jaxlib']}, NumPy {m['numpy']}, jaxkin {m['jaxkin']}, pin {m['pinocchio']}, "
        f"example-robot-data {m['example_robot_data']}, pytorch-kinematics "
        f"{m['pytorch_kinematics']} (torch {m['torch']}, default {m['torch_threads']} "
        f"threads), mujoco {m['mujoco']}, roboticstoolbox-python {m['roboticstoolbox']}."
    )


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


def scale_summary(info: dict[str, Any], json_path: Path) -> str:
    """What ``python3 -m bench.scale`` prints at the end of a run."""
    compile_where = "in the first chunk" if info["inputs"] == "stream" else "apart"
    return (
        f"{info['n']:,} Panda configurations -> {info['what']} ({info['dtype']}), inputs "
        f"{info['inputs']}, chunks of {info['chunk_size']:,}\n"
        f"  map: {info['map_s']:.1f} s = {info['throughput_per_s'] / 1e6:.2f} M/s "
        f"(compile {info.get('compile_s', info.get('first_chunk_s', 0)):.2f} s included "
        f"{compile_where}); wall "
        f"{info['wall_s']:.1f} s = {info['throughput_wall_per_s'] / 1e6:.2f} M/s\n"
        f"  output {info['out_bytes'] / 1e9:.2f} GB, shape {tuple(info['file_shape'])}; spot "
        f"check of rows {info['spot_check_rows']}: max abs diff "
        f"{info['spot_check_max_abs_diff']:.1e}\n"
        f"  peak RSS {info['peak_rss_mb']:.0f} MiB (target <= {info['target_peak_rss_mb']} MiB; "
        f"{info['rss_mb_after_imports']:.0f} MiB after imports); files "
        f"{'kept in ' + info['kept'] if 'kept' in info else 'deleted'} -> {json_path}"
    )


# ---------------------------------------------------------------------------- README section

CELLS_NOTE = (
    "Cells: Jacobians (or twists) per second, median of the samples, and in brackets the "
    "ratios to Pinocchio from Python measured interleaved with that row (above 1: faster): "
    "`(a / b)` is against its loop that stores each result into a preallocated array (a; "
    "geometric Jacobians only, `-` elsewhere) and against the same loop dropping the results "
    "(b). "
    "`*`: a Python-loop peer timed over fewer configurations than N (its rate does not "
    "depend on N). `skipped`: predicted call time or memory over the limits (JSON: "
    "`status`). max abs diff: jaxkin rows against Pinocchio (same frame, float64 "
    "reference); peer rows against jaxkin float64."
)
SUMMARY_NOTE = (
    "jaxkin `jax.jit(jax.vmap(...))` at N = 100k (else the largest N measured) against "
    "Pinocchio from Python on pre-built q arrays in its own layout, measured interleaved: "
    '"stored" is the loop a user who wants the N Jacobians in an array writes (one '
    "`computeFrameJacobian` per configuration, each result stored into a preallocated array; "
    "for several frames `computeJointJacobians` + `updateFramePlacements` + one "
    '`getFrameJacobian` per frame), "unstored" the same loop dropping its results. Ratios '
    "are against the stored loop first; the targets are issue 24's. Compile: `lower` + "
    '`compile` of that batch shape. "jaxkin chunked_map into an array": the same N '
    "through `jk.batch.chunked_map(f, q, out=out)` with the library's default chunks, the "
    "results written into a preallocated numpy array as the stored loop writes them (each "
    "chunk's results over an earlier chunk's device buffers, so no call pages in new memory); "
    "its ratio is against the stored loop measured beside that row, its compile the trace, "
    "lowering and compile of the first call (`MapStats.compile_seconds`)."
)
QUICK_NOTE = (
    "**This is a `--quick` smoke run (small N, 2 repeats, possibly a loaded machine): "
    "its numbers only show that everything runs. Run `python3 -m bench --write-readme` "
    "on a quiet machine for the real tables.**"
)


def _free_flyer_section(name: str, info: dict[str, Any], rows: Rows) -> list[str]:
    parts = [
        f"### {name} ({info['nq']} q, {info['dof']} v; free-flyer root)",
        "",
        f"URDF: {info['urdf']}. jaxkin: `{info['jaxkin']}`, float64.",
        "",
    ]
    for quantity, case in info["cases"].items():
        if "error" in case:
            parts.append(f"- {quantity}: not measured ({case['error']}).")
            continue
        parts.append(
            f"- {quantity}: `{case['jaxkin']}` ({case['nonzero_columns']} of {info['dof']} "
            f"columns nonzero; poses vs Pinocchio {case['pose_diff_vs_pinocchio']:.1e}); "
            f"Pinocchio: {case['pinocchio']}."
        )
    if info.get("peers_failed"):
        parts.append(
            "- Not compared: "
            + "; ".join(f"{k}: {v}" for k, v in info["peers_failed"].items())
            + "."
        )
    return [*parts, "", case_table(rows, name), ""]


def _robot_section(name: str, info: dict[str, Any], rows: Rows) -> list[str]:
    if free_flyer(info):
        return _free_flyer_section(name, info, rows)
    parts = [
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
    return [*parts, "", pivot(rows, name, QUANTITIES), ""]


def results_markdown(result: dict[str, Any]) -> str:
    """The generated results section of bench/README.md."""
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
        parts += [QUICK_NOTE, ""]
    parts += [
        "### Against Pinocchio from Python, every robot (float64)",
        "",
        SUMMARY_NOTE,
        "",
        summary_table(result),
        "",
        CELLS_NOTE,
        "",
    ]
    costs = path_costs(rows)
    if costs:
        parts += ["### Cost with the support path (time per Jacobian, float64)", "", costs, ""]
    for name, info in result["robots"].items():
        parts += _robot_section(name, info, rows)
    if _has_single(rows):
        parts += [
            "### One configuration from Python (N = 1)",
            "",
            single_table(rows, result["dispatch_floor_us"]),
            "",
        ]
    parts += [
        "### Compile times (jaxkin, per batch shape)",
        "",
        compile_table(rows),
        "",
        "### Profile of the compiled kernels",
        "",
        profile_table(rows, result.get("page_fault_us")),
        "",
        "### Distance from the machine limits",
        "",
        limits(result) or "Not available from this run (no Panda row at N = 100k).",
        "",
        "### Scale: 10 million configurations",
        "",
        scale_markdown(),
    ]
    return "\n".join(parts)


def write_readme(result: dict[str, Any], path: Path = README) -> None:
    """Replace the generated results section of bench/README.md (``path``)."""
    replace_section(path, results_markdown(result), MARK_START, MARK_END)


def print_tables(result: dict[str, Any], out_path: Path) -> None:
    """The tables on stdout, at the end of a run."""
    print()
    print(headline(result))
    print()
    print(machine_line(result))
    print("\n### Against Pinocchio from Python (float64)\n")
    print(summary_table(result))
    costs = path_costs(result["rows"])
    if costs:
        print("\n### Cost with the support path\n")
        print(costs)
    for name, info in result["robots"].items():
        print(f"\n### {name}\n")
        if free_flyer(info):
            print(case_table(result["rows"], name))
        else:
            print(pivot(result["rows"], name, QUANTITIES))
    if _has_single(result["rows"]):
        print("\n### One configuration from Python\n")
        print(single_table(result["rows"], result["dispatch_floor_us"]))
    print("\n### Compile times\n")
    print(compile_table(result["rows"]))
    print("\n### Profile\n")
    print(profile_table(result["rows"], result.get("page_fault_us")))
    lim = limits(result)
    if lim:
        print("\n### Machine limits\n")
        print(lim)
    print(f"\n-> {out_path}")


# ---------------------------------------------------------------------------- plot

STYLES = {
    "float64": "-",
    "float32": "--",
}


def _plot_panel(ax, sel: Rows, quantities: tuple[str, ...], colors: dict[str, str]) -> None:
    """One panel: a rate-against-N line per (implementation, quantity, dtype), and the Pinocchio
    reference of each quantity as a horizontal line."""
    per_quantity = len(quantities) > 1
    keys = list(dict.fromkeys((r["impl"], r["quantity"], r["dtype"]) for r in sel))
    for impl, quantity, dtype in keys:
        pts = sorted(
            (r["n"], r["per_s"])
            for r in sel
            if (r["impl"], r["quantity"], r["dtype"]) == (impl, quantity, dtype)
        )
        ckey = f"{impl} {quantity}" if per_quantity else impl
        if ckey not in colors:
            colors[ckey] = f"C{len(colors) % 10}"
        ax.loglog(
            [p[0] for p in pts],
            [p[1] for p in pts],
            STYLES[dtype],
            marker="o" if dtype == "float64" else "s",
            color=colors[ckey],
            label=f"{impl} {quantity} {dtype}" if per_quantity else f"{impl} {dtype}",
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
            label = f"Pinocchio {quantity} (Python loop)"
            ax.axhline(1.0 / median(pins), color="k", linestyle=ls, label=label)


def plot(rows: Rows, path: Path) -> None:
    """Rates against N: a column per robot, geometric above, analytical and twist below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robots = list(dict.fromkeys(r["robot"] for r in rows if r["quantity"] in QUANTITIES))
    if not robots:
        return
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
            _plot_panel(ax, sel, quantities, colors)
            ax.set_title(f"{name}: {' and '.join(quantities)}")
            ax.set_xlabel("batch size N")
            ax.set_ylabel("per second (median)")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
