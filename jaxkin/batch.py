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
3. :func:`_drain` hands a finished chunk's results, padding dropped, to the host outputs: numpy
   arrays, a sink, or a :class:`ResultWriter` streaming them to an npz, CSV or directory.

While one chunk is drained the next is already running (JAX dispatches asynchronously).
"""

from __future__ import annotations

import collections
import contextlib
import csv
import dataclasses
import errno
import io
import math
import os
import re
import shutil
import signal
import sys
import threading
import time
import unicodedata
import zipfile
import zlib
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import Any, TextIO

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .errors import JaxkinError, ShapeError

__all__ = [
    "MapStats",
    "ProgressBar",
    "ResultWriter",
    "chunked_map",
    "csv_record",
    "csv_records",
    "stream_map",
]

DEFAULT_CHUNK_SIZE = 65536


# ---------------------------------------------------------------------- progress bar
class ProgressBar:
    """A progress bar for chunked work: a thin wrapper of ``tqdm.auto.tqdm``.

    tqdm is optional (``pip install "jaxkin[progress]"``): without it the bar is silent and
    raises nothing. With it, the bar draws on ``file`` (default stderr) in a terminal and as a
    widget or text in Jupyter. It is silent when ``enabled`` is False, and on a stream that is not
    a terminal (outside Jupyter) unless ``force`` is True. ``min_interval``: seconds between
    redraws; ``width``: the line's width in characters (default: the terminal's). Use it as a
    context manager, or call :meth:`close` when done::

        with ProgressBar(total=n, desc="q") as bar:
            for chunk in chunks:
                ...
                bar.update(len(chunk))

    ``chunked_map(progress=True)`` makes one, forced on. Any tqdm instance can be passed as
    ``progress`` instead.

    >>> bar = ProgressBar(3, "rows", enabled=False)  # counts, draws nothing
    >>> bar.update(2); bar.update(1); bar.close()
    >>> bar.done, bar.active
    (3, False)
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
        width: int | None = None,
    ) -> None:
        self.total = int(total)
        self.done = 0
        self.file = file
        tqdm = _tqdm_class() if enabled else None
        self.bar = None
        if tqdm is not None:
            self.bar = tqdm(
                total=self.total,
                desc=desc or None,
                unit=unit,
                disable=False if force else None,  # None: silent off a terminal (tqdm's rule)
                file=file,
                mininterval=float(min_interval),
                ncols=width,
            )

    @property
    def active(self) -> bool:
        """Whether anything is drawn (tqdm installed, enabled, on a terminal or forced)."""
        return self.bar is not None and not self.bar.disable

    def note(self, text: str) -> None:
        """Show ``text`` after the bar until :meth:`start` (e.g. "compiling")."""
        if self.bar is not None:
            self.bar.set_postfix_str(text)

    def start(self) -> None:
        """Clear the note and restart the clock (the rate should not include a compile)."""
        if self.bar is not None:
            self.bar.set_postfix_str("", refresh=False)
            self.bar.reset()
            self.bar.update(self.done)

    def update(self, n: int = 1) -> None:
        """Count ``n`` more items done."""
        self.done += int(n)
        if self.bar is not None:
            self.bar.update(int(n))

    def close(self) -> None:
        """Draw the final state and end the line (idempotent)."""
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _tqdm_class() -> Any:
    """``tqdm.auto.tqdm`` (a notebook widget in Jupyter, text elsewhere), or None without tqdm."""
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm


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
    progress: Any = False,
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
      *arrays: one or more inputs, all of leading length ``N``: array-likes (numpy, JAX; a JAX
        array is copied to the host first), or row sources read slice by slice, never whole
        (``np.memmap``, an h5py or zarr dataset, any object with ``shape``, ``dtype`` and
        ``source[start:stop]``), so inputs larger than memory stream too.
      chunk_size: most rows per compiled call (>= 1). Memory on the device is about ``c``
        times the per-row footprint of ``fn``'s intermediates; the default suits a CPU.
      progress: True for a tqdm bar on stderr, in a terminal or in Jupyter; nothing is shown
        and nothing raised when tqdm is not installed (``pip install "jaxkin[progress]"``). Or a
        bar to update by the rows done: a :class:`ProgressBar` (shows the compile, then closed
        at the end) or any object with ``update(n)`` such as a ``tqdm`` instance (not closed;
        its ``total`` should be ``N``).
      out: where results go:

        * a pytree of writable arrays (e.g. ``np.memmap``) with the structure of ``fn``'s output
          and leaf shapes ``(N, *leaf_shape)``, filled in place;
        * a path: ``"results.npz"`` (an uncompressed npz), ``"results.csv"`` or a directory (one
          ``.npy`` per output leaf, loadable with ``np.load(..., mmap_mode="r")``), named after
          the leaves' paths (``{"J": ...}`` gives ``J.npy``). Written by a :class:`ResultWriter`
          chunk by chunk (never held in memory, so they may exceed it); the file appears
          atomically at the end and the function returns its absolute path;
        * a sink: an object with an ``append(chunk)`` method (e.g. an open
          :class:`ResultWriter`), called with each chunk's results (``fn``'s pytree, numpy
          leaves, padding dropped) in row order; returned as is.
      return_stats: also return a :class:`MapStats` with compile and run times.
      devices: where each chunk runs. None (default) or ``"all"``: every device JAX sees
        (``jax.devices()``: all GPUs, or all hosts' devices after ``jax.distributed.initialize``);
        a sequence of devices; or a 1-D ``jax.sharding.Mesh``. With more than one device each
        chunk is split along its rows with a ``NamedSharding`` (the chunk is rounded up to a
        multiple of the device count) and the compiled call runs on all of them at once.
        Test on a CPU with ``XLA_FLAGS=--xla_force_host_platform_device_count=4``.

    Returns:
      The pytree ``fn`` returns, each leaf a numpy array of shape ``(N, *leaf_shape)`` (``out``
      itself when given; the path for a path); with ``return_stats=True`` the pair
      ``(result, stats)``.

    Raises:
      ShapeError: no arrays, an array without a leading axis, unequal leading lengths, or an
        ``out`` that does not match ``fn``'s output.
      JaxkinError: ``chunk_size`` is not a positive integer; an ``out`` path whose directory is
        missing, or output leaves whose names coincide once made file names.
      OSError: writing an ``out`` path failed (disk full...); nothing is left under its name.
    """
    if not callable(fn):
        raise JaxkinError(f"chunked_map: fn must be callable, got {type(fn).__name__}.")
    host, n = _check_inputs(arrays)
    mesh = _mesh(devices)
    chunk, n_chunks = _chunking(chunk_size, n, mesh.size)

    bar = _bar(progress, n)
    try:
        t0 = time.perf_counter()
        traced = _trace(fn, host, chunk, mesh)
        with _target(out, traced.out_info, n) as (results, put):
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
                    _drain(put, *pending)
                    bar.update(pending[1] - pending[0])
                pending = running
            if pending is not None:
                _drain(put, *pending)
                bar.update(pending[1] - pending[0])
    finally:
        bar.close()
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


def _bar(progress: Any, n: int) -> ProgressBar:
    """The :class:`ProgressBar` that ``chunked_map`` drives for its ``progress`` argument."""
    if isinstance(progress, ProgressBar):
        return progress
    if isinstance(progress, bool) or progress is None:
        return ProgressBar(n, enabled=bool(progress), force=True)
    if not callable(getattr(progress, "update", None)):
        raise JaxkinError(
            "chunked_map: progress must be True, False, a ProgressBar or an object with an "
            f"update(n) method such as a tqdm bar, got {type(progress).__name__}."
        )
    return _Forward(progress)


class _Forward(ProgressBar):
    """Forwards the rows done to a caller's bar (a tqdm instance...), which it never closes."""

    def __init__(self, target: Any) -> None:
        super().__init__(0, enabled=False)
        self.target = target

    def update(self, n: int = 1) -> None:
        super().update(n)
        self.target.update(int(n))


@contextlib.contextmanager
def _target(out: Any, out_info: Any, n: int) -> Iterator[tuple[Any, Callable[..., None]]]:
    """``(what chunked_map returns, put(start, stop, host chunk))`` for each kind of ``out``; a
    path is committed when the block ends normally and removed when it raises."""
    if isinstance(out, (str, os.PathLike)):
        names = _leaf_names(out_info)
        specs = jax.tree_util.tree_leaves(out_info)
        fields = {k: (s.shape[1:], s.dtype) for k, s in zip(names, specs, strict=True)}
        with ResultWriter(out, fields, n) as writer:

            def put(start: int, stop: int, tree: Any) -> None:
                writer.append(dict(zip(names, jax.tree_util.tree_leaves(tree), strict=True)))

            yield writer.path, put
            writer.commit()
    elif callable(getattr(out, "append", None)) and not isinstance(out, list):
        yield out, lambda start, stop, tree: out.append(tree)
    else:
        results = _allocate(out_info, n, out)  # checks out= before the compile

        def put(start: int, stop: int, tree: Any) -> None:
            def copy(dst: np.ndarray, src: np.ndarray) -> None:
                dst[start:stop] = src

            jax.tree_util.tree_map(copy, results, tree)

        yield results, put


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

    ``fn`` is compiled for the first batch's number of inputs, dtypes and shapes after the row
    axis; a later batch that differs raises :class:`~jaxkin.ShapeError` naming both.
    ``chunk_size`` and ``devices`` are checked when called, before the first batch is read: a
    ``chunk_size`` that is not a positive integer raises :class:`~jaxkin.JaxkinError`.
    """
    mesh = _mesh(devices)
    size = _chunk_size(chunk_size, "stream_map")
    chunk, _ = _chunking(size, size, mesh.size)
    return _stream(fn, batches, chunk, mesh)


def _stream(
    fn: Callable[..., Any], batches: Iterable[Any], chunk: int, mesh: Mesh
) -> Iterator[Any]:
    """The generator behind :func:`stream_map`, for checked ``chunk`` and ``mesh``."""
    compiled, signature = None, None
    queue: collections.deque[list[Any]] = collections.deque()
    buffered = 0

    def run(rows: int):
        host = _take(queue, rows)
        out = compiled(*_feed(host, 0, chunk, rows, mesh))
        return jax.tree_util.tree_map(lambda x: _to_host(x)[:rows], out)

    for index, item in enumerate(batches):
        host, rows = _check_inputs(item if isinstance(item, tuple) else (item,))
        got = [(np.dtype(a.dtype).name, tuple(a.shape[1:])) for a in host]
        if compiled is None:
            compiled, signature = _trace(fn, host, chunk, mesh).lower().compile(), got
        elif got != signature:
            raise ShapeError(
                f"stream_map: batch {index} has inputs (dtype, row shape) {got}, but fn was "
                f"compiled for the first batch's {signature}. Give every batch the same inputs, "
                "dtypes and shapes after the row axis (convert with np.asarray(x, dtype))."
            )
        if rows:
            queue.append(host)
            buffered += rows
        while buffered >= chunk:
            yield run(chunk)
            buffered -= chunk
    if buffered:
        yield run(buffered)


def _take(queue: collections.deque[list[Any]], rows: int) -> list[np.ndarray]:
    """The first ``rows`` rows of the queued batches, removed from the queue and joined."""
    parts, need = [], rows
    while need:
        head = queue[0]
        k = head[0].shape[0]
        if k <= need:
            parts.append(queue.popleft())
            need -= k
        else:
            parts.append([a[:need] for a in head])
            queue[0] = [a[need:] for a in head]
            need = 0
    return [np.concatenate(cols) if len(cols) > 1 else cols[0] for cols in zip(*parts, strict=True)]


class _Rows:
    """A row source (``shape``, ``dtype``, ``source[start:stop]``) read slice by slice, each slice
    converted to ``dtype``."""

    def __init__(self, source: Any, dtype: np.dtype) -> None:
        self.source = source
        self.shape = tuple(int(s) for s in source.shape)
        self.dtype = dtype

    def __getitem__(self, rows: slice) -> np.ndarray:
        return np.asarray(self.source[rows], dtype=self.dtype)


def _is_row_source(a: Any) -> bool:
    return (
        not isinstance(a, (np.ndarray, jax.Array, list, tuple))
        and isinstance(getattr(a, "shape", None), tuple)
        and hasattr(a, "dtype")
        and hasattr(a, "__getitem__")
    )


def _check_inputs(arrays: tuple[Any, ...]) -> tuple[list[Any], int]:
    if not arrays:
        raise ShapeError(
            "chunked_map needs at least one input array, e.g. chunked_map(fn, qs) with qs of "
            "shape (N, dof)."
        )
    host = []
    for i, a in enumerate(arrays):
        try:
            arr = a if _is_row_source(a) else np.asarray(a)
        except (TypeError, ValueError) as e:
            raise ShapeError(f"chunked_map: input {i} is not array-like ({e}).") from None
        if len(arr.shape) == 0:
            raise ShapeError(
                f"chunked_map: input {i} must have a leading batch axis (shape (N, ...)), got a "
                "scalar. Close over values shared by every row in fn instead of passing them."
            )
        # JAX's own dtype (float32 while x64 is off), so the compiled call accepts the chunks.
        dtype = jax.dtypes.canonicalize_dtype(np.dtype(arr.dtype))
        if _is_row_source(arr):
            host.append(_Rows(arr, dtype))
        else:
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
    n_chunks = -(-n // _chunk_size(chunk_size, "chunked_map"))
    chunk = -(-n // n_chunks) if n_chunks else 1
    chunk = -(-chunk // n_devices) * n_devices
    return chunk, n_chunks


def _chunk_size(chunk_size: Any, who: str) -> int:
    """``chunk_size`` as an int; a :class:`JaxkinError` (naming ``who``) unless it is a positive
    integer (a bool is not)."""
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)):
        raise JaxkinError(
            f"{who}: chunk_size must be a positive integer, got {chunk_size!r} "
            f"({type(chunk_size).__name__}). The default is {DEFAULT_CHUNK_SIZE}."
        )
    if chunk_size < 1:
        raise JaxkinError(
            f"{who}: chunk_size must be >= 1, got {chunk_size}. "
            f"The default is {DEFAULT_CHUNK_SIZE}."
        )
    return int(chunk_size)


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


def _feed(host: list[Any], start: int, chunk: int, n: int, mesh: Mesh) -> list[jax.Array]:
    """Rows ``start : start + chunk`` of every input, split over the mesh's devices; past ``n``
    the last row repeats (padding)."""
    stop = start + chunk
    rows = [a[start : min(stop, n)] for a in host]
    if stop > n:
        rows = [np.concatenate([r, np.repeat(r[-1:], stop - n, axis=0)]) for r in rows]
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


def _drain(put: Callable[..., None], start: int, stop: int, device_out: Any) -> None:
    """Hand rows ``0 : stop - start`` of a finished chunk, on the host, to ``put``."""
    put(start, stop, jax.tree_util.tree_map(lambda x: _to_host(x)[: stop - start], device_out))


def _leaf_names(out_info: Any) -> list[str]:
    """File names (without ``.npy``) of the output leaves; refuses two leaves that would share
    one, e.g. keys ``"J v"`` and ``"J_v"``."""
    names: dict[str, str] = {}
    for path, _ in jax.tree_util.tree_leaves_with_path(out_info):
        where = jax.tree_util.keystr(path)
        name = "".join(c if c.isalnum() or c in "_-" else "_" for c in where).strip("_") or "out"
        if name in names:
            raise JaxkinError(
                f"chunked_map: output leaves {names[name] or 'out'} and {where} would both be "
                f"written as {name!r}; rename one of them (letters, digits, '_' and '-' are kept, "
                "other characters become '_')."
            )
        names[name] = where
    return list(names)


# ---------------------------------------------------------------------- result files
RESULT_FORMATS = ("npz", "csv", "dir")


class ResultWriter:
    """Named arrays streamed to a file chunk by chunk, appearing complete under ``path`` or not
    at all.

    ``fields`` maps each name to ``(row_shape, dtype)``: the file holds, per name, an array of
    shape ``(n, *row_shape)``, appended in row order by :meth:`append`; ``meta`` adds small
    arrays written whole (labels, settings). Formats (``format=``, default from the suffix):

    * ``"npz"`` (``*.npz``): an uncompressed zip64 ``.npz``. Every member's size is known up
      front, so each is written in place into its own region of the file: no staging copy, the
      disk holds the file once;
    * ``"csv"`` (``*.csv``, or ``path="-"`` for standard output): one line per row; ``columns``
      maps the fields to write to their column names (default: every field, ``name`` or
      ``name_1 ... name_k``), quoted by the ``csv`` module where they hold ``,``, ``"`` or
      line breaks; ``comments`` become ``#`` lines above the header (default: ``meta``), each
      kept on its line: a backslash is doubled and line breaks and other control characters
      are written as Python's escapes (``\\n``, ``\\x1b``, ``\\u2028``).
      :func:`csv_records` reads names and comments back exactly;
    * ``"dir"`` (any other path): a new directory of ``name.npy`` files
      (``np.load(..., mmap_mode="r")`` reads them without loading).

    Everything is written to a temporary sibling of ``path``, named ``.<name>.<random>.tmp``
    (a file, or a directory for ``"dir"``), then flushed, ``fsync``-ed, given ordinary
    permissions (``0o666``/``0o777`` less the umask) and renamed onto ``path``. Use it as a
    context manager: leaving the block without :meth:`commit` (an exception, Ctrl-C, SIGTERM)
    removes the temporary. Inside the block SIGINT and SIGTERM run the handler installed
    before (Python's SIGINT handler raises ``KeyboardInterrupt``) or, where that was the
    default action, raise ``SystemExit(128 + signal)`` (143 for SIGTERM), so that this cleanup
    runs; an exception so raised where Python swallows it (inside a garbage-collector callback)
    is raised again by the next :meth:`append` or :meth:`commit`, so an interrupted run stops
    within a chunk and never commits. SIGXFSZ is ignored so that a file size limit is an
    ``OSError``. The handlers are restored on exit (main thread only; an ignored signal stays
    ignored). Only SIGKILL or a crash can leave the temporary behind.

    The temporary is created on entering the block, before any work: a directory that cannot
    be written (permissions, a read-only file system) raises :class:`~jaxkin.JaxkinError`
    naming it there (and at construction where ``os.access`` already says so).

    Example::

        with ResultWriter("r.npz", {"x": ((2,), "float64")}, n=3, meta={"note": "demo"}) as w:
            w.append({"x": np.ones((2, 2))})
            w.append({"x": np.zeros((1, 2))})
            w.commit()  # r.npz appears, holding x (3, 2) and note
    """

    def __init__(
        self,
        path: Any,
        fields: Mapping[str, tuple[Any, Any]],
        n: int,
        *,
        format: str | None = None,
        meta: Mapping[str, Any] | None = None,
        columns: Mapping[str, Sequence[str]] | None = None,
        comments: Sequence[str] | None = None,
    ) -> None:
        text = os.fspath(path)
        self.format = _result_format(text, format)
        self.path = text if text == "-" else os.path.abspath(text)
        self.fields = {k: (tuple(int(d) for d in s), np.dtype(t)) for k, (s, t) in fields.items()}
        self.meta = {k: np.asarray(v) for k, v in (meta or {}).items()}
        _check_names([*self.fields, *self.meta], self.format)
        self.n, self.rows, self.tmp = int(n), 0, None
        self._saved: list[tuple[int, Any]] = []
        self._pending: BaseException | None = None
        if self.format == "csv":
            columns = columns or {k: _default_columns(k, s) for k, (s, _) in self.fields.items()}
            if comments is None:
                comments = [f"{k} = {v}" for k, v in self.meta.items()]
            self._file: Any = _CsvFile(self.fields, self.n, columns, comments)
        elif self.format == "npz":
            self._file = _NpzFile(self.fields, self.n, self.meta)
        else:
            self._file = _DirFile(self.fields, self.n, self.meta)
        if self.path == "-":
            self._file.open(sys.stdout)
            return
        self._check_target()  # the temporary is created on entering the block (__enter__)

    def _check_target(self) -> None:
        parent = os.path.dirname(self.path)
        if not os.path.isdir(parent):
            raise JaxkinError(
                f"cannot write {self.path}: directory {parent} "
                + ("is not a directory" if os.path.lexists(parent) else "does not exist")
                + "; create it or choose another path."
            )
        if not os.access(parent, os.W_OK | os.X_OK):
            raise _unwritable(self.path, "permission denied")
        if self.format == "dir" and os.path.lexists(self.path):
            raise JaxkinError(f"out {self.path!r} already exists; choose a new path.")
        if os.path.isdir(self.path):
            raise JaxkinError(f"output path {self.path} is a directory; give a file name.")
        need, free = self._file.size_estimate(), shutil.disk_usage(parent).free
        if need > free:
            raise JaxkinError(
                f"cannot write {self.path}: it needs about {_size_text(need)} and {parent} has "
                f"{_size_text(free)} free; write fewer rows or elsewhere."
            )

    def _open(self) -> None:
        parent, name = os.path.split(self.path)
        try:
            for _ in range(100):
                # The name is recorded before the temporary exists: a SIGTERM at any point from
                # here on leaves abort() something to remove (tempfile's mkdtemp and mkstemp
                # return the name only after creating it).
                self.tmp = os.path.join(parent, f".{name}.{os.urandom(4).hex()}.tmp")
                try:
                    if self.format == "dir":
                        os.mkdir(self.tmp, 0o700)
                    else:
                        fd = os.open(self.tmp, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
                    break
                except FileExistsError:  # someone else's: not ours to remove
                    self.tmp = None
            else:
                raise FileExistsError(errno.EEXIST, "no free temporary name", self.path)
            if self.format == "dir":
                self._file.open(self.tmp)
            else:
                self._file.open(os.fdopen(fd, "w+b"))
        except OSError as e:
            self.abort()
            if e.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
                raise _unwritable(self.path, e.strerror) from None
            raise OSError(e.errno, e.strerror, self.path) from None
        except BaseException:  # e.g. Ctrl-C: __exit__ does not run when __enter__ raises
            self.abort()
            raise

    def append(self, rows: Mapping[str, Any]) -> None:
        """Append the next rows: ``rows[name]`` of shape ``(k, *row_shape)`` for every field,
        one ``k`` for all."""
        self._check_signal()
        if self._file is None:
            raise JaxkinError(f"ResultWriter for {self.path}: append after commit or abort.")
        self._open_once()  # used without a with-block
        missing = set(self.fields) - set(rows)
        if missing:
            raise ShapeError(f"ResultWriter.append: no rows for field(s) {sorted(missing)}.")
        arrays = {k: np.ascontiguousarray(rows[k], dtype=t) for k, (_, t) in self.fields.items()}
        counts = {a.shape[0] if a.ndim else -1 for a in arrays.values()}
        bad = [k for k, a in arrays.items() if a.shape[1:] != self.fields[k][0]]
        if len(counts) != 1 or bad or self.rows + max(counts) > self.n:
            shapes = {k: a.shape for k, a in arrays.items()}
            raise ShapeError(
                f"ResultWriter.append: rows of shapes {shapes} do not fit fields "
                f"{ {k: s for k, (s, _) in self.fields.items()} } with {self.n - self.rows} of "
                f"{self.n} rows left; give (k, *row_shape) arrays, one k for all."
            )
        self._io(self._file.append, arrays)
        self.rows += counts.pop()

    def commit(self) -> str:
        """Finish the file and rename it onto ``path`` (replacing a previous file); returns
        ``path``. Every one of the ``n`` rows must have been appended."""
        self._check_signal()
        if self._file is None:
            raise JaxkinError(f"ResultWriter for {self.path}: commit after commit or abort.")
        if self.rows != self.n:
            raise JaxkinError(
                f"ResultWriter for {self.path}: {self.rows} of {self.n} rows were appended; "
                "nothing was written."
            )
        self._open_once()  # n == 0 without a with-block
        self._io(self._file.close)
        self._file = None
        if self.tmp is not None:
            self._io(self._publish)
        return self.path

    def _publish(self) -> None:
        mask = _umask()
        os.chmod(self.tmp, (0o777 if self.format == "dir" else 0o666) & ~mask)
        os.replace(self.tmp, self.path)
        self.tmp = None
        _fsync_dir(os.path.dirname(self.path))

    def _io(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Run a write step; an OSError names ``path`` (not the temporary)."""
        try:
            return fn(*args)
        except OSError as e:
            raise OSError(e.errno, e.strerror, self.path) from None

    def abort(self) -> None:
        """Remove the temporary; ``path`` is left as it was (idempotent)."""
        if self._file is not None:
            with contextlib.suppress(OSError):
                self._file.discard()
            self._file = None
        if self.tmp is not None:
            if os.path.isdir(self.tmp):
                shutil.rmtree(self.tmp, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    os.remove(self.tmp)
            self.tmp = None

    def __enter__(self) -> ResultWriter:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._saved.append((sig, signal.getsignal(sig)))
                if self._saved[-1][1] != signal.SIG_IGN:
                    signal.signal(sig, self._interrupted)
            if hasattr(signal, "SIGXFSZ"):
                self._saved.append((signal.SIGXFSZ, signal.signal(signal.SIGXFSZ, signal.SIG_IGN)))
        # Only now, with the handlers in place: a SIGTERM can no longer find a temporary that
        # nothing would remove.
        try:
            self._open_once()
        except BaseException:  # __exit__ does not run when __enter__ raises: restore here
            self.__exit__(*sys.exc_info())
            raise
        return self

    def _open_once(self) -> None:
        if self.path != "-" and self.tmp is None and self._file is not None:
            self._open()

    def _interrupted(self, signum: int, frame: Any) -> None:
        """SIGINT and SIGTERM: run the handler installed before (SIGINT's raises
        KeyboardInterrupt), or raise ``SystemExit(128 + signum)`` where it was the default."""
        previous = dict(self._saved)[signum]
        try:
            if not callable(previous):
                raise SystemExit(128 + signum)
            previous(signum, frame)
        except BaseException as e:
            # Python may run this inside a gc or __del__ callback (JAX has some), which swallows
            # exceptions: kept, the next append or commit raises it again.
            self._pending = e
            raise

    def _check_signal(self) -> None:
        if self._pending is not None:
            raise self._pending

    def __exit__(self, *exc: Any) -> None:
        try:
            self.abort()
        finally:
            for sig, handler in reversed(self._saved):
                signal.signal(sig, signal.SIG_DFL if handler is None else handler)
            self._saved = []


def _unwritable(path: str, why: str | None) -> JaxkinError:
    parent = os.path.dirname(path)
    return JaxkinError(
        f"cannot write {path}: directory {parent} is not writable ({why}); choose a directory "
        "you can write to, or make it writable."
    )


def _size_text(nbytes: float) -> str:
    """``nbytes`` in the unit that fits: ``"512 bytes"``, ``"1.5 kB"``, ``"2.3 MB"``, ``"4.0 GB"``,
    ``"1.2 TB"`` (decimal units: 1 kB = 1000 bytes, as ``df -H`` counts)."""
    if nbytes < 1000:
        return f"{int(nbytes)} bytes"
    for unit in ("kB", "MB", "GB"):
        nbytes /= 1000
        if nbytes < 999.95:
            return f"{nbytes:.1f} {unit}"
    return f"{nbytes / 1000:,.1f} TB"


def _result_format(path: str, format: str | None) -> str:
    suffix = "csv" if path == "-" else os.path.splitext(path)[1].lower().lstrip(".")
    if format is None:
        return suffix if suffix in ("npz", "csv") else "dir"
    if format not in RESULT_FORMATS:
        raise JaxkinError(f"format must be one of {RESULT_FORMATS}, got {format!r}.")
    if (suffix in ("npz", "csv") and suffix != format) or (path == "-" and format != "csv"):
        where = "standard output ('-')" if path == "-" else f"{path!r}"
        raise JaxkinError(
            f"format {format!r} contradicts {where}: "
            + ("only csv goes to standard output" if path == "-" else f"a .{suffix} name")
            + "; change the name or the format."
        )
    return format


def _check_names(names: list[str], fmt: str) -> None:
    seen: dict[str, str] = {}
    for name in names:
        if not name or not all(c.isalnum() or c in "_-." for c in name) or name[0] == ".":
            raise JaxkinError(
                f"cannot write an array named {name!r}: use letters, digits, '_', '-' and '.'."
            )
        key = name.lower() if fmt == "dir" else name  # case-insensitive file systems
        if key in seen:
            raise JaxkinError(f"two arrays would be written as {name!r} ({seen[key]!r}).")
        seen[key] = name


def _default_columns(name: str, shape: tuple[int, ...]) -> list[str]:
    k = math.prod(shape)
    return [name] if shape == () else [f"{name}_{i + 1}" for i in range(k)]


def _umask() -> int:
    """The process umask, read without changing it where /proc allows."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync_dir(path: str) -> None:
    with contextlib.suppress(OSError):  # not every platform opens directories
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _npy_header(shape: tuple[int, ...], dtype: np.dtype) -> bytes:
    buf = io.BytesIO()
    header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": shape}
    np.lib.format.write_array_header_2_0(buf, header)
    return buf.getvalue()


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, array, allow_pickle=False)
    return buf.getvalue()


def _row_bytes(shape: tuple[int, ...], dtype: np.dtype) -> int:
    return math.prod(shape) * dtype.itemsize


class _NpzFile:
    """An uncompressed zip64 npz whose members are written in place: each member's local
    header and size are laid out when opened, chunks go to each member's next free offset,
    CRCs are patched into the headers and the central directory is appended at close."""

    def __init__(self, fields: dict, n: int, meta: dict[str, np.ndarray]) -> None:
        self.members = [(k, _npy_bytes(v), 0) for k, v in meta.items()]
        for k, (shape, dtype) in fields.items():
            self.members.append((k, _npy_header((n, *shape), dtype), n * _row_bytes(shape, dtype)))

    def size_estimate(self) -> int:
        return sum(len(head) + size + 200 for _, head, size in self.members)

    def open(self, f: Any) -> None:
        self.f, self.infos, self.at, self.crc, pos = f, [], {}, {}, 0
        stamp = time.localtime()[:6]
        for name, head, size in self.members:
            info = zipfile.ZipInfo(f"{name}.npy", date_time=stamp)
            info.file_size = info.compress_size = len(head) + size
            info.CRC = 0  # patched at close
            info.header_offset = pos
            local = info.FileHeader(zip64=True)
            f.seek(pos)
            f.write(local + head)
            self.infos.append(info)
            self.at[name], self.crc[name] = pos + len(local) + len(head), zlib.crc32(head)
            pos += len(local) + info.file_size
        self.end = pos

    def append(self, arrays: dict[str, np.ndarray]) -> None:
        for name, a in arrays.items():
            self.f.seek(self.at[name])
            self.f.write(memoryview(a).cast("B"))
            self.at[name] += a.nbytes
            self.crc[name] = zlib.crc32(memoryview(a).cast("B"), self.crc[name])

    def close(self) -> None:
        for info, (name, _, _) in zip(self.infos, self.members, strict=True):
            info.CRC = self.crc[name]
            self.f.seek(info.header_offset)
            self.f.write(info.FileHeader(zip64=True))
        self.f.seek(self.end)
        zf = zipfile.ZipFile(self.f, "w", allowZip64=True)  # writes the central directory only
        zf.filelist.extend(self.infos)
        zf.NameToInfo.update({i.filename: i for i in self.infos})
        zf.close()
        _sync_close(self.f)

    def discard(self) -> None:
        if hasattr(self, "f"):  # not opened when the temporary could not be created
            self.f.close()


def csv_records(
    lines: Iterable[str], *, source: Any = "csv", comments: list[str] | None = None
) -> Iterator[tuple[int, list[str]]]:
    """The records of CSV text such as a :class:`ResultWriter` writes: ``(line, fields)``.

    ``lines``: a text file opened with ``newline=""`` (so that quoted fields keep their line
    breaks) or any iterable of lines with their ends. Records are parsed by the ``csv`` module
    (quoted fields may hold ``,``, ``"`` and line breaks) and ``fields`` are returned as
    written, not stripped; ``line`` is the number of the record's first line. Comments and
    blank lines are recognised only where a record starts, never inside a quoted field: a
    blank line is skipped; a line whose first non-blank character is ``#`` is a comment, and
    when ``comments`` is a list its text (after ``#`` and one space, escapes such as ``\\n``
    undone: see :class:`ResultWriter`) is appended to it.

    Raises:
      JaxkinError: malformed CSV (``strict`` parsing: a quoted field never closed, or text
        after a closing quote), naming ``source`` and the line.

    >>> list(csv_records(['# a note\\n', 'x,"y, z"\\n', '\\n', '1,2\\n']))
    [(2, ['x', 'y, z']), (4, ['1', '2'])]
    """
    at = {"start": True, "line": 0, "first": 0}

    def record_lines() -> Iterator[str]:
        for number, line in enumerate(lines, start=1):
            at["line"] = number
            if at["start"]:
                head = line.lstrip()
                if not head:
                    continue
                if head.startswith("#"):
                    if comments is not None:
                        comments.append(_comment_text(head))
                    continue
                at["start"], at["first"] = False, number
            yield line

    reader = csv.reader(record_lines(), strict=True)
    while True:
        try:
            fields = next(reader)
        except StopIteration:
            return
        except csv.Error as e:
            raise JaxkinError(f"{source} line {at['line']}: {e}; check its quotes.") from None
        at["start"] = True
        yield at["first"], fields


def csv_record(fields: Sequence[str]) -> str:
    """``fields`` as one CSV record ending in ``\\n``, which :func:`csv_records` reads back as
    they are (a :class:`ResultWriter`'s header is one).

    Quoted by the ``csv`` module where a field holds ``,``, ``"``, ``\\r`` or ``\\n``; every
    field is quoted where the record would otherwise read as a comment (``#`` first), a blank
    line or a byte order mark.

    >>> csv_record(["x", "y, z", "#"])
    'x,"y, z",#\\n'
    >>> csv_record(["#a", "b"])
    '"#a","b"\\n'
    """
    buf = io.StringIO()
    # "\r\n": the csv module quotes fields holding its line terminator's characters (not others)
    csv.writer(buf, lineterminator="\r\n").writerow(fields)
    text = buf.getvalue()
    if not text.strip() or text.lstrip().startswith("#") or text.startswith("\ufeff"):
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\r\n", quoting=csv.QUOTE_ALL).writerow(fields)
        text = buf.getvalue()
    return text[: -len("\r\n")] + "\n"


_ESCAPES = {"\\": "\\", "\n": "n", "\r": "r", "\t": "t"}
_UNESCAPES = {v: k for k, v in _ESCAPES.items()}
_ESCAPED = re.compile(r"\\(?:[\\nrt]|x[0-9a-fA-F]{2}|u[0-9a-fA-F]{4}|U[0-9a-fA-F]{8})")


def _escape_comment(text: str) -> str:
    """``text`` on one line, reversibly: a backslash is doubled; line breaks and other control
    or format characters (Unicode categories Cc, Cf, Zl, Zp, Cs) become Python's escapes
    ``\\n``, ``\\r``, ``\\t``, ``\\xNN``, ``\\uNNNN``, ``\\UNNNNNNNN``
    (:func:`_comment_text` undoes them)."""
    out = []
    for c in text:
        if c in _ESCAPES:
            out.append("\\" + _ESCAPES[c])
        elif unicodedata.category(c) in ("Cc", "Cf", "Zl", "Zp", "Cs"):
            k = ord(c)
            width = 2 if k < 0x100 else 4 if k < 0x10000 else 8
            out.append(f"\\{'xuU'[width // 4]}{k:0{width}x}")
        else:
            out.append(c)
    return "".join(out)


def _comment_text(line: str) -> str:
    """The text of a ``#`` comment line as :func:`_escape_comment` wrote it."""
    text = line[1:].rstrip("\r\n")
    text = text[1:] if text.startswith(" ") else text

    def unescape(m: re.Match[str]) -> str:
        code = m.group()[1:]
        if code in _UNESCAPES:
            return _UNESCAPES[code]
        k = int(code[1:], 16)
        return chr(k) if k <= sys.maxunicode else m.group()

    return _ESCAPED.sub(unescape, text)


def _sync_close(f: Any) -> None:
    f.flush()
    os.fsync(f.fileno())
    f.close()


class _DirFile:
    """A directory of ``.npy`` files, one per field, each appended chunk by chunk."""

    def __init__(self, fields: dict, n: int, meta: dict[str, np.ndarray]) -> None:
        self.fields, self.n, self.meta, self.files = fields, n, meta, {}

    def size_estimate(self) -> int:
        rows = sum(self.n * _row_bytes(s, t) + 256 for s, t in self.fields.values())
        return rows + sum(v.nbytes + 256 for v in self.meta.values())

    def open(self, directory: str) -> None:
        self.directory = directory
        for name, value in self.meta.items():
            with open(os.path.join(directory, f"{name}.npy"), "wb") as f:
                f.write(_npy_bytes(value))
                f.flush()
                os.fsync(f.fileno())
        for name, (shape, dtype) in self.fields.items():
            self.files[name] = open(os.path.join(directory, f"{name}.npy"), "wb")
            self.files[name].write(_npy_header((self.n, *shape), dtype))

    def append(self, arrays: dict[str, np.ndarray]) -> None:
        for name, a in arrays.items():
            self.files[name].write(memoryview(a).cast("B"))

    def close(self) -> None:
        for f in self.files.values():
            _sync_close(f)
        _fsync_dir(self.directory)

    def discard(self) -> None:
        for f in self.files.values():
            f.close()


class _CsvFile:
    """One text line per row: the ``columns`` fields side by side, ``%.17g`` (float64) or
    ``%.9g`` (float32), so values round-trip; ``comments`` as ``#`` lines on top, each escaped
    onto its line (:func:`_escape_comment`); the header quoted by the ``csv`` module
    (:func:`csv_record`). :func:`csv_records` reads all of it back as written."""

    def __init__(
        self, fields: dict, n: int, columns: Mapping[str, Sequence[str]], comments
    ) -> None:
        unknown = set(columns) - set(fields)
        if unknown:
            raise JaxkinError(f"csv columns name unknown fields {sorted(unknown)}.")
        for name, names in columns.items():
            if len(names) != math.prod(fields[name][0]):
                raise JaxkinError(
                    f"csv: field {name!r} has {math.prod(fields[name][0])} values per row, "
                    f"but {len(names)} column names."
                )
        self.columns, self.comments = dict(columns), [str(c) for c in comments]
        self.names = [str(c) for cols in self.columns.values() for c in cols]
        for c in self.names:
            try:
                c.encode("utf-8")
            except UnicodeEncodeError:
                raise JaxkinError(
                    f"csv: column name {c!r} holds a lone surrogate, which UTF-8 cannot "
                    "carry; rename the column."
                ) from None
        wide = any(fields[k][1] == np.float64 for k in self.columns)
        self.digits, self.n_values = (17 if wide else 9), sum(map(len, self.columns.values()))
        self.n = n

    def size_estimate(self) -> int:
        return self.n * self.n_values * (self.digits + 7)  # sign, point, exponent, comma

    def open(self, f: Any) -> None:
        self.f = f
        lines = [f"# {_escape_comment(c)}\n" for c in self.comments]
        self._write("".join(lines) + csv_record(self.names))

    def _write(self, text: str) -> None:
        self.f.write(text if isinstance(self.f, io.TextIOBase) else text.encode())

    def append(self, arrays: dict[str, np.ndarray]) -> None:
        k = next(iter(arrays.values())).shape[0]
        if k == 0:  # reshape(0, -1) is ambiguous
            return
        table = np.concatenate([arrays[c].reshape(k, -1) for c in self.columns], axis=1)
        buf = io.StringIO()
        np.savetxt(buf, table, fmt=f"%.{self.digits}g", delimiter=",")
        self._write(buf.getvalue())

    def close(self) -> None:
        if isinstance(self.f, io.TextIOBase):  # standard output
            self.f.flush()
        else:
            _sync_close(self.f)

    def discard(self) -> None:
        if hasattr(self, "f") and not isinstance(self.f, io.TextIOBase):
            self.f.close()
