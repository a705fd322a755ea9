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
   arrays, a sink, or a :class:`~jaxkin.io.ResultWriter` streaming them to an npz, CSV or
   directory (:mod:`jaxkin.io` holds the writers). The drained chunk's device buffers are then
   donated to a later chunk, which writes its results over them (:func:`_compile_into`).

While one chunk is drained the next is already running (JAX dispatches asynchronously).

:func:`chunked_scan` is the sequential counterpart: a ``lax.scan`` over the rows (each row's
computation depends on a state carried from the previous one, such as the configuration of a
tracked motion), chunk by chunk, the state carried across chunks, with the same inputs, outputs
and progress bar.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import math
import os
import time
import weakref
from collections.abc import Callable, Iterable, Iterator
from typing import Any, TextIO

import jax
import jax.numpy as jnp
import numpy as np
from jax.extend import core as jax_core
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._jit import compiler_options
from .errors import JaxkinError, ShapeError
from .io import ResultWriter

# Before jaxkin.io was split out of this module, the writer and its CSV helpers lived here:
# jaxkin.batch.ResultWriter, csv_record and csv_records keep working (documented in jaxkin.io).
from .io import csv_record as csv_record
from .io import csv_records as csv_records

__all__ = [
    "MapStats",
    "ProgressBar",
    "chunked_map",
    "chunked_scan",
    "stream_map",
]

DEFAULT_CHUNK_SIZE = 65536
"""Rows per compiled call of :func:`chunked_scan` and :func:`stream_map` by default, and of
:func:`chunked_map` off CPUs (and its largest automatic chunk)."""

CHUNK_RESULT_BYTES = 8 * 2**20
"""On CPUs, :func:`chunked_map`'s default chunk holds about this many bytes of results. Each
call of a compiled chunk allocates its intermediates anew; once they pass glibc's 32 MiB limit
for reusing freed memory, every call pages them in again (4 KiB page faults, ~2.2-2.6 us each
here). ``python3 -m bench`` measures the result (its ``jaxkin chunked_map`` rows against one
``jit(vmap)`` call, bench/README.md): at N = 100,000, 1.3-2.0x faster for the 32-joint chain,
the G1's four frames, the Panda and a Talos hand. The size itself came from a one-off sweep
(not in the repository) of 4, 8 and 16 MiB on those robots, where 8 MiB was best or within
the ~20% run-to-run noise of the best."""

MIN_AUTO_CHUNK = 1024
"""The smallest chunk :func:`chunked_map` picks by itself (per-call overhead bounds it)."""


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
    shape (once; about 0 when a previous call with the same ``fn`` built it). ``run_seconds``:
    feeding every chunk, running it and copying its results to the host outputs, compile
    excluded. ``padding``: rows added to fill the last chunk (computed and
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
    chunk_size: int | None = None,
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
    once for that shape (and kept: a later call with the same ``fn`` object, chunk shape and
    dtypes reuses the program, as ``jax.jit`` does; a new function, e.g. a new ``lambda``, is
    compiled afresh; with the default ``chunk_size`` ``fn`` is also traced once for one row, by
    ``jax.eval_shape``, to size the chunk). The last chunk is padded to ``c`` rows (fewer than
    ``k`` padding rows) by repeating the last row, so ``fn`` only sees valid inputs; the
    padding is dropped from the results.

    Args:
      fn: per-row function; pure and jittable.
      *arrays: one or more inputs, all of leading length ``N``: array-likes (numpy, JAX; a JAX
        array is copied to the host first), or row sources read slice by slice, never whole
        (``np.memmap``, an h5py or zarr dataset, any object with ``shape``, ``dtype`` and
        ``source[start:stop]``), so inputs larger than memory stream too.
      chunk_size: most rows per compiled call (>= 1). Memory on the device is about ``c``
        times the per-row footprint of ``fn``'s intermediates. Default (None): on CPUs, as
        many rows as give about :data:`CHUNK_RESULT_BYTES` of results (from ``fn``'s output
        shapes, between :data:`MIN_AUTO_CHUNK` and :data:`DEFAULT_CHUNK_SIZE` rows), so that
        its intermediates stay in memory already paged in (the Panda's (6, 7) Jacobian: 24,966
        rows; a G1's four (6, 35) Jacobians: 1,248). Elsewhere :data:`DEFAULT_CHUNK_SIZE`.
        Each chunk's results are written over an earlier chunk's drained device buffers
        (donated), not into new memory.
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
          the leaves' paths (``{"J": ...}`` gives ``J.npy``). Written by a
          :class:`~jaxkin.io.ResultWriter` chunk by chunk (never held in memory, so they may
          exceed it); the file appears atomically at the end and the function returns its
          absolute path;
        * a sink: an object with an ``append(chunk)`` method (e.g. an open
          :class:`~jaxkin.io.ResultWriter`), called with each chunk's results (``fn``'s pytree,
          numpy leaves, padding dropped) in row order; returned as is.
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
    if chunk_size is None:
        chunk_size = _default_chunk_size(fn, host, mesh)
    chunk, n_chunks = _chunking(chunk_size, n, mesh.size)

    bar = _bar(progress, n)
    try:
        t0 = time.perf_counter()
        traced = _trace(fn, host, chunk, mesh)
        with _target(out, traced.out_info, n) as (results, put):
            if n_chunks:
                bar.note(f"compiling for chunks of {chunk:,} rows ...")
                into = _compile_into(fn, mesh, traced)
            compile_seconds = time.perf_counter() - t0
            bar.start()
            t0 = time.perf_counter()
            if n_chunks:

                def launch(start: int) -> Any:
                    return into.compiled(into.buffers(), *_feed(host, start, chunk, n, mesh))

                try:
                    _pipelined(n, chunk, n_chunks, launch, put, bar, recycle=into.recycle)
                finally:
                    into.settle()
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


def chunked_scan(
    step: Callable[..., Any],
    init: Any,
    *arrays: Any,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    progress: Any = False,
    out: Any = None,
    return_stats: bool = False,
):
    """``jax.lax.scan(step, init, arrays)`` evaluated chunk by chunk, the carry passed across
    chunks: a sequential computation (each row depends on the previous one's state) over a
    sequence of any length in bounded memory.

    ``step(carry, *rows) -> (carry, outputs)`` is written for one row (as for ``lax.scan``):
    ``rows[i]`` is ``arrays[i][t]``; ``carry`` a pytree of arrays whose structure, shapes and
    dtypes ``step`` keeps. The sequence is cut into chunks as in :func:`chunked_map`, and
    ``jax.jit`` of a ``lax.scan`` over one chunk is compiled once (and kept: a later call with the
    same ``step``, carry and chunk shapes and dtypes reuses the program, as ``jax.jit`` does;
    ``step`` is the key, by identity for a function, so a new ``lambda`` is compiled afresh,
    and by value for a hashable value object: pass arrays that vary between calls in the
    carry, not as constants it closes over); each chunk starts from the
    carry the previous one ended with, which stays on the device (the next chunk is dispatched
    before the previous one's outputs are copied out). The last chunk is padded by repeating its
    last row; padded rows leave the carry unchanged and their outputs are dropped, so the result
    equals one ``lax.scan`` over the whole sequence. Runs on one device (the rows are
    sequential: there is nothing to split).

    ``arrays``, ``chunk_size``, ``progress`` and ``out`` are as for :func:`chunked_map` (inputs
    may be row sources such as ``np.memmap``; ``out`` a pytree of arrays, a path written by a
    :class:`~jaxkin.io.ResultWriter`, or a sink), and so are the errors raised.

    Returns:
      ``(carry, outputs)``: the final carry (JAX arrays) and the stacked per-row outputs (numpy
      arrays of shape ``(N, ...)``; ``out`` itself, its absolute path, or the sink when given);
      with ``return_stats=True`` the triple ``(carry, outputs, stats)`` (:class:`MapStats`).

    >>> import numpy as np
    >>> def step(total, x):
    ...     total = total + x
    ...     return total, {"running": total}
    >>> xs = np.arange(5, dtype=np.float32)
    >>> total, ys = chunked_scan(step, np.float32(0), xs, chunk_size=2)
    >>> float(total), ys["running"].tolist()
    (10.0, [0.0, 1.0, 3.0, 6.0, 10.0])
    """
    if not callable(step):
        raise JaxkinError(f"chunked_scan: step must be callable, got {type(step).__name__}.")
    host, n = _check_inputs(arrays)
    mesh = _mesh([jax.devices()[0]])
    chunk, n_chunks = _chunking(chunk_size, n)
    carry = jax.tree_util.tree_map(jnp.asarray, init)

    bar = _bar(progress, n)
    try:
        t0 = time.perf_counter()
        traced = _trace_scan(step, carry, host, chunk)
        with _target(out, traced.out_info[1], n) as (results, put):
            if n_chunks:
                bar.note(f"compiling for chunks of {chunk:,} rows ...")
                compiled = traced.lower().compile(compiler_options() or None)
            compile_seconds = time.perf_counter() - t0
            bar.start()
            t0 = time.perf_counter()
            state = [carry]

            def launch(start: int) -> Any:
                rows = _feed(host, start, chunk, n, mesh)
                state[0], ys = compiled(state[0], np.int32(min(start + chunk, n) - start), *rows)
                return ys

            _pipelined(n, chunk, n_chunks, launch, put, bar)
            carry = state[0]
    finally:
        bar.close()
    run_seconds = time.perf_counter() - t0
    if not return_stats:
        return carry, results
    stats = MapStats(
        n=n,
        chunk_size=chunk,
        n_chunks=n_chunks,
        padding=n_chunks * chunk - n,
        compile_seconds=compile_seconds,
        run_seconds=run_seconds,
    )
    return carry, results, stats


def _trace_scan(
    step: Callable[..., Any], carry: Any, host: list[Any], chunk: int
) -> jax.stages.Traced:
    """Trace ``jit`` of a ``lax.scan`` of ``step`` over ``chunk`` rows, as a function of
    ``(carry, valid, *chunk arrays)``: rows at or past ``valid`` (padding) keep the carry.
    ``.out_info``: ``(carry, outputs)`` shapes. The ``jax.jit`` object is kept per ``step``
    (:func:`_scanned`), so that a later call with the same step, shapes and dtypes reuses JAX's
    caches of the trace, the lowering and the executable."""
    spec = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype), carry)
    specs = [jax.ShapeDtypeStruct((chunk, *a.shape[1:]), a.dtype) for a in host]
    return _scanned(step).trace(spec, jax.ShapeDtypeStruct((), np.int32), *specs)


SCANNED_CACHE_SIZE = 8
"""How many ``jax.jit`` objects of a chunk's scan :func:`_scanned` keeps (least recently used
dropped first); each holds its step function (and what that closes over, e.g. a robot) and
JAX's compiled executables for the shapes it was called with."""

_scanned_cache: collections.OrderedDict = collections.OrderedDict()


def _scanned(step: Callable[..., Any]) -> Any:
    """``jax.jit`` of :func:`_scan_chunk` for ``step``: one object per ``step`` (at most
    :data:`SCANNED_CACHE_SIZE`), a new one for an unhashable ``step``. Keyed by the step itself
    (by value for a hashable value object such as :func:`jaxkin.motion.retarget`'s, else by
    identity), as ``jax.jit``'s own cache is: a step whose behaviour depends on state it reads
    when traced (not on its arguments) is not retraced when that state changes."""
    try:
        jitted = _scanned_cache.pop(step, None)
    except TypeError:  # unhashable: no cache
        return jax.jit(_scan_chunk(step))
    if jitted is None:
        jitted = jax.jit(_scan_chunk(step))
    _scanned_cache[step] = jitted  # most recently used last
    while len(_scanned_cache) > SCANNED_CACHE_SIZE:
        _scanned_cache.popitem(last=False)
    return jitted


def _scan_chunk(step: Callable[..., Any]) -> Callable[..., Any]:
    """``run(carry, valid, *xs)``: ``lax.scan`` of ``step`` over the rows of ``xs``; rows at or
    past ``valid`` (padding) keep the carry."""

    def run(carry, valid, *xs):
        def body(state, row):
            c, t = state
            new, ys = step(c, *row)
            keep = t < valid
            c = jax.tree_util.tree_map(lambda a, b: jnp.where(keep, a, b), new, c)
            return (c, t + 1), ys

        (carry, _), ys = jax.lax.scan(body, (carry, jnp.int32(0)), xs)
        return carry, ys

    return run


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
            compiled = _trace(fn, host, chunk, mesh).lower().compile(compiler_options() or None)
            signature = got
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


def _default_chunk_size(fn: Callable[..., Any], host: list[Any], mesh: Mesh) -> int:
    """:func:`chunked_map`'s chunk when none is given: on CPUs about
    :data:`CHUNK_RESULT_BYTES` of results (``fn``'s output per row from ``jax.eval_shape``),
    clipped to [:data:`MIN_AUTO_CHUNK`, :data:`DEFAULT_CHUNK_SIZE`]; elsewhere
    :data:`DEFAULT_CHUNK_SIZE`."""
    if any(d.platform != "cpu" for d in mesh.devices.flat):
        return DEFAULT_CHUNK_SIZE
    rows = [jax.ShapeDtypeStruct(a.shape[1:], a.dtype) for a in host]
    out = jax.eval_shape(fn, *rows)
    row_bytes = sum(
        math.prod(s.shape) * np.dtype(s.dtype).itemsize for s in jax.tree_util.tree_leaves(out)
    )
    per_device = CHUNK_RESULT_BYTES // max(row_bytes, 1)
    return int(min(max(per_device, MIN_AUTO_CHUNK), DEFAULT_CHUNK_SIZE)) * mesh.size


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
    Inputs and outputs are split along rows over ``mesh``.

    The ``jax.jit`` object is kept per ``(fn, mesh)`` (:func:`_mapped`), so that a later call
    with the same function, shapes and dtypes reuses JAX's caches of the trace, the lowering
    and the executable (as ``jax.jit(fn)`` called twice does), instead of tracing and compiling
    again."""
    sharding = NamedSharding(mesh, PartitionSpec("rows"))
    specs = [jax.ShapeDtypeStruct((chunk, *a.shape[1:]), a.dtype, sharding=sharding) for a in host]
    return _mapped(fn, mesh).trace(*specs)


MAPPED_CACHE_SIZE = 8
"""How many ``jax.jit(jax.vmap(fn))`` objects :func:`_mapped` keeps (least recently used dropped
first); each holds its function (and what that closes over) and JAX's compiled executables for
the shapes it was called with."""

_mapped_cache: collections.OrderedDict = collections.OrderedDict()


def _mapped(fn: Callable[..., Any], mesh: Mesh) -> Any:
    """``jax.jit(jax.vmap(fn))`` with outputs split along rows over ``mesh``: one object per
    ``(fn, mesh)`` (at most :data:`MAPPED_CACHE_SIZE`), a new one for an unhashable ``fn``.
    Keyed by the function object itself, as ``jax.jit``'s own cache is: a function whose
    behaviour depends on state it reads when traced (not on its arguments) is not retraced when
    that state changes, exactly as under ``jax.jit``."""
    sharding = NamedSharding(mesh, PartitionSpec("rows"))
    try:
        key = (fn, mesh)
        jitted = _mapped_cache.pop(key, None)
    except TypeError:  # unhashable: no cache
        return jax.jit(jax.vmap(fn), out_shardings=sharding)
    if jitted is None:
        jitted = jax.jit(jax.vmap(fn), out_shardings=sharding)
    _mapped_cache[key] = jitted  # most recently used last
    while len(_mapped_cache) > MAPPED_CACHE_SIZE:
        _mapped_cache.popitem(last=False)
    return jitted


_into_cache: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
"""Per :func:`_mapped` object (dropped with it), :func:`_compile_into`'s programs by input
shapes."""

SPARE_BYTES = 2 * CHUNK_RESULT_BYTES
"""On CPUs, a program's drained result buffers of at most this many bytes (per set) are kept
between :func:`chunked_map` calls (two sets), so the next call's first chunks write over them
instead of over newly allocated, zeroed memory."""


class _Into:
    """A compiled chunk program that writes its results over donated buffers
    (:func:`_compile_into`), with the pool of drained result buffers its chunks write over."""

    def __init__(self, compiled: Any, reuse: Any, keep: bool) -> None:
        self.compiled = compiled
        self.reuse = reuse  # specs of the buffers (the outputs' shapes, dtypes and sharding)
        self.keep = keep  # whether the pool outlives a call
        self.spare: list[Any] = []

    def buffers(self) -> Any:
        """A drained chunk's results to write over, or new (zeroed) buffers."""
        try:
            return self.spare.pop()
        except IndexError:
            return _blank(self.reuse)

    def recycle(self, results: Any) -> None:
        """Keep a drained chunk's device results for a later chunk (at most two sets)."""
        if len(self.spare) < 2:
            self.spare.append(results)

    def settle(self) -> None:
        """At the end of a call: release the pool unless it is kept between calls."""
        if not self.keep:
            self.spare.clear()


def _compile_into(fn: Callable[..., Any], mesh: Mesh, traced: jax.stages.Traced) -> _Into:
    """An executable computing what ``traced`` (from :func:`_trace`) computes, called as
    ``compiled(buffers, *chunk arrays)``, that writes its results over ``buffers`` (donated:
    arrays shaped as the outputs), with its pool of buffers (:class:`_Into`).

    Why: every call of a compiled program returns its results in newly allocated memory, and
    the operating system hands out new memory a 4 KiB page at a time, the first write to each
    page a fault that costs about as much as computing a few Jacobian entries. Chunk after
    chunk, :func:`chunked_map` passes a drained chunk's device results back as the buffers to
    write over, so results land in memory already paged in; on CPUs, when a set is small
    (:data:`SPARE_BYTES`), the last two are kept for the next call. JAX donates a buffer only
    while nothing else refers to it: a numpy view that a sink kept makes it allocate afresh,
    never overwrite the view.

    The program replays ``traced``'s jaxpr (no second trace of ``fn``; calling the ``jax.jit``
    object instead would nest it, which XLA compiles into a different, slower program). Kept
    per :func:`_mapped` object and input shapes, so a later call compiles nothing."""
    sharding = NamedSharding(mesh, PartitionSpec("rows"))
    inputs = traced.args_info[0]  # chunked_map's arrays: positional, one leaf each
    key = tuple((tuple(a.shape), str(a.dtype)) for a in inputs)
    jitted = _mapped(fn, mesh)
    try:
        cached = _into_cache.setdefault(jitted, {})
    except TypeError:  # not weakly referable: no cache
        cached = {}
    if key not in cached:
        body = jax_core.jaxpr_as_fun(traced.jaxpr)
        outs = jax.tree_util.tree_structure(traced.out_info)
        reuse = jax.tree_util.tree_map(
            lambda s: jax.ShapeDtypeStruct(s.shape, s.dtype, sharding=sharding), traced.out_info
        )
        into = jax.jit(
            lambda buffers, *xs: jax.tree_util.tree_unflatten(outs, body(*xs)),
            donate_argnums=0,
            keep_unused=True,  # the buffers are never read: keep (and donate) them anyway
            out_shardings=sharding,
        )
        specs = [jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=sharding) for a in inputs]
        compiled = into.trace(reuse, *specs).lower().compile(compiler_options() or None)
        nbytes = sum(
            math.prod(s.shape) * np.dtype(s.dtype).itemsize
            for s in jax.tree_util.tree_leaves(reuse)
        )
        on_cpu = all(d.platform == "cpu" for d in mesh.devices.flat)
        cached[key] = _Into(compiled, reuse, keep=on_cpu and nbytes <= SPARE_BYTES)
    return cached[key]


def _blank(reuse: Any) -> Any:
    """Device buffers for :func:`_compile_into`'s ``reuse`` specs (zeros; overwritten)."""
    return jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype, device=s.sharding), reuse)


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


def _pipelined(
    n: int,
    chunk: int,
    n_chunks: int,
    launch: Callable[[int], Any],
    put,
    bar,
    recycle: Callable[[Any], None] | None = None,
) -> None:
    """Run ``launch(start)`` for each of the ``n_chunks`` chunks of ``n`` rows (``chunk`` rows
    each, the last padded) and hand each finished chunk to ``put``, one chunk behind: the next
    chunk is dispatched before the previous one's results are copied to the host, so the device
    never waits for the writer. Once drained, a chunk's device results go to ``recycle`` (if
    given; :func:`chunked_map` writes later chunks over them). Shared by :func:`chunked_map`
    and :func:`chunked_scan`."""
    pending = None  # (start, stop, device results) of the chunk in flight
    for k in range(n_chunks):
        start = k * chunk
        running = (start, min(start + chunk, n), launch(start))
        if pending is not None:
            _drain(put, *pending)
            bar.update(pending[1] - pending[0])
            if recycle is not None:
                recycle(pending[2])
        pending = running
    if pending is not None:
        _drain(put, *pending)
        bar.update(pending[1] - pending[0])
        if recycle is not None:
            recycle(pending[2])


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
