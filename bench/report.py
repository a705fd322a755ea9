"""What every benchmark shares, written once: machine information and library versions, timing
helpers, number formatting, markdown tables, JSON results and generated sections of the markdown
pages, and the joint-rate draw.

The measuring modules (:mod:`bench.jacobians`, :mod:`bench.ik`, :mod:`bench.scale`) import this
module; it imports none of them. Joint configurations are drawn by the library itself,
``jk.sample_configurations(robot, n, key)``; joint rates (which are not configurations) by
:func:`joint_rates`.
"""

from __future__ import annotations

import datetime
import gc
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, NoReturn

import jax
import numpy as np

import jaxkin as jk

HERE = Path(__file__).resolve().parent
RESULTS_DIR = HERE / "results"

# ---------------------------------------------------------------------------- machine


def log(msg: str) -> None:
    """A progress line on stderr (tables go to stdout)."""
    print(msg, file=sys.stderr, flush=True)


def utc_now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def version(dist: str) -> str:
    """The installed version of the distribution ``dist``, or ``"not installed"``."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as _version

    try:
        return _version(dist)
    except PackageNotFoundError:
        return "not installed"


def _cpu_and_memory() -> dict[str, Any]:
    """CPU models, clock, SIMD flags and total memory from /proc (Linux; empty elsewhere)."""
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
    return dict(
        cpu_model=sorted(set(cpu_models)) or [platform.processor()],
        cpu_mhz=mhz,
        simd=[x for x in ("sse4_2", "avx", "avx2", "fma", "avx512f") if x in flags],
        mem_total=mem,
    )


def machine_info() -> dict[str, Any]:
    """The machine, the library versions and JAX's devices, for a result file. Call it before a
    peer changes torch's thread count (``torch_threads`` records the default)."""
    import jaxlib

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
        date_utc=utc_now(),
        **_cpu_and_memory(),
        logical_cpus=os.cpu_count(),
        cpus_usable=affinity,
        platform=platform.platform(),
        python=platform.python_version(),
        jax=jax.__version__,
        jaxlib=jaxlib.__version__,
        numpy=np.__version__,
        jaxkin=getattr(jk, "__version__", "?"),
        optax=version("optax"),
        pinocchio=version("pin"),
        example_robot_data=version("example-robot-data"),
        pytorch_kinematics=version("pytorch-kinematics"),
        torch=version("torch"),
        torch_threads=torch_threads,
        mujoco=version("mujoco"),
        roboticstoolbox=version("roboticstoolbox-python"),
        jax_devices=[str(d) for d in jax.devices()],
        xla_flags=os.environ.get("XLA_FLAGS", ""),
    )


# ---------------------------------------------------------------------------- inputs


def joint_rates(n: int, dof: int, seed: Any) -> np.ndarray:
    """``n`` joint-rate vectors ``qd`` (float64, (n, dof)), uniform in [-1, 1] per joint, from
    ``np.random.default_rng(seed)`` (``seed``: an int or a sequence of ints)."""
    return np.random.default_rng(seed).uniform(-1.0, 1.0, size=(n, dof))


# ---------------------------------------------------------------------------- timing


def timed(fn: Callable[[], Any]) -> tuple[Any, float]:
    """``fn()`` and the seconds it took."""
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def page_fault_us(mib: int = 64, repeats: int = 3) -> float:
    """Microseconds a page of newly mapped memory costs to fill beyond refilling a page already
    in memory: a private anonymous ``mmap`` of ``mib`` MiB filled once (every page's first write a
    fault) and then again, the difference over its pages (best of ``repeats``). Anonymous maps
    get no transparent huge pages unless the system enables them for every process, so this is
    what each page of an output or temporary that XLA allocates anew costs."""
    import mmap

    size, page = mib << 20, mmap.PAGESIZE
    best = math.inf
    for _ in range(repeats):
        m = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
        view = np.frombuffer(m, dtype=np.uint8)
        t0 = time.perf_counter()
        view.fill(1)
        t1 = time.perf_counter()
        view.fill(2)
        t2 = time.perf_counter()
        best = min(best, (t1 - t0) - (t2 - t1))
        del view
        m.close()
    return best / (size // page) * 1e6


def page_faults() -> int:
    """Minor page faults of this process so far (``getrusage``; first writes to new pages)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def median(xs: Iterable[float]) -> float:
    return float(np.median(list(xs)))


def first_and_repeats(fn: Callable[[], Any], repeats: int) -> dict[str, Any]:
    """The first call of ``fn`` (in a fresh process: trace + compile + run) timed apart from
    ``repeats`` later calls; the steady state is their median. ``result`` is the last answer."""
    result, first = timed(fn)
    times = []
    for _ in range(repeats):
        result, t = timed(fn)
        times.append(t)
    return dict(
        result=result,
        first_call_s=first,
        steady_s=median(times),
        steady_min_s=float(np.min(times)),
        samples_s=times,
    )


class Timer:
    """Median-of-repeats samples of a call, each sample optionally followed by one sample of a
    reference (Pinocchio), with Python's GC off while timing.

    ``cfg`` keys: ``target_s`` (a sample is a loop of calls lasting at least this long),
    ``repeats`` (samples), ``big_repeats`` (samples when one call takes over ``big_call_s``).
    """

    def __init__(self, cfg: dict[str, Any]):
        self.cfg = cfg

    def samples(
        self, call: Callable[[], Any], n: int, ref: Callable[[], float] | None
    ) -> dict[str, Any]:
        """``call()`` computes ``n`` configurations (and blocks). Returns seconds per
        configuration of each sample, the reference's, and the calls per sample."""
        cfg = self.cfg
        call()  # warm-up
        _, t_call = timed(call)
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


# ---------------------------------------------------------------------------- formatting


def fmt_rate(x: float) -> str:
    """A rate per second: ``851.2 k``, ``1.19 M``, ``709``."""
    if x >= 1e6:
        return f"{x / 1e6:.2f} M"
    if x >= 1e3:
        return f"{x / 1e3:.1f} k"
    return f"{x:.0f}"


def fmt_n(n: int) -> str:
    """A batch size: ``100k``, ``1M``, ``2500``."""
    if n >= 1_000_000 and n % 1_000_000 == 0:
        return f"{n // 1_000_000}M"
    if n >= 1000 and n % 1000 == 0:
        return f"{n // 1000}k"
    return str(n)


def fmt_us(x: float) -> str:
    """Microseconds: three significant digits below 100, whole numbers above."""
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


def fmt_diff(x: float) -> str:
    """A largest difference (``4.7e-16``); empty when not measured (NaN)."""
    return "" if math.isnan(x) else f"{x:.1e}"


# ---------------------------------------------------------------------------- markdown


def markdown_table(
    header: Sequence[str], rows: Iterable[Sequence[str]], align: str | None = None
) -> str:
    """A markdown table; ``align`` has one letter per column, ``l`` or ``r`` (default: all
    left)."""
    align = align or "l" * len(header)
    if len(align) != len(header):
        raise ValueError(f"align {align!r} does not match {len(header)} columns")

    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(cells) + " |"

    rule = "|" + "|".join("---:" if a == "r" else "---" for a in align) + "|"
    return "\n".join([line(header), rule, *(line(r) for r in rows)])


def replace_section(path: Path, body: str, start: str, end: str) -> None:
    """Replace what stands between the markers ``start`` and ``end`` in ``path`` by ``body``
    (a generated section of a markdown page; the rest of the page is kept as written)."""
    text = path.read_text()
    if start not in text or end not in text:
        raise SystemExit(f"{path} has no {start} ... {end} markers")
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    path.write_text(f"{head}{start}\n{body}\n{end}{tail}")


def print_section(text: str, write: bool, path: Path, start: str, end: str) -> None:
    """Print a generated section and, if ``write``, put it into ``path`` between the markers
    ``start`` and ``end`` (:func:`replace_section`)."""
    print(text)
    if write:
        replace_section(path, text, start, end)


def exit_without_teardown(rc: int) -> NoReturn:
    """Flush stdout and stderr and end the process with status ``rc``, skipping the
    interpreter's teardown: the Robotics Toolbox's nanobind extension otherwise prints pages of
    "leaked instance" warnings at exit. Call it only once everything is written."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)


def write_json(path: Path, obj: Any) -> None:
    """``obj`` as indented JSON (NumPy scalars as floats), creating the folder."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj, indent=1, default=float) + "\n")
