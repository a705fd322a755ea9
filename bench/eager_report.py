"""What the eager benchmark reports: the tables that ``python3 -m bench.eager`` prints and
writes into bench/README.md (between :data:`MARK_START` and :data:`MARK_END`).

Everything here reads a result (the dictionary :mod:`bench.eager` measures and writes as JSON, or
an earlier run's JSON: ``python3 -m bench.eager --from-json PATH [--write-readme]``) and measures
nothing.
"""

from __future__ import annotations

import math
from typing import Any

from .report import HERE, fmt_diff, fmt_n, fmt_rate, fmt_us, markdown_table, print_section

README = HERE / "README.md"
MARK_START, MARK_END = "<!-- eager:start -->", "<!-- eager:end -->"


def tables(res: dict[str, Any]) -> str:
    """The markdown of a result: eager calls, one frame of a large tree, compiled
    pytorch_kinematics (when measured)."""
    m = res["machine"]
    load = res["load_average_before"], res["load_average_after"]
    parts = [
        f"`python3 -m bench.eager` ({res['date']}; {', '.join(m['cpu_model'])}, "
        f"{m['cpus_usable']} cores; load average (1, 5, 15 min) {_load(load[0])} before, "
        f"{_load(load[1])} after; jax {m['jax']}, Pinocchio {m['pinocchio']}, torch {m['torch']}, "
        f"pytorch-kinematics {m['pytorch_kinematics']}). Panda from example-robot-data, float64.",
        "",
        "**Eager calls** (outside `jit`, one configuration; first call in the process, then the "
        "median of later calls on new configurations):",
        "",
    ]
    rows = []
    for r in res["eager"]:
        pin = r.get("pinocchio_s")
        rows.append(
            [
                f"`{r['function']}`",
                f"{r['first_call_s']:.2f}",
                fmt_us(r["per_call_s"] * 1e6),
                fmt_us(pin * 1e6) if pin else "-",
                fmt_diff(r["max_abs_diff_vs_jit"]),
                fmt_diff(r.get("max_abs_diff_vs_pinocchio", math.nan)) or "-",
            ]
        )
    parts.append(
        markdown_table(
            [
                "function",
                "first call s",
                "later calls us (median)",
                "Pinocchio one call us",
                "diff vs jit",
                "diff vs Pinocchio",
            ],
            rows,
            "lrrrrr",
        )
    )
    tree_rows = []
    for t in res["trees"]:
        for k in ("fk", "geometric_jacobian"):
            if k not in t or "max_abs_diff_vs_pinocchio" not in t[k]:
                where = f"`{t['frame']}` (depth {t['depth']})" if "frame" in t else "-"
                build = f"{t['build_s']:.2f}" if "build_s" in t else "-"
                first = f"{t[k]['first_call_s']:.2f}" if k in t else t.get("error", "-")
                later = f"{t[k]['per_call_s'] * 1e3:.3g}" if k in t else "-"
                row = [f"{t['joints']:,}", where, f"`{k}(robot, q, frame)`", build, first, later]
                tree_rows.append([*row, "not checked (" + t.get("error", "stopped") + ")"])
                continue
            tree_rows.append(
                [
                    f"{t['joints']:,}",
                    f"`{t['frame']}` (depth {t['depth']})",
                    f"`{k}(robot, q, frame)`",
                    f"{t['build_s']:.2f}",
                    f"{t[k]['first_call_s']:.2f}",
                    f"{t[k]['per_call_s'] * 1e3:.3g}",
                    fmt_diff(t[k]["max_abs_diff_vs_pinocchio"]),
                ]
            )
    parts += [
        "",
        "**One frame of a large tree**"
        + (f" (measured {res['trees_date']}, a separate run)" if "trees_date" in res else "")
        + " (`bench.eager.random_tree`: built with "
        "`jk.Robot.from_joints`, a fixed seed; its deepest frame; eager calls in a fresh process, "
        "first call included; checked against Pinocchio on `jk.to_urdf` of the frame's "
        "ancestor chain, other columns exactly 0):",
        "",
        markdown_table(
            [
                "joints",
                "frame",
                "function",
                "build s",
                "first call s",
                "later calls ms (median)",
                "diff vs Pinocchio",
            ],
            tree_rows,
            "lllrrrr",
        ),
    ]
    p = res.get("pk_compiled")
    if p and p.get("rows"):
        parts += [
            "",
            f"**pytorch_kinematics, compiled `jacobian_tensor`** (`{p['how']}`; its README's "
            "fastest documented mode) against jaxkin `jax.jit(jax.vmap(jk.geometric_jacobian))`, "
            "Panda (N, 6, 7), samples interleaved in one process; rate = Jacobians per second "
            "(median); first call = compile + run for that shape:",
            "",
            markdown_table(
                [
                    "dtype",
                    "N",
                    "pytorch_kinematics compiled",
                    "jaxkin jit(vmap)",
                    "jaxkin / pk",
                    "pk first call s",
                    "jaxkin first call s",
                    "max abs diff",
                ],
                [
                    [
                        r["dtype"],
                        fmt_n(r["n"]),
                        f"{fmt_rate(r['pk_rate'])} ({r['pk_threads']} thr)",
                        fmt_rate(r["jaxkin_rate"]),
                        f"{r['jaxkin_rate'] / r['pk_rate']:.2f}x",
                        f"{r['pk_first_call_s']:.2f}",
                        f"{r['jaxkin_first_call_s']:.2f}",
                        fmt_diff(r["max_abs_diff"]),
                    ]
                    for r in p["rows"]
                ],
                "lrrrrrrr",
            ),
        ]
    elif p:
        parts += ["", f"pytorch_kinematics compiled: not measured ({p.get('error')})."]
    return "\n".join(parts)


def _load(x) -> str:
    """A load average (1, 5, 15 min) as text."""
    return ", ".join(f"{v:.1f}" for v in x)


def report(res: dict[str, Any], write: bool) -> None:
    """Print the tables of ``res`` and, if ``write``, put them into bench/README.md."""
    print_section(tables(res), write, README, MARK_START, MARK_END)
