"""jaxkin.batch: chunked_map against one plain vmap, compile-once, validation, out=, progress."""

import io
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxkin as jk
from jaxkin.batch import MapStats, ProgressBar, chunked_map, stream_map


def row_fn(x, y):
    """Per-row: x (3,), y () -> a pytree with a (3, 3), a scalar and a (2,) leaf."""
    return {
        "outer": jnp.outer(x, x) * y,
        "pair": (jnp.log(y) + jnp.sum(jnp.sqrt(x)), jnp.stack([x[0] * y, x[2] - y])),
    }


def inputs(n, dtype=np.float64, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.1, 2.0, (n, 3)).astype(dtype), rng.uniform(0.5, 1.5, n).astype(dtype)


def reference(x, y):
    """row_fn over all rows, in numpy."""
    return {
        "outer": x[:, :, None] * x[:, None, :] * y[:, None, None],
        "pair": (np.log(y) + np.sum(np.sqrt(x), axis=1), np.stack([x[:, 0] * y, x[:, 2] - y], 1)),
    }


def assert_tree_equal(got, want, **tol):
    assert jax.tree_util.tree_structure(got) == jax.tree_util.tree_structure(want)
    for g, w in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want), strict=True):
        assert isinstance(g, np.ndarray)
        assert g.shape == w.shape and g.dtype == w.dtype
        np.testing.assert_allclose(g, np.asarray(w), **tol)


def test_matches_plain_vmap():
    x, y = inputs(13)
    got = chunked_map(row_fn, x, y, chunk_size=4)
    assert_tree_equal(got, jax.vmap(row_fn)(x, y), rtol=1e-14, atol=0)


@pytest.mark.parametrize("n", [1, 3, 4, 5, 12, 30])
def test_matches_whole_batch(n):
    # N = 1, N < chunk, N = chunk, N not a multiple of chunk, N a multiple of chunk.
    x, y = inputs(n)
    got = chunked_map(row_fn, x, y, chunk_size=4)
    assert_tree_equal(got, reference(x, y), rtol=1e-14, atol=0)


def test_float32_and_jax_inputs():
    x, y = inputs(9, np.float32)
    got = chunked_map(row_fn, jnp.asarray(x), y, chunk_size=4)
    assert got["outer"].dtype == np.float32
    assert_tree_equal(got, reference(x, y), rtol=1e-6)


def test_compiles_once_across_chunks_and_padding():
    traces = []

    def fn(x, y):
        traces.append(x.shape)
        return row_fn(x, y)

    x, y = inputs(10)
    _, stats = chunked_map(fn, x, y, chunk_size=3, return_stats=True)
    assert len(traces) == 1  # one trace for 4 chunks, the last one padded
    assert stats == MapStats(
        n=10,
        chunk_size=3,
        n_chunks=4,
        padding=2,
        compile_seconds=stats.compile_seconds,
        run_seconds=stats.run_seconds,
    )
    assert stats.compile_seconds > 0 and stats.rate > 0


@pytest.mark.parametrize(
    ("n", "chunk_size", "expected"),
    [(5, 65536, (5, 1, 0)), (12, 4, (4, 3, 0)), (13, 4, (4, 4, 3)), (9, 8, (5, 2, 1))],
)
def test_chunking_has_minimal_padding(n, chunk_size, expected):
    x, y = inputs(n)
    _, stats = chunked_map(row_fn, x, y, chunk_size=chunk_size, return_stats=True)
    assert (stats.chunk_size, stats.n_chunks, stats.padding) == expected


def test_default_chunk_holds_about_chunk_result_bytes_of_results():
    # Each row gives 4 KiB of float32 results: 8 MiB / 4 KiB = 2,048 rows at most per chunk,
    # so 5,000 rows run as 3 equal chunks (was one chunk of up to 65,536 rows).
    from jaxkin import batch

    def wide(x):
        return jnp.full((1024,), x[0], jnp.float32)

    x = np.arange(5000, dtype=np.float32)[:, None]
    got, stats = chunked_map(wide, x, return_stats=True)
    assert batch.CHUNK_RESULT_BYTES // (1024 * 4) == 2048
    assert (stats.chunk_size, stats.n_chunks, stats.padding) == (1667, 3, 1)
    np.testing.assert_array_equal(got[:, 0], x[:, 0])
    np.testing.assert_array_equal(got[:, -1], x[:, 0])
    # A row of a few bytes is not cut finer than 65,536 rows (nor a huge row below 1,024).
    assert batch._default_chunk_size(lambda r: r, [x], batch._mesh(None)) == 65536
    huge = lambda r: jnp.zeros((1 << 20,), jnp.float32)  # noqa: E731
    assert batch._default_chunk_size(huge, [x], batch._mesh(None)) == batch.MIN_AUTO_CHUNK


def test_chunks_are_written_over_drained_results():
    # The compiled chunk program aliases each output to a donated input buffer: chunk k + 2
    # writes over chunk k's drained device results instead of newly allocated memory.
    from jaxkin import batch

    x, y = inputs(12)
    host, _ = batch._check_inputs((x, y))
    mesh = batch._mesh(None)
    traced = batch._trace(row_fn, host, 4, mesh)
    into = batch._compile_into(row_fn, mesh, traced)
    assert jax.tree_util.tree_structure(into.reuse) == jax.tree_util.tree_structure(traced.out_info)
    assert "input_output_alias" in into.compiled.as_text()
    buffers = batch._blank(into.reuse)
    first = into.compiled(buffers, *batch._feed(host, 0, 4, 12, mesh))
    assert all(b.is_deleted() for b in jax.tree_util.tree_leaves(buffers))  # donated
    assert_tree_equal(
        jax.tree_util.tree_map(np.asarray, first),
        reference(x[:4], y[:4]),
        rtol=1e-14,
        atol=0,
    )


def test_humanoid_jacobians_chunked_equal_one_jit_vmap_call():
    # The fast path for N results in an array (default chunks, each written over an earlier
    # chunk's buffers) against one jax.jit(jax.vmap(...)) of the same function: a floating-base
    # robot, four frames in one call, three chunks (the third reuses the first one's buffers).
    robot = jk.robots.load("erd/solo12", floating_base=True, dtype=np.float64)
    feet = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]

    def fn(q):
        return jk.geometric_jacobian(robot, q, frame=feet)

    q = np.asarray(jk.sample_configurations(robot, 5000, jax.random.key(3)))
    got, stats = chunked_map(fn, q, return_stats=True)
    assert stats.n_chunks == 3  # 8 MiB / (4 * 6 * 18 * 8 bytes) = 2,427 rows at most
    want = np.asarray(jax.jit(jax.vmap(fn))(q))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_small_result_buffers_are_kept_for_the_next_call_and_large_ones_released(monkeypatch):
    # On a CPU the last two drained buffer sets stay with the program when a set is small, so
    # the next call's first chunks write over them (not over new zeroed memory); large sets go.
    from jaxkin import batch

    def small(x):
        return x * 2.0

    def large(x):
        return x * 3.0

    x = np.arange(40.0)[:, None]
    mesh = batch._mesh(None)
    host, _ = batch._check_inputs((x,))
    for fn, limit, kept in ((small, batch.SPARE_BYTES, 2), (large, 79, 0)):  # a set: 80 bytes
        monkeypatch.setattr(batch, "SPARE_BYTES", limit)
        np.testing.assert_array_equal(chunked_map(fn, x, chunk_size=10), np.asarray(fn(x)))
        into = batch._compile_into(fn, mesh, batch._trace(fn, host, 10, mesh))  # cached
        assert len(into.spare) == kept
        pool = list(into.spare)
        np.testing.assert_array_equal(chunked_map(fn, x, chunk_size=10), np.asarray(fn(x)))
        assert all(leaf.is_deleted() for tree in pool for leaf in jax.tree_util.tree_leaves(tree))


def test_a_sink_that_keeps_its_chunks_keeps_them_intact():
    # A sink receives numpy views of the device results; JAX does not donate a buffer that a
    # view still refers to, so later chunks never overwrite what the sink kept.
    class Keep:
        def __init__(self):
            self.chunks = []

        def append(self, tree):
            self.chunks.append(tree)

    x, y = inputs(30)
    sink = chunked_map(row_fn, x, y, chunk_size=4, out=Keep())
    got = jax.tree_util.tree_map(lambda *parts: np.concatenate(parts), *sink.chunks)
    assert_tree_equal(got, reference(x, y), rtol=1e-14, atol=0)


def test_padding_rows_are_valid_inputs():
    # The last chunk is padded by repeating the last row, so fn never sees zeros (log(0) = -inf
    # would be harmless here, but a user's fn might raise or poison shared state).
    seen = []

    def fn(x):
        jax.debug.callback(lambda v: seen.append(np.asarray(v)), x)
        return jnp.log(x)

    x = np.arange(1.0, 8.0)  # 7 rows, chunk 4: one padding row
    out = chunked_map(fn, x, chunk_size=4)
    np.testing.assert_allclose(out, np.log(x))
    assert min(float(np.min(s)) for s in seen) >= 1.0


def test_empty_batch():
    x, y = inputs(0)
    got = chunked_map(row_fn, x, y, chunk_size=4)
    assert got["outer"].shape == (0, 3, 3)
    assert got["pair"][1].shape == (0, 2)


def test_out_memmap(tmp_path):
    n = 11
    x, y = inputs(n)
    out = {
        "outer": np.lib.format.open_memmap(tmp_path / "outer.npy", "w+", np.float64, (n, 3, 3)),
        "pair": (np.zeros(n), np.zeros((n, 2))),
    }
    got = chunked_map(row_fn, x, y, chunk_size=4, out=out)
    assert got is out
    out["outer"].flush()
    want = reference(x, y)
    np.testing.assert_allclose(np.load(tmp_path / "outer.npy"), want["outer"], rtol=1e-14)
    np.testing.assert_allclose(out["pair"][1], want["pair"][1], rtol=1e-14)


# ---------------------------------------------------------------------- bad input
def test_unequal_lengths():
    x, _ = inputs(5)
    with pytest.raises(jk.ShapeError, match=r"same leading length.*\(5, 3\).*\(4,\)"):
        chunked_map(row_fn, x, np.ones(4))


def test_no_arrays_and_scalars():
    with pytest.raises(jk.ShapeError, match="at least one input"):
        chunked_map(row_fn)
    with pytest.raises(jk.ShapeError, match="leading batch axis"):
        chunked_map(row_fn, np.ones((3, 3)), 1.0)


@pytest.mark.parametrize("bad", [0, -4, 2.5, True, "8"])
def test_bad_chunk_size(bad):
    x, y = inputs(3)
    with pytest.raises(jk.JaxkinError, match="chunk_size must be"):
        chunked_map(row_fn, x, y, chunk_size=bad)


def test_fn_not_callable():
    with pytest.raises(jk.JaxkinError, match="fn must be callable"):
        chunked_map(np.ones(3), np.ones(3))


def test_bad_out():
    x, y = inputs(4)
    good_pair = (np.zeros(4), np.zeros((4, 2)))
    with pytest.raises(jk.ShapeError, match="structure of fn's output"):
        chunked_map(row_fn, x, y, out=[np.zeros(4)])
    with pytest.raises(jk.ShapeError, match=r"out\['outer'\].*shape \(4, 3, 3\).*\(4, 3\)"):
        chunked_map(row_fn, x, y, out={"outer": np.zeros((4, 3)), "pair": good_pair})
    with pytest.raises(jk.ShapeError, match="cannot hold"):
        out = {"outer": np.zeros((4, 3, 3), np.int64), "pair": good_pair}
        chunked_map(row_fn, x, y, out=out)
    ro = np.zeros((4, 3, 3))
    ro.flags.writeable = False
    with pytest.raises(jk.ShapeError, match="read-only"):
        chunked_map(row_fn, x, y, out={"outer": ro, "pair": good_pair})


# ---------------------------------------------------------------------- progress bar
class FakeTTY(io.StringIO):
    def isatty(self):
        return True


def test_progress_true_shows_a_tqdm_bar_that_reaches_n(capsys):
    pytest.importorskip("tqdm")
    x, y = inputs(10)
    assert_tree_equal(chunked_map(row_fn, x, y, chunk_size=4, progress=True), reference(x, y))
    err = capsys.readouterr().err  # tqdm writes to stderr, even off a terminal when asked
    assert "10/10" in err and "100%" in err and err.endswith("\n")


def test_progress_updates_a_tqdm_instance_and_leaves_it_open():
    tqdm = pytest.importorskip("tqdm")
    stream = io.StringIO()
    x, y = inputs(10)
    with tqdm.tqdm(total=10, file=stream, disable=False, mininterval=0) as bar:
        chunked_map(row_fn, x, y, chunk_size=4, progress=bar)
        assert bar.n == 10 and not bar.disable  # counted, not closed
    assert "10/10" in stream.getvalue()


def test_progress_bar_wraps_tqdm():
    pytest.importorskip("tqdm")
    x, y = inputs(10)
    for stream, force in ((FakeTTY(), False), (io.StringIO(), True)):
        bar = ProgressBar(10, "work", unit="cfg", file=stream, force=force, min_interval=0)
        chunked_map(row_fn, x, y, chunk_size=4, progress=bar)
        text = stream.getvalue()
        assert bar.done == 10 and "work" in text and "10/10" in text and "cfg/s" in text
        assert "compiling" in text and text.endswith("\n")  # the compile note, then closed
    for bar in (
        ProgressBar(10, file=io.StringIO()),  # not a terminal, not forced
        ProgressBar(10, file=FakeTTY(), enabled=False),
    ):
        bar.update(10)
        bar.close()
        assert not bar.active and bar.file.getvalue() == ""


def test_progress_without_tqdm_shows_nothing_and_raises_nothing(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)  # import tqdm.auto raises ImportError
    x, y = inputs(10)
    assert_tree_equal(chunked_map(row_fn, x, y, chunk_size=4, progress=True), reference(x, y))
    bar = ProgressBar(10, force=True, file=FakeTTY())
    with bar:
        bar.update(10)
    assert not bar.active and bar.done == 10 and bar.file.getvalue() == ""
    assert capsys.readouterr().err == ""


def test_progress_refuses_what_is_not_a_bar():
    x, y = inputs(3)
    with pytest.raises(jk.JaxkinError, match="update"):
        chunked_map(row_fn, x, y, progress="yes")


# ---------------------------------------------------------------------- streams and sources
def test_stream_map_refuses_a_batch_of_another_dtype_or_width():
    x, _ = inputs(10)
    fn = lambda r: r * 2  # noqa: E731
    parts = list(stream_map(fn, [x[:3], x[3:4], x[4:10]], chunk_size=4))
    np.testing.assert_array_equal(np.concatenate(parts), 2 * x)
    with pytest.raises(jk.ShapeError, match=r"batch 1 .*\('float64', \(2,\)\).*first batch"):
        list(stream_map(fn, [x[:3], x[3:5, :2]], chunk_size=4))
    with pytest.raises(jk.ShapeError, match=r"batch 2 .*int64"):
        list(stream_map(fn, [x[:3], x[3:5], np.ones((2, 3), np.int64)], chunk_size=4))


class RowSource:
    """An input read slice by slice (as an h5py dataset), recording the slices asked for."""

    def __init__(self, a):
        self.a, self.shape, self.dtype, self.reads = a, a.shape, a.dtype, []

    def __getitem__(self, rows):
        self.reads.append((rows.start, rows.stop))
        return self.a[rows]


def test_row_sources_are_read_chunk_by_chunk():
    x, y = inputs(13)
    source = RowSource(x)
    assert_tree_equal(chunked_map(row_fn, source, y, chunk_size=4), reference(x, y), rtol=1e-14)
    assert source.reads == [(0, 4), (4, 8), (8, 12), (12, 13)]


@pytest.mark.parametrize("bad", [0, -4, 2.5, True, "abc", None])
def test_stream_map_bad_chunk_size_is_refused_when_called(bad):
    """The check chunked_map makes, named for stream_map, before any batch is read (a generator
    would only check on the first next())."""
    read = []

    def batches():
        read.append(1)
        yield np.ones((2, 3))

    with pytest.raises(jk.JaxkinError, match=r"stream_map: chunk_size must be .*default is"):
        stream_map(lambda r: r * 2, batches(), chunk_size=bad)
    assert read == []
