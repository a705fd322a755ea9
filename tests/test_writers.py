"""jaxkin.batch.ResultWriter and chunked_map(out=path): files appear whole or not at all.

Temporaries live next to the final name, as ``.<name>.<random>.tmp`` (a file for npz and csv, a
directory for directory outputs). SIGTERM, Ctrl-C, exceptions and a full disk remove them; only
SIGKILL (or a crash) can leave one behind, never a partial file under the final name.
"""

import os
import signal
import stat
import subprocess
import sys
import textwrap
import time
import zipfile

import jax.numpy as jnp
import numpy as np
import pytest

import jaxkin as jk
from jaxkin.batch import ResultWriter, chunked_map


def row_fn(x):
    return {"outer": jnp.outer(x, x), "sum": jnp.sum(x)}


def rows(n, seed=0):
    return np.random.default_rng(seed).uniform(-1, 1, (n, 3))


def temporaries(directory):
    return [p for p in os.listdir(directory) if p.startswith(".") and p.endswith(".tmp")]


@pytest.mark.parametrize("name", ["r.npz", "r.csv", "rdir"])
def test_formats_round_trip(tmp_path, name):
    x = rows(1001)
    path = chunked_map(row_fn, x, chunk_size=128, out=tmp_path / name)
    assert path == str(tmp_path / name) and temporaries(tmp_path) == []
    if name.endswith(".csv"):
        lines = (tmp_path / name).read_text().splitlines()
        assert lines[0].split(",") == [f"outer_{i}" for i in range(1, 10)] + ["sum"]
        table = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
        np.testing.assert_array_equal(table[:, :9], (x[:, :, None] * x[:, None, :]).reshape(-1, 9))
        return
    if name.endswith(".npz"):
        with zipfile.ZipFile(path) as z:
            assert z.testzip() is None  # every CRC patched in
        d = np.load(path)
    else:
        d = {k: np.load(os.path.join(path, f"{k}.npy"), mmap_mode="r") for k in ("outer", "sum")}
    np.testing.assert_array_equal(d["outer"], x[:, :, None] * x[:, None, :])
    np.testing.assert_allclose(d["sum"], x.sum(axis=1), rtol=1e-15)


def test_writer_meta_csv_columns_and_checks(tmp_path):
    fields = {"q": ((2,), "float64"), "m": ((), "float64")}
    with ResultWriter(tmp_path / "a.npz", fields, 3, meta={"robot": "arm", "k": 7}) as w:
        w.append({"q": np.ones((2, 2)), "m": np.zeros(2)})
        with pytest.raises(jk.ShapeError, match="do not fit"):
            w.append({"q": np.ones((2, 3)), "m": np.zeros(2)})
        with pytest.raises(jk.JaxkinError, match="2 of 3 rows"):
            w.commit()
        w.append({"q": np.full((1, 2), 2.0), "m": np.ones(1)})
        w.commit()
    d = np.load(tmp_path / "a.npz")
    assert str(d["robot"]) == "arm" and int(d["k"]) == 7
    np.testing.assert_array_equal(d["q"], [[1, 1], [1, 1], [2, 2]])
    columns = {"m": ["margin"], "q": ["q_a", "q_b"]}
    with ResultWriter(tmp_path / "b.csv", fields, 1, columns=columns, comments=["hello"]) as w:
        w.append({"q": np.array([[0.5, 0.25]]), "m": np.array([3.0])})
        w.commit()
    assert (tmp_path / "b.csv").read_text() == "# hello\nmargin,q_a,q_b\n3,0.5,0.25\n"


def test_format_and_path_mistakes(tmp_path):
    fields = {"q": ((2,), "float64")}
    with pytest.raises(jk.JaxkinError, match="contradicts"):
        ResultWriter(tmp_path / "x.npz", fields, 1, format="csv")
    with pytest.raises(jk.JaxkinError, match="only csv goes to standard output"):
        ResultWriter("-", fields, 1, format="npz")
    with pytest.raises(jk.JaxkinError, match="does not exist"):
        ResultWriter(tmp_path / "no" / "x.npz", fields, 1)
    with pytest.raises(jk.JaxkinError, match="two arrays would be written as 'q'"):
        ResultWriter(tmp_path / "x.npz", fields, 1, meta={"q": 1})
    with pytest.raises(jk.JaxkinError, match="would both be written as 'J_v'"):
        chunked_map(lambda x: {"J v": x, "J_v": 2 * x}, rows(4), out=tmp_path / "c.npz")
    assert os.listdir(tmp_path) == []


def test_permissions_follow_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        f = chunked_map(row_fn, rows(5), out=tmp_path / "f.npz")
        d = chunked_map(row_fn, rows(5), out=tmp_path / "d")
    finally:
        os.umask(old)
    assert stat.S_IMODE(os.stat(f).st_mode) == 0o640  # not mkstemp's 0o600
    assert stat.S_IMODE(os.stat(d).st_mode) == 0o750  # not mkdtemp's 0o700
    assert stat.S_IMODE(os.stat(os.path.join(d, "outer.npy")).st_mode) == 0o640


def test_exception_and_interrupt_remove_the_temporary(tmp_path):
    (tmp_path / "r.npz").write_bytes(b"previous")
    seen = []

    def fn(x):
        return x * 2

    class Sink:
        def append(self, chunk):
            seen.append(temporaries(tmp_path))
            raise KeyboardInterrupt

    fields = {"x": ((3,), "float64")}
    with pytest.raises(KeyboardInterrupt), ResultWriter(tmp_path / "r.npz", fields, 4):
        chunked_map(fn, rows(4), out=Sink())
    assert len(seen[0]) == 1 and temporaries(tmp_path) == []  # Ctrl-C mid-write: removed
    with pytest.raises(RuntimeError), ResultWriter(tmp_path / "r.npz", fields, 4) as w:
        assert len(temporaries(tmp_path)) == 1 and temporaries(tmp_path)[0].startswith(".r.npz.")
        w.append({"x": rows(2)})
        raise RuntimeError("boom")
    assert temporaries(tmp_path) == [] and (tmp_path / "r.npz").read_bytes() == b"previous"


def test_sigterm_handler_is_restored(tmp_path):
    before = signal.getsignal(signal.SIGTERM)
    with ResultWriter(tmp_path / "r.npz", {"x": ((1,), "float64")}, 0) as w:
        assert signal.getsignal(signal.SIGTERM) not in (before, signal.SIG_DFL)
        assert signal.getsignal(signal.SIGXFSZ) == signal.SIG_IGN
        w.commit()
    assert signal.getsignal(signal.SIGTERM) == before


# ---------------------------------------------------------------------- killed writers
CHILD = textwrap.dedent(
    """
    import resource, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from jaxkin.batch import chunked_map

    out, n, limit = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    if limit:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    x = np.ones((n, 8))
    # slow enough to be killed mid-write: many small chunks, each written as it finishes
    chunked_map(lambda r: {"a": r * 2.0, "b": r.sum()}, x, chunk_size=256, out=out)
    print("done")
    """
)


def start_child(tmp_path, name, n, limit=0):
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    out = tmp_path / "out" / name
    out.parent.mkdir()
    cmd = [sys.executable, str(script), str(out), str(n), str(limit)]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True), out


def wait_for_temporary(proc, directory, timeout=120):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if temporaries(directory):
            return True
        if proc.poll() is not None:
            return False
        time.sleep(0.005)
    return False


def assert_complete_or_absent(out, n):
    if out.exists():  # the write finished before the signal: then it is whole
        d = np.load(out) if out.suffix == ".npz" else None
        assert d is None or d["a"].shape == (n, 8)


@pytest.mark.parametrize("name", ["r.npz", "rdir"])
def test_sigterm_mid_write_leaves_nothing(tmp_path, name):
    n = 400_000
    proc, out = start_child(tmp_path, name, n)
    try:
        assert wait_for_temporary(proc, out.parent), proc.communicate()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert temporaries(out.parent) == [] and not out.exists()


def test_sigkill_mid_write_leaves_no_partial_file(tmp_path):
    n = 400_000
    proc, out = start_child(tmp_path, "r.npz", n)
    try:
        assert wait_for_temporary(proc, out.parent), proc.communicate()
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == -signal.SIGKILL
    assert_complete_or_absent(out, n)
    left = temporaries(out.parent)  # SIGKILL cannot be caught: the temporary may remain
    assert all(p.startswith(".r.npz.") for p in left)


@pytest.mark.parametrize("name", ["r.npz", "r.csv", "rdir"])
def test_file_size_limit_mid_write_leaves_nothing(tmp_path, name):
    """A full disk, simulated by RLIMIT_FSIZE (SIGXFSZ is ignored while writing, so the write
    fails with EFBIG instead of killing the process)."""
    proc, out = start_child(tmp_path, name, 20_000, limit=300_000)  # about 1.4 MB wanted
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 1, err
    assert "File too large" in err and str(out) in err and "Traceback" in err
    assert temporaries(out.parent) == [] and not out.exists()
