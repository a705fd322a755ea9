"""Ten million Panda configurations through ``jaxkin.batch``, in bounded memory.

``python3 -m bench.scale`` generates ``--n`` (default 10,000,000) Panda configurations chunk by
chunk, computes their geometric Jacobians (``--what twist``: twists, with random joint rates) and
streams the results to an uncompressed ``.npz`` on disk, then reports the peak resident memory
(``resource.getrusage(RUSAGE_SELF).ru_maxrss``), the throughput, and spot checks of the file,
and deletes the files (``--keep`` keeps them).

Two pipelines (``--inputs``):

* ``memmap`` (default): the configurations are written chunk by chunk to a ``.npy`` file
  (plain writes, never held in memory) and opened with ``np.load(..., mmap_mode="r")``;
  ``jaxkin.batch.chunked_map(fn, qs, out="....npz")`` reads them chunk by chunk and writes each
  chunk's results to disk as it finishes. Pages of the mapped input that have been read count in
  the resident set until the kernel reclaims them (up to the input's size, 560 MB in float64).
* ``stream``: a generator yields the configurations chunk by chunk;
  ``jaxkin.batch.stream_map`` evaluates them and each result chunk is written straight into the
  ``.npz`` member (a ZIP64 stream); nothing of size N is ever mapped.

Peak memory target: <= 2 GB. The run writes about ``N * 6 * 7 * 8`` bytes (3.4 GB for float64
Jacobians) plus, in ``memmap`` mode, the same again while ``chunked_map`` packs its ``.npz``.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import sys
import tempfile
import time
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import jax
import numpy as np

import jaxkin as jk
from jaxkin.batch import chunked_map, stream_map
from jaxkin.io import npy_header

from .jacobian_report import scale_summary
from .peers import jaxkin_robot, robot_sources
from .report import RESULTS_DIR, joint_rates, utc_now, write_json

TARGET_RSS_MB = 2048
MEMBER = "out.npy"  # the array inside the output npz


def peak_rss_mb() -> float:
    """Peak resident set of this process so far, in MiB (Linux reports KiB)."""
    kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kib / 1024 if sys.platform != "darwin" else kib / 2**20


def current_rss_mb() -> float:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def _configs(robot, start: int, stop: int, seed: int, block: int, dtype, rates: bool) -> np.ndarray:
    """Rows ``start:stop`` of the reproducible stream of configurations (``q``, or ``[q, qd]``
    with ``rates``): block ``b`` (rows ``b*block : (b+1)*block``) has ``q`` from
    ``jk.sample_configurations`` with key ``fold_in(key(seed), b)`` and ``qd`` from
    :func:`bench.report.joint_rates` with seed ``[seed, b]``."""
    out = []
    for b in range(start // block, (stop - 1) // block + 1):
        key = jax.random.fold_in(jax.random.key(seed), b)
        q = np.asarray(jk.sample_configurations(robot, block, key))
        a, z = max(start, b * block) - b * block, min(stop, (b + 1) * block) - b * block
        if rates:
            qd = joint_rates(block, robot.dof, [seed, b])
            out.append(np.concatenate([q[a:z], qd[a:z]], axis=1))
        else:
            out.append(q[a:z])
    return np.concatenate(out).astype(dtype)


def _write_npy(path: Path, robot, n: int, seed: int, block: int, dtype, rates: bool) -> None:
    """The configurations ``(n, dof)`` (``(n, 2 dof)`` with rates) to a ``.npy``, block by
    block with plain writes (never mapped, never all in memory)."""
    with open(path, "wb") as f:
        header = {
            "descr": np.lib.format.dtype_to_descr(np.dtype(dtype)),
            "fortran_order": False,
            "shape": (n, robot.dof * (2 if rates else 1)),
        }
        np.lib.format.write_array_header_1_0(f, header)
        for start in range(0, n, block):
            stop = min(start + block, n)
            f.write(_configs(robot, start, stop, seed, block, dtype, rates).tobytes())


def _npz_rows(path: Path, member: str, rows: list[int]) -> tuple[tuple[int, ...], np.ndarray]:
    """Selected rows of an array inside an uncompressed npz, read by seeking (never loading)."""
    with zipfile.ZipFile(path) as z, z.open(member) as f:
        shape, fortran, dtype = npy_header(f)
        assert not fortran
        base = f.tell()
        row_bytes = int(np.prod(shape[1:], dtype=np.int64)) * dtype.itemsize
        out = []
        for r in rows:
            f.seek(base + r * row_bytes)
            out.append(np.frombuffer(f.read(row_bytes), dtype=dtype).reshape(shape[1:]))
    return tuple(shape), np.stack(out)


def _kernel(robot, what: str) -> tuple[Callable, tuple[int, ...]]:
    """The per-row function of ``x`` (``q``, or ``[q, qd]`` for twists) and its output shape."""
    dof = robot.dof
    if what == "jacobian":
        return (lambda x: jk.geometric_jacobian(robot, x[:dof])), (6, dof)
    return (lambda x: jk.twist(robot, x[:dof], x[dof:])), (6,)


def _memmap_pipeline(fn, robot, args, work: Path, out_path: Path, rates: bool) -> dict[str, Any]:
    """Inputs written to a ``.npy`` block by block, mapped, ``chunked_map`` to ``out_path``."""
    dtype = np.dtype(args.dtype)
    t = time.perf_counter()
    in_path = work / "configs.npy"
    _write_npy(in_path, robot, args.n, args.seed, args.chunk, dtype, rates)
    info = dict(input_write_s=time.perf_counter() - t, input_bytes=in_path.stat().st_size)
    xs = np.load(in_path, mmap_mode="r")
    _, stats = chunked_map(
        fn, xs, chunk_size=args.chunk, out=str(out_path), progress=True, return_stats=True
    )
    del xs
    return dict(
        info,
        compile_s=stats.compile_seconds,
        map_s=stats.run_seconds,
        n_chunks=stats.n_chunks,
        padding=stats.padding,
    )


def _stream_pipeline(fn, robot, args, out_path: Path, row_shape, rates: bool) -> dict[str, Any]:
    """Inputs from a generator, ``stream_map``, each result chunk written into the npz."""
    n, block, dtype = args.n, args.chunk, np.dtype(args.dtype)

    def batches() -> Iterator[np.ndarray]:
        for start in range(0, n, block):
            stop = min(start + block, n)
            yield _configs(robot, start, stop, args.seed, block, dtype, rates)

    t = time.perf_counter()
    rows_done, first = 0, None
    with zipfile.ZipFile(out_path, "w", zipfile.ZIP_STORED, allowZip64=True) as z:
        with z.open(MEMBER, "w", force_zip64=True) as f:
            header = {
                "descr": np.lib.format.dtype_to_descr(dtype),
                "fortran_order": False,
                "shape": (n, *row_shape),
            }
            np.lib.format.write_array_header_1_0(f, header)
            for res in stream_map(fn, batches(), chunk_size=block):
                if first is None:  # the first chunk includes the compile
                    first = time.perf_counter() - t
                f.write(np.ascontiguousarray(res).tobytes())
                rows_done += len(res)
    assert rows_done == n, (rows_done, n)
    return dict(map_s=time.perf_counter() - t, first_chunk_s=first)


def _spot_check(fn, robot, args, out_path: Path, rates: bool) -> dict[str, Any]:
    """Rows read back from the file against a direct evaluation."""
    n = args.n
    rows = sorted({0, 1, n // 2, n - 2, n - 1} & set(range(n)))
    shape, got = _npz_rows(out_path, MEMBER, rows)
    want = np.stack(
        [
            np.asarray(fn(_configs(robot, r, r + 1, args.seed, args.chunk, args.dtype, rates)[0]))
            for r in rows
        ]
    )
    return dict(
        file_shape=list(shape),
        spot_check_rows=rows,
        spot_check_max_abs_diff=float(np.abs(got.astype(np.float64) - want).max()),
    )


def run(args: argparse.Namespace) -> dict[str, Any]:
    if args.dtype == "float64":
        jax.config.update("jax_enable_x64", True)
    rates = args.what == "twist"
    robot, how = jaxkin_robot(robot_sources(["panda"])[0], np.dtype(args.dtype))
    fn, row_shape = _kernel(robot, args.what)
    work = Path(tempfile.mkdtemp(prefix="jaxkin-scale-", dir=args.dir))
    out_path = work / f"panda_{args.what}_{args.n}.npz"
    info: dict[str, Any] = dict(
        date_utc=utc_now(),
        load_average_1min=os.getloadavg()[0],
        n=args.n,
        what=args.what,
        dtype=args.dtype,
        inputs=args.inputs,
        chunk_size=args.chunk,
        robot=f"panda: {how}",
        out=str(out_path),
        rss_mb_after_imports=current_rss_mb(),
    )
    t_all = time.perf_counter()
    try:
        if args.inputs == "memmap":
            info.update(_memmap_pipeline(fn, robot, args, work, out_path, rates))
        else:
            info.update(_stream_pipeline(fn, robot, args, out_path, row_shape, rates))
        info["wall_s"] = time.perf_counter() - t_all
        info["peak_rss_mb"] = peak_rss_mb()
        info["out_bytes"] = out_path.stat().st_size
        info["throughput_per_s"] = args.n / info["map_s"]
        info["throughput_wall_per_s"] = args.n / info["wall_s"]
        info.update(_spot_check(fn, robot, args, out_path, rates))
        info["peak_rss_mb_end"] = peak_rss_mb()
    finally:
        if args.keep:
            info["kept"] = str(work)
        else:
            shutil.rmtree(work, ignore_errors=True)
            info["deleted"] = not work.exists()
    return info


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python3 -m bench.scale", description=__doc__.split("\n")[0])
    p.add_argument("--n", type=lambda s: int(float(s)), default=10_000_000)
    p.add_argument("--what", choices=("jacobian", "twist"), default="jacobian")
    p.add_argument("--dtype", choices=("float64", "float32"), default="float64")
    p.add_argument("--inputs", choices=("memmap", "stream"), default="memmap")
    p.add_argument("--chunk", type=int, default=65536, help="rows per compiled call")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--dir", default=None, help="where to write (default: the temp directory)")
    p.add_argument("--keep", action="store_true", help="keep the files (default: delete)")
    p.add_argument("--json", type=Path, default=RESULTS_DIR / "scale.json")
    args = p.parse_args(argv)

    free = shutil.disk_usage(args.dir or tempfile.gettempdir()).free
    item = 8 if args.dtype == "float64" else 4
    per_row = (42 if args.what == "jacobian" else 6) * item
    need = args.n * (per_row * (2 if args.inputs == "memmap" else 1) + 14 * item)  # + inputs
    if need > 0.9 * free:
        print(f"not enough disk: need about {need / 1e9:.1f} GB, {free / 1e9:.1f} GB free")
        return 1
    info = run(args)
    info["target_peak_rss_mb"] = TARGET_RSS_MB
    write_json(args.json, info)
    print(scale_summary(info, args.json))
    return 0


if __name__ == "__main__":
    sys.exit(main())
