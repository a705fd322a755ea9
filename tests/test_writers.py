"""jaxkin.io.ResultWriter and chunked_map(out=path): files appear whole or not at all.

Temporaries live next to the final name, as ``.<name>.<random>.tmp`` (a file for npz and csv, a
directory for directory outputs). SIGTERM, Ctrl-C, exceptions and a full disk remove them; only
SIGKILL (or a crash) can leave one behind, never a partial file under the final name.
"""

import collections
import errno
import os
import re
import signal
import stat
import subprocess
import sys
import textwrap
import time
import zipfile

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxkin as jk
from jaxkin.batch import chunked_map
from jaxkin.io import ResultWriter


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
    before_int = signal.getsignal(signal.SIGINT)
    with ResultWriter(tmp_path / "r.npz", {"x": ((1,), "float64")}, 0) as w:
        assert signal.getsignal(signal.SIGTERM) not in (before, signal.SIG_DFL)
        assert signal.getsignal(signal.SIGINT) not in (before_int, signal.SIG_DFL)
        assert signal.getsignal(signal.SIGXFSZ) == signal.SIG_IGN
        w.commit()
    assert signal.getsignal(signal.SIGTERM) == before
    assert signal.getsignal(signal.SIGINT) == before_int


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


# ---------------------------------------------------------------------- careless calls
@pytest.mark.parametrize(
    ("nbytes", "text"),
    [
        (0, "0 bytes"),
        (999, "999 bytes"),
        (1000, "1.0 kB"),
        (51_200, "51.2 kB"),
        (999_949, "999.9 kB"),
        (999_950, "1.0 MB"),
        (3_400_000, "3.4 MB"),
        (12 * 10**9, "12.0 GB"),
        (2_500 * 10**9, "2.5 TB"),
        (1_234_000 * 10**9, "1,234.0 TB"),
    ],
)
def test_disk_space_refusal_uses_units_that_fit(tmp_path, monkeypatch, nbytes, text):
    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(jk.io.shutil, "disk_usage", lambda path: usage(10**15, 0, nbytes))
    n = max(nbytes, 1000) // 4  # 8 bytes a row: twice the space there is
    match = rf"needs about .+ and {re.escape(str(tmp_path))} has {text} free;"
    with pytest.raises(jk.JaxkinError, match=match):
        ResultWriter(tmp_path / "r.npz", {"x": ((), "float64")}, n)
    assert os.listdir(tmp_path) == []


def test_disk_space_refusal_names_small_sizes_in_bytes_and_kb(tmp_path, monkeypatch):
    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(jk.io.shutil, "disk_usage", lambda path: usage(10**6, 0, 1000))
    with pytest.raises(jk.JaxkinError) as e:
        ResultWriter(tmp_path / "r.npz", {"x": ((), "float64")}, 1000)
    assert "0.0 GB" not in str(e.value)
    assert re.search(r"needs about 8\.\d kB and .* has 1\.0 kB free", str(e.value)), e.value


def refuse_temporaries(monkeypatch, error):
    """os.open and os.mkdir fail with ``error`` for jaxkin's temporaries (as on a read-only
    directory, which permission bits cannot make for root); everything else goes through."""
    real_open, real_mkdir = os.open, os.mkdir

    def guard(real):
        def call(path, *args, **kwargs):
            if str(path).endswith(".tmp"):
                raise OSError(error, os.strerror(error), path)
            return real(path, *args, **kwargs)

        return call

    monkeypatch.setattr(os, "open", guard(real_open))
    monkeypatch.setattr(os, "mkdir", guard(real_mkdir))


@pytest.mark.parametrize("error", [errno.EACCES, errno.EROFS])
@pytest.mark.parametrize("name", ["r.npz", "r.csv", "rdir"])
def test_unwritable_directory_is_refused_before_computing(tmp_path, monkeypatch, error, name):
    """Creating the temporary is the true test (root passes os.access on a read-only mount...):
    it fails before fn runs, with a jaxkin error naming the directory, not an AttributeError."""
    compiled = []
    real_compile = jax.stages.Lowered.compile
    monkeypatch.setattr(
        jax.stages.Lowered, "compile", lambda *a: compiled.append(1) or real_compile(*a)
    )
    refuse_temporaries(monkeypatch, error)
    before = (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM))
    match = rf"directory {re.escape(str(tmp_path))} is not writable \(.+\); choose"
    with pytest.raises(jk.JaxkinError, match=match):
        chunked_map(lambda x: x * 2, rows(4), out=tmp_path / name)
    assert compiled == [] and os.listdir(tmp_path) == []
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before


def test_directory_without_write_permission_is_refused_up_front(tmp_path, monkeypatch):
    """os.access, checked when the writer is made (a non-root user's chmod 555; simulated for
    root, whom permission bits do not stop)."""
    real_access = os.access
    monkeypatch.setattr(
        os, "access", lambda p, mode: False if str(p) == str(tmp_path) else real_access(p, mode)
    )
    with pytest.raises(jk.JaxkinError, match=f"directory {re.escape(str(tmp_path))} is not writ"):
        ResultWriter(tmp_path / "r.npz", {"x": ((), "float64")}, 3)
    (tmp_path / "file").write_text("")
    with pytest.raises(jk.JaxkinError, match="is not a directory"):
        ResultWriter(tmp_path / "file" / "r.npz", {"x": ((), "float64")}, 3)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a chmod 555 directory")
def test_read_only_directory_is_refused(tmp_path):
    (tmp_path / "ro").mkdir()
    os.chmod(tmp_path / "ro", 0o555)
    try:
        with pytest.raises(jk.JaxkinError, match="is not writable"):
            chunked_map(lambda x: x * 2, rows(4), out=tmp_path / "ro" / "r.npz")
        assert os.listdir(tmp_path / "ro") == []
    finally:
        os.chmod(tmp_path / "ro", 0o755)


# A Ctrl-C that Python delivers inside a garbage-collector callback (JAX installs one) is
# printed as "Exception ignored in ..." and dropped; a run used to go on to the end and write
# its file. The child blocks in such a callback once its temporary exists, so that the SIGINT
# lands there every time.
SIGINT_CHILD = textwrap.dedent(
    """
    import gc, os, sys, time
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from jaxkin.batch import chunked_map

    out = sys.argv[1]
    waited = []

    def wait_for_sigint(phase, info):
        folder = os.path.dirname(out)
        if waited or not any(p.endswith(".tmp") for p in os.listdir(folder)):
            return
        waited.append(1)
        open(os.path.join(folder, "ready"), "w").close()
        time.sleep(60)  # the SIGINT's KeyboardInterrupt is raised here, and dropped by gc

    x = np.ones((200_000, 4))
    gc.callbacks.append(wait_for_sigint)
    chunked_map(lambda r: {"a": r * 2.0}, x, chunk_size=256, out=out)
    print("finished", flush=True)
    """
)


def test_sigint_stops_the_run_even_where_python_drops_it(tmp_path):
    script = tmp_path / "child.py"
    script.write_text(SIGINT_CHILD)
    (tmp_path / "out").mkdir()
    out = tmp_path / "out" / "r.npz"
    proc = subprocess.Popen(
        [sys.executable, str(script), str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not (out.parent / "ready").exists():
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.01)
        proc.send_signal(signal.SIGINT)
        sent = time.monotonic()
        stdout, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert time.monotonic() - sent < 10  # one chunk, not the rest of the run
    assert "finished" not in stdout
    assert proc.returncode == -signal.SIGINT, err  # an uncaught KeyboardInterrupt
    assert err.rstrip().endswith("KeyboardInterrupt"), err
    assert not out.exists() and temporaries(out.parent) == []


def test_command_line_refuses_an_unwritable_directory_in_one_line(tmp_path, monkeypatch, capsys):
    from jaxkin import cli

    monkeypatch.chdir(tmp_path)
    refuse_temporaries(monkeypatch, errno.EROFS)
    code = cli.main(["velocities", "two_link_planar", "--n", "10", "--output", "v.csv"])
    _, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert f"directory {tmp_path} is not writable (Read-only file system)" in err
    assert os.listdir(tmp_path) == []
