"""What the IK benchmark reports: the results table that ``python3 -m bench.ik`` prints (from
the rows it measures and writes to ``results/ik.json``); it measures nothing."""

from __future__ import annotations

from typing import Any

from .report import markdown_table

HEADER = (
    "starts",
    "solver",
    "success (1e-9, in limits)",
    "success (1e-6)",
    "own flag",
    "total time [s]",
    "first call [s]",
)


def _line(r: dict[str, Any]) -> list[str]:
    first = f"{r['first_call_s']:.2f}" if r.get("first_call_s") is not None else "-"
    measured = r.get("measured_targets", r["n"])
    note = "" if measured >= r["n"] else f" (extrapolated from {measured})"
    return [
        f"{r['starts']}",
        r["solver"],
        f"{100 * r['success']:.1f}%",
        f"{100 * r['success_loose']:.1f}%",
        f"{100 * r['own_converged']:.1f}%",
        f"{r['total_s']:.3f}{note}",
        first,
    ]


def results_table(rows: list[dict[str, Any]]) -> str:
    """One line per (starts, solver): success at 1e-9 and 1e-6, the solver's own flag, times."""
    return markdown_table(HEADER, [_line(r) for r in rows])
