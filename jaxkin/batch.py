"""Chunked evaluation of a per-configuration function over a large batch.

Kernels in jaxkin are written for one configuration (``q`` of shape ``(dof,)``) and batched with
``jax.vmap``. One ``vmap`` over millions of rows would hold every intermediate of every row at
once; :func:`chunked_map` instead streams the batch through one compiled ``jax.vmap(fn)`` of a
fixed chunk shape and collects the results in preallocated host (numpy) arrays.

The pipeline has three steps, each a small function, so that multi-device execution can replace
one of them without touching the others:

1. :func:`_chunking` picks equal chunks of at most ``chunk_size`` rows (minimal padding), and
   :func:`_trace` traces ``jax.jit(jax.vmap(fn))`` for that shape; it is lowered and compiled
   once.
2. :func:`_feed` slices a chunk from the host inputs (padding the last one to the full chunk
   shape by repeating the last row, so it never recompiles) and places it on the device.
   Sharding enters here and in :func:`_chunking`: place the chunk with a ``NamedSharding`` over
   a device mesh, and round the chunk size up to a multiple of the device count.
3. :func:`_drain` copies a finished chunk's results, padding dropped, into the host outputs.

While one chunk is drained the next is already running (JAX dispatches asynchronously).
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import sys
import tempfile
import time
import zipfile
from collections.abc import Callable, Iterable, Iterator
from typing import Any, TextIO

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .errors import JaxkinError, ShapeError

__all__ = ["MapStats", "ProgressBar", "chunked_map", "stream_map"]

DEFAULT_CHUNK_SIZE = 65536


# ---------------------------------------------------------------------- progress bar
class ProgressBar:
    """A minimal progress bar on stderr: done/total, percent, rate and ETA.

    Redraws at most every ``min_interval`` seconds (and once at the end). It is silent when
    ``enabled`` is False, or when the stream is not a terminal unless ``force`` is True.
    Use it as a context manager, or call :meth:`close` when done::

        with ProgressBar(total=n, desc="q") as bar:
            for chunk in chunks:
                ...
                bar.update(len(chunk))
    """

    def __init__(
        self,
        total: int,
        desc: str = "",
        *,
        unit: str = "it",
        enabled: bool = True,
        force: bool = False,
        file: TextIO | None = None,
        min_interval: float = 0.1,
        width: int = 24,
    ) -> None:
        self.total = int(total)
        self.desc = desc
        self.unit = unit
        self.file = sys.stderr if file is None else file
        self.min_interval = float(min_interval)
        self.width = int(width)
        self.done = 0
        isatty = getattr(self.file, "isatty", None)
        tty = bool(isatty()) if callable(isatty) else False
        self.active = bool(enabled) and (tty or bool(force))
        self._start = time.perf_counter()
        self._last_draw = -math.inf
        self._drawn = -1  # ``done`` at the last redraw
        self._width_drawn = 0  # length of the line on screen
        self._closed = False

    def note(self, text: str) -> None:
        """Show ``text`` in place of the bar until the next redraw (e.g. "compiling")."""
        if self.active:
            self._write(f"{self.desc} {text}" if self.desc else text)

    def start(self) -> None:
        """Restart the clock (e.g. after a compile the rate should not include) and draw."""
        self._start = time.perf_counter()
        if self.active:
            self._draw(self._start)

    def update(self, n: int = 1) -> None:
        """Count ``n`` more items done; redraw if the last redraw is old enough."""
        self.done += int(n)
        if self.active:
            now = time.perf_counter()
            if now - self._last_draw >= self.min_interval or self.done >= self.total:
                self._draw(now)

    def close(self) -> None:
        """Draw the final state and end the line (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self.active:
            if self._drawn != self.done:
                self._draw(time.perf_counter())
            self.file.write("\n")
            self.file.flush()

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _draw(self, now: float) -> None:
        self._last_draw = now
        self._drawn = self.done
        elapsed = max(now - self._start, 1e-9)
        frac = min(self.done / self.total, 1.0) if self.total > 0 else 1.0
        filled = round(frac * self.width)
        rate = self.done / elapsed
        remaining = (self.total - self.done) / rate if rate > 0 else math.inf
        desc = f"{self.desc} " if self.desc else ""
        self._write(
            f"{desc}[{'#' * filled}{'.' * (self.width - filled)}] "
            f"{self.done:,}/{self.total:,} {100 * frac:5.1f}% "
            f"{_si(rate)} {self.unit}/s ETA {_duration(remaining)}"
        )

    def _write(self, line: str) -> None:
        # Back to the start of the line; blank out what is left of a longer previous line.
        self.file.write(f"\r{line}{' ' * max(self._width_drawn - len(line), 0)}")
        self.file.flush()
        self._width_drawn = len(line)


def _si(x: float) -> str:
    for factor, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if x >= factor:
            return f"{x / factor:.2f}{suffix}"
    return f"{x:.1f}"


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "--:--"
    s = round(seconds)
    h, rest = divmod(s, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


# ---------------------------------------------------------------------- chunked map
@dataclasses.dataclass(frozen=True)
class MapStats:
    """Timings of one :func:`chunked_map` call.

    ``compile_seconds``: tracing, lowering and compiling ``jax.jit(jax.vmap(fn))`` for the chunk
    shape (once). ``run_seconds``: feeding every chunk, running it and copying its results to the
    host outputs, compile excluded. ``padding``: rows added to fill the last chunk (computed and
    dropped).
    """

    n: int
    chunk_size: int
    n_chunks: int
    padding: int
    compile_seconds: float
    run_seconds: float

    @property
    def rate(self) -> float:
        """Steady-state rows per second (compile excluded)."""
        return self.n / self.run_seconds if self.run_seconds > 0 else math.inf


def chunked_map(
    fn: Callable[..., Any],
    *arrays: Any,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    progress: bool | ProgressBar = False,
    out: Any = None,
    return_stats: bool = False,
    devices: Any = None,
):
    """``jax.vmap(fn)(*arrays)`` evaluated chunk by chunk, with results in host numpy arrays.

    ``fn(*rows)`` is written for one row: it receives ``arrays[i][k]`` (shape
    ``arrays[i].shape[1:]``) for each input and returns a pytree of arrays.
    The batch is cut into ``k = ceil(N / chunk_size)`` chunks of equal size
    ``c = ceil(N / k) <= chunk_size`` rows, and ``jax.jit(jax.vmap(fn))`` is traced and compiled
    once for that shape. The last chunk is padded to ``c`` rows (fewer than ``k`` padding rows) by
    repeating the last row, so ``fn`` only sees valid inputs; the padding is dropped from the
    results.

    Args:
      fn: per-row function; pure and jittable.
      *arrays: one or more array-likes (numpy, ``np.memmap``, JAX), all of leading length ``N``.
        They are read chunk by chunk on the host; a JAX array is copied to the host first.
      chunk_size: most rows per compiled call (>= 1). Memory on the device is about ``c``
        times the per-row footprint of ``fn``'s intermediates; the default suits a CPU.
      progress: True for a :class:`ProgressBar` on stderr (shown on a terminal only), or a
        :class:`ProgressBar` to update (its ``total`` should be ``N``).
      out: optional pytree of writable arrays (e.g. ``np.memmap``) with the structure of ``fn``'s
        output and leaf shapes ``(N, *leaf_shape)``, into which results are written; or a path:
        ``"results.npz"`` (an uncompressed npz) or a directory (one ``.npy`` per output leaf,
        loadable with ``np.load(..., mmap_mode="r")``). Path outputs are written chunk by chunk
        to disk (never held in memory, so they may exceed it) and appear atomically at the end;
        the function then returns the path.
      return_stats: also return a :class:`MapStats` with compile and run times.
      devices: where each chunk runs. None (default) or ``"all"``: every device JAX sees
        (``jax.devices()``: all GPUs, or all hosts' devices after ``jax.distributed.initialize``);
        a sequence of devices; or a 1-D ``jax.sharding.Mesh``. With more than one device each
        chunk is split along its rows with a ``NamedSharding`` (the chunk is rounded up to a
        multiple of the device count) and the compiled call runs on all of them at once.
        Test on a CPU with ``XLA_FLAGS=--xla_force_host_platform_device_count=4``.

    Returns:
      The pytree ``fn`` returns, each leaf a numpy array of shape ``(N, *leaf_shape)`` (``out``
      itself when given); with ``return_stats=True`` the pair ``(result, stats)``.

    Raises:
      ShapeError: no arrays, an array without a leading axis, unequal leading lengths, or an
        ``out`` that does not match ``fn``'s output.
      JaxkinError: ``chunk_size`` is not a positive integer.
    """
    if not callable(fn):
        raise JaxkinError(f"chunked_map: fn must be callable, got {type(fn).__name__}.")
    host, n = _check_inputs(arrays)
    mesh = _mesh(devices)
    chunk, n_chunks = _chunking(chunk_size, n, mesh.size)
    path = os.fspath(out) if isinstance(out, (str, os.PathLike)) else None

    bar = progress if isinstance(progress, ProgressBar) else ProgressBar(n, enabled=bool(progress))
    writer = None
    try:
        t0 = time.perf_counter()
        traced = _trace(fn, host, chunk, mesh)
        if path is not None:
            writer = _FileWriter(path, traced.out_info, n)
            results = None
        else:
            results = _allocate(traced.out_info, n, out)  # checks out= before the compile
        if n_chunks:
            bar.note(f"compiling for chunks of {chunk:,} rows ...")
            compiled = traced.lower().compile()
        compile_seconds = time.perf_counter() - t0

        bar.start()
        t0 = time.perf_counter()
        pending = None  # (start, stop, device results) of the chunk in flight
        for k in range(n_chunks):
            start = k * chunk
            stop = min(start + chunk, n)
            running = (start, stop, compiled(*_feed(host, start, chunk, n, mesh)))
            if pending is not None:
                _drain(results if writer is None else writer, *pending)
                bar.update(pending[1] - pending[0])
            pending = running
        if pending is not None:
            _drain(results if writer is None else writer, *pending)
            bar.update(pending[1] - pending[0])
        if writer is not None:
            results = writer.commit()
    finally:
        bar.close()
        if writer is not None:
            writer.abort()
    run_seconds = time.perf_counter() - t0

    if not return_stats:
        return results
    stats = MapStats(
        n=n,
        chunk_size=chunk,
        n_chunks=n_chunks,
        padding=n_chunks * chunk - n,
        compile_seconds=compile_seconds,
        run_seconds=run_seconds,
    )
    return results, stats


def stream_map(
    fn: Callable[..., Any],
    batches: Iterable[Any],
    *,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    devices: Any = None,
) -> Iterator[Any]:
    """Apply a per-row ``fn`` to a stream of batches of any sizes, one compile for all.

    ``batches`` yields arrays (or tuples of arrays, one per argument of ``fn``) with a leading
    row axis; rows are regrouped into chunks of exactly ``chunk_size`` rows (the last one padded)
    and each finished chunk's results are yielded as a pytree of numpy arrays (padding dropped),
    in order. Memory holds about two chunks, whatever the stream's length: use it for
    configurations generated on the fly or read from disk.
    """
    mesh = _mesh(devices)
    chunk, _ = _chunking(chunk_size, max(int(chunk_size), 1), mesh.size)
    compiled = None
    buffer: list[list[np.ndarray]] = []
    buffered = 0

    def run(parts: list[list[np.ndarray]], rows: int):
        host = [np.concatenate(cols) for cols in zip(*parts, strict=True)]
        out = compiled(*_feed(host, 0, chunk, rows, mesh))
        return jax.tree_util.tree_map(lambda x: np.asarray(x)[:rows], out)

    for item in batches:
        arrays = item if isinstance(item, tuple) else (item,)
        host, _ = _check_inputs(arrays)
        if compiled is None:
            compiled = _trace(fn, host, chunk, mesh).lower().compile()
        buffer.append(host)
        buffered += host[0].shape[0]
        while buffered >= chunk:
            joined = [np.concatenate(cols) for cols in zip(*buffer, strict=True)]
            yield run([[a[:chunk] for a in joined]], chunk)
            rest = [a[chunk:] for a in joined]
            buffer, buffered = ([rest], rest[0].shape[0]) if rest[0].shape[0] else ([], 0)
    if buffered:
        yield run(buffer, buffered)


def _check_inputs(arrays: tuple[Any, ...]) -> tuple[list[np.ndarray], int]:
    if not arrays:
        raise ShapeError(
            "chunked_map needs at least one input array, e.g. chunked_map(fn, qs) with qs of "
            "shape (N, dof)."
        )
    host = []
    for i, a in enumerate(arrays):
        try:
            arr = np.asarray(a)
        except (TypeError, ValueError) as e:
            raise ShapeError(f"chunked_map: input {i} is not array-like ({e}).") from None
        if arr.ndim == 0:
            raise ShapeError(
                f"chunked_map: input {i} must have a leading batch axis (shape (N, ...)), got a "
                "scalar. Close over values shared by every row in fn instead of passing them."
            )
        # JAX's own dtype (float32 while x64 is off), so the compiled call accepts the chunks.
        dtype = jax.dtypes.canonicalize_dtype(arr.dtype)
        host.append(arr if arr.dtype == dtype else arr.astype(dtype))
    lengths = [a.shape[0] for a in host]
    if len(set(lengths)) > 1:
        shapes = ", ".join(f"input {i}: {a.shape}" for i, a in enumerate(host))
        raise ShapeError(
            f"chunked_map: all inputs must have the same leading length N, got {shapes}. "
            "Give one row per configuration in every input (broadcast shared values with "
            "np.broadcast_to, or close over them in fn)."
        )
    return host, lengths[0]


def _chunking(chunk_size: Any, n: int, n_devices: int = 1) -> tuple[int, int]:
    """(rows per chunk, number of chunks): the fewest chunks of at most ``chunk_size`` rows, all
    of one size, so that padding is minimal; rounded up to a multiple of ``n_devices``."""
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)):
        raise JaxkinError(
            f"chunked_map: chunk_size must be a positive integer, got {chunk_size!r} "
            f"({type(chunk_size).__name__}). The default is {DEFAULT_CHUNK_SIZE}."
        )
    if chunk_size < 1:
        raise JaxkinError(
            f"chunked_map: chunk_size must be >= 1, got {chunk_size}. "
            f"The default is {DEFAULT_CHUNK_SIZE}."
        )
    n_chunks = -(-n // int(chunk_size))
    chunk = -(-n // n_chunks) if n_chunks else 1
    chunk = -(-chunk // n_devices) * n_devices
    return chunk, n_chunks


def _mesh(devices: Any) -> Mesh:
    """A 1-D mesh (axis ``"rows"``) over the devices a chunk is split across."""
    if isinstance(devices, Mesh):
        if devices.devices.ndim != 1:
            raise JaxkinError(
                f"chunked_map: devices must be a 1-D mesh, got axes {devices.axis_names}."
            )
        return devices
    if devices is None or (isinstance(devices, str) and devices == "all"):
        devs = jax.devices()
    elif isinstance(devices, str):
        raise JaxkinError(
            f"chunked_map: devices must be None, 'all', a sequence of devices or a Mesh, got "
            f"{devices!r}."
        )
    else:
        devs = list(devices)
        if not devs:
            raise JaxkinError("chunked_map: devices is empty; pass None to use every device.")
    return Mesh(np.array(devs), ("rows",))


def _trace(
    fn: Callable[..., Any], host: list[np.ndarray], chunk: int, mesh: Mesh
) -> jax.stages.Traced:
    """Trace ``jit(vmap(fn))`` for ``chunk`` rows (``.out_info``: output shapes; ``.lower()
    .compile()``: the executable, which accepts exactly these shapes, so it never retraces).
    Inputs and outputs are split along rows over ``mesh``."""
    sharding = NamedSharding(mesh, PartitionSpec("rows"))
    specs = [jax.ShapeDtypeStruct((chunk, *a.shape[1:]), a.dtype, sharding=sharding) for a in host]
    return jax.jit(jax.vmap(fn), out_shardings=sharding).trace(*specs)


def _feed(host: list[np.ndarray], start: int, chunk: int, n: int, mesh: Mesh) -> list[jax.Array]:
    """Rows ``start : start + chunk`` of every input, split over the mesh's devices; past ``n``
    the last row repeats (padding)."""
    stop = start + chunk
    if stop <= n:
        rows = [a[start:stop] for a in host]
    else:
        index = np.minimum(np.arange(start, stop), n - 1)
        rows = [a[index] for a in host]
    sharding = NamedSharding(mesh, PartitionSpec("rows"))
    return [jax.device_put(r, sharding) for r in rows]


def _allocate(out_info: Any, n: int, out: Any) -> Any:
    """Host outputs of shape (n, *leaf_shape): new numpy arrays, or ``out`` once checked."""
    if out is None:
        return jax.tree_util.tree_map(lambda s: np.empty((n, *s.shape[1:]), s.dtype), out_info)
    expected = jax.tree_util.tree_structure(out_info)
    got = jax.tree_util.tree_structure(out)
    if expected != got:
        raise ShapeError(
            f"chunked_map: out must have the structure of fn's output, {expected}, got {got}."
        )
    for (path, spec), leaf in zip(
        jax.tree_util.tree_leaves_with_path(out_info), jax.tree_util.tree_leaves(out), strict=True
    ):
        where = jax.tree_util.keystr(path)
        want = (n, *spec.shape[1:])
        shape = getattr(leaf, "shape", None)
        if not isinstance(leaf, np.ndarray) or tuple(shape) != want:
            raise ShapeError(
                f"chunked_map: out{where} must be a writable numpy array of shape {want}, got "
                f"{type(leaf).__name__} of shape {shape}. Allocate it with "
                f"np.empty({want}, {np.dtype(spec.dtype).name}) or np.memmap."
            )
        if not np.can_cast(spec.dtype, leaf.dtype, casting="same_kind"):
            raise ShapeError(
                f"chunked_map: out{where} has dtype {leaf.dtype}, which cannot hold fn's "
                f"{np.dtype(spec.dtype).name} results; use dtype {np.dtype(spec.dtype).name}."
            )
        if not leaf.flags.writeable:
            raise ShapeError(f"chunked_map: out{where} is read-only; pass a writable array.")
    return out


def _to_host(x: jax.Array) -> np.ndarray:
    if jax.process_count() > 1 and not x.is_fully_addressable:
        from jax.experimental import multihost_utils

        return np.asarray(multihost_utils.process_allgather(x, tiled=True))
    return np.asarray(x)


def _drain(results: Any, start: int, stop: int, device_out: Any) -> None:
    """Copy rows ``0 : stop - start`` of a finished chunk into ``results[start:stop]`` (host
    arrays) or append them to a :class:`_FileWriter`."""
    if isinstance(results, _FileWriter):
        results.append(jax.tree_util.tree_map(lambda x: _to_host(x)[: stop - start], device_out))
        return

    def copy(dst: np.ndarray, src: jax.Array) -> None:
        dst[start:stop] = _to_host(src)[: stop - start]

    jax.tree_util.tree_map(copy, results, device_out)


class _FileWriter:
    """Writes each output leaf as a ``.npy`` file, chunk after chunk, then publishes them.

    ``path`` ending in ``.npz``: an uncompressed npz (a zip of the ``.npy`` files); otherwise a
    directory of ``.npy`` files. Everything is written to a temporary sibling first and renamed
    into place at :meth:`commit`, so an interruption never leaves a half-written result.
    """

    def __init__(self, path: str, out_info: Any, n: int) -> None:
        self.path = os.path.abspath(path)
        parent = os.path.dirname(self.path) or "."
        if not os.path.isdir(parent):
            raise JaxkinError(f"chunked_map: directory {parent!r} for out does not exist.")
        if os.path.exists(self.path) and not self.path.endswith(".npz"):
            raise JaxkinError(f"chunked_map: out {path!r} already exists; choose a new path.")
        self.tmp = tempfile.mkdtemp(prefix=".jaxkin-", dir=parent)
        leaves = jax.tree_util.tree_leaves_with_path(out_info)
        self.names = [_leaf_name(p) or "out" for p, _ in leaves]
        self.files = []
        for name, (_, spec) in zip(self.names, leaves, strict=True):
            f = open(os.path.join(self.tmp, f"{name}.npy"), "wb")
            header = {
                "descr": np.lib.format.dtype_to_descr(np.dtype(spec.dtype)),
                "fortran_order": False,
                "shape": (n, *spec.shape[1:]),
            }
            np.lib.format.write_array_header_1_0(f, header)
            self.files.append(f)
        self.treedef = jax.tree_util.tree_structure(out_info)
        self.done = False

    def append(self, chunk_out: Any) -> None:
        for f, leaf in zip(self.files, jax.tree_util.tree_leaves(chunk_out), strict=True):
            f.write(np.ascontiguousarray(leaf).tobytes())

    def commit(self) -> str:
        for f in self.files:
            f.close()
        if self.path.endswith(".npz"):
            staged = os.path.join(self.tmp, "result.npz")
            with zipfile.ZipFile(staged, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as z:
                for name in self.names:
                    z.write(os.path.join(self.tmp, f"{name}.npy"), arcname=f"{name}.npy")
            os.replace(staged, self.path)
        else:
            os.replace(self.tmp, self.path)
            self.tmp = None
        self.done = True
        return self.path

    def abort(self) -> None:
        for f in self.files:
            if not f.closed:
                f.close()
        if self.tmp is not None and os.path.isdir(self.tmp):
            shutil.rmtree(self.tmp, ignore_errors=True)
        self.tmp = None


def _leaf_name(path) -> str:
    name = jax.tree_util.keystr(path)
    return "".join(c if c.isalnum() or c in "_-" else "_" for c in name).strip("_")
