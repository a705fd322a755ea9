"""What the IK-protocols benchmark reports: the tables that ``python3 -m bench.ik_protocols``
prints and writes into bench/IK.md (between :data:`MARK_START` and :data:`MARK_END`).

Everything here reads a result (the dictionary :mod:`bench.ik_protocols` measures and writes as
JSON, or an earlier run's JSON: ``python3 -m bench.ik_protocols --from-json PATH [--write-md]``)
and measures nothing.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from .report import HERE, markdown_table, print_section

IK_MD = HERE / "IK.md"
MARK_START, MARK_END = "<!-- protocols:start -->", "<!-- protocols:end -->"
PUBLISHED_GPU = {"PyRoki": 13.3e-3, "cuRobo": 26.5e-3}  # s per 1,000 targets, RTX 4090


def _pct(x: float) -> str:
    return f"{100 * x:.2f}%"


def tables(res: dict[str, Any]) -> str:
    """The markdown of a result: the TRAC-IK protocol table and the cuRobo / PyRoki one."""
    m = res["machine"]
    la, lb = res["load_average_before"], res["load_average_after"]
    out = [
        f"`python3 -m bench.ik_protocols{' --quick' if res['quick'] else ''}` ({res['date']}; "
        f"{', '.join(m['cpu_model'])}, {m['cpus_usable']} cores; load "
        f"average (1, 5, 15 min) {', '.join(f'{x:.1f}' for x in la)} before, "
        f"{', '.join(f'{x:.1f}' for x in lb)} after; jax {m['jax']}, numpy {m['numpy']}, "
        f"pytracik {res['versions']['pytracik']}, roboticstoolbox-python {m['roboticstoolbox']}, "
        f"Pinocchio {m['pinocchio']}, pytorch-kinematics {m['pytorch_kinematics']}, torch "
        f"{m['torch']}; total {res['wall_s']:.0f} s).",
        "",
        f"**TRAC-IK's protocol**: {res['n']:,} random reachable targets per arm, one seed at "
        "mid-limits, success = every pose-error component <= 1e-5 (m, rad) and within the "
        f"limits. Peers on the first {res['peer_targets']:,} targets, stopped after "
        f"{res['budget']:.0f} s per arm (column *targets*). Time = wall time per target "
        "(jaxkin: one batched call, steady state; its first call, compile included, apart). "
        "The 1e-9 column judges the same answers at 1e-9 per component (float64).",
        "",
    ]
    rows = []
    for r in res["trac_ik"]:
        if "error" in r:
            rows.append([r["arm"], str(r["dof"]), r["solver"], "-", "-", "-", "-", r["error"]])
            continue
        first = f"first call {r['first_call_s']:.1f} s" if "first_call_s" in r else ""
        rows.append(
            [
                r["arm"],
                str(r["dof"]),
                r["solver"],
                f"{r['n']:,}",
                _pct(r["success"]),
                _pct(r["success_1e9"]),
                f"{r['mean_time_per_target_s'] * 1e3:.3g}",
                first,
            ]
        )
    out.append(
        markdown_table(
            [
                "arm",
                "DOF",
                "solver",
                "targets",
                "success 1e-5",
                "success 1e-9",
                "ms / target",
                "note",
            ],
            rows,
            "lrlrrrrl",
        )
    )
    if not res.get("gpu"):
        return "\n".join([*out, "", "cuRobo / PyRoki protocol: not run (the run was stopped)."])
    out += [
        "",
        f"**cuRobo / PyRoki protocol** (Franka Panda, {res['gpu'][0]['n']:,} targets, 16 seeds, "
        "success at 5 mm / 0.05 rad). jaxkin on this 2-core CPU; PyRoki and cuRobo are their "
        "published figures on an RTX 4090 GPU, **different hardware, not measured here**:",
        "",
    ]
    grows = [
        [
            f"jaxkin, {r['setting']} (this CPU)",
            _pct(r["success"]),
            _pct(r["success_1e9"]),
            f"{r['total_s'] * 1e3 * 1000 / r['n']:.1f}",
            f"{r['first_call_s']:.1f}",
        ]
        for r in res["gpu"]
    ]
    grows += [
        [f"{k} (published, RTX 4090)", "-", "-", f"{v * 1e3:.1f}", "-"]
        for k, v in PUBLISHED_GPU.items()
    ]
    out.append(
        markdown_table(
            ["solver", "success", "success 1e-9", "ms per 1,000 targets", "first call s"],
            grows,
            "lrrrr",
        )
    )
    return "\n".join(out)


def load(path: Path) -> dict[str, Any]:
    """A result written as JSON, a partial one (a stopped run) completed for :func:`tables`."""
    res = json.loads(path.read_text())
    res.setdefault("load_average_after", res["load_average_before"])
    res.setdefault("wall_s", math.nan)
    return res


def report(res: dict[str, Any], write: bool) -> None:
    """Print the tables of ``res`` and, if ``write``, put them into bench/IK.md."""
    print_section(tables(res), write, IK_MD, MARK_START, MARK_END)
