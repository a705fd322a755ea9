"""jk.compilation: the persistent cache is switched on only when asked, and a second process loads
what the first compiled (counted by JAX's own cache-hit log, not timed)."""

from __future__ import annotations

import os
import re
import stat
import subprocess
import sys
import textwrap

import jax
import pytest

import jaxkin as jk

SCRIPT = textwrap.dedent(
    """
    import logging, sys
    import jax, jax.numpy as jnp
    import jaxkin as jk
    print(jax.config.jax_compilation_cache_dir)  # importing jaxkin switched nothing on
    jax.config.update("jax_enable_x64", True)
    hits = []
    class Hits(logging.Handler):
        def emit(self, record):
            if "Persistent compilation cache hit" in record.getMessage():
                hits.append(record.getMessage())
    logger = logging.getLogger("jax._src.compiler")
    logger.setLevel(logging.DEBUG)
    logger.addHandler(Hits())
    jk.compilation.enable_persistent_cache(sys.argv[1], min_compile_time_s=0.0)
    robot = jk.robots.load("scara")  # small: what is tested is the cache
    J = jax.jit(jax.vmap(lambda q: jk.geometric_jacobian(robot, q)))(jnp.zeros((3, 4)))
    print(len(hits), float(J[0, 2, 0]))
    """
)


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """SCRIPT run twice in fresh processes sharing one cache directory: ``(directory, [stdout
    lines of each])``. The suite's own cache settings are left out of their environment (this
    conftest shares one cache between the suite's processes), so the first line of each is what
    importing jax and jaxkin set."""
    where = tmp_path_factory.mktemp("xla_cache")
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("JAX_COMPILATION_CACHE", "JAX_PERSISTENT_CACHE"))
    }
    env["JAX_PLATFORMS"] = "cpu"
    runs = [
        subprocess.run(
            [sys.executable, "-c", SCRIPT, str(where)],
            capture_output=True,
            text=True,
            timeout=300,
            env=env,
        )
        for _ in range(2)
    ]
    for run in runs:
        assert run.returncode == 0, run.stderr
    return where, [run.stdout.splitlines() for run in runs]


def test_not_switched_on_by_importing_jaxkin(two_runs):
    _, outputs = two_runs
    for lines in outputs:
        assert lines[0].split() == ["None"]


def test_a_second_process_loads_what_the_first_compiled(two_runs):
    where, outputs = two_runs
    (hits1, value1), (hits2, value2) = (lines[1].split() for lines in outputs)
    assert int(hits1) == 0 and int(hits2) >= 1
    assert value1 == value2
    assert any(where.iterdir())


def test_default_directory_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("JAXKIN_CACHE_DIR", str(tmp_path / "x"))
    assert jk.compilation.default_cache_directory() == tmp_path / "x"
    monkeypatch.delenv("JAXKIN_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert jk.compilation.default_cache_directory() == tmp_path / "jaxkin" / "xla"


def _mode(path):
    return stat.S_IMODE(os.stat(path).st_mode)


def _enable_restoring(monkeypatch, *args):
    """enable_persistent_cache, with JAX's settings put back after the test."""
    old = (
        jax.config.jax_compilation_cache_dir,
        jax.config.jax_persistent_cache_min_compile_time_secs,
    )
    try:
        return jk.compilation.enable_persistent_cache(*args)
    finally:
        jax.config.update("jax_compilation_cache_dir", old[0])
        jax.config.update("jax_persistent_cache_min_compile_time_secs", old[1])


posix = pytest.mark.skipif(not hasattr(os, "geteuid"), reason="no user ids")


@posix
def test_the_cache_directory_is_created_private_whatever_the_umask(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "home"))
    monkeypatch.delenv("JAXKIN_CACHE_DIR", raising=False)
    old = os.umask(0)
    try:
        path = _enable_restoring(monkeypatch)
    finally:
        os.umask(old)
    assert path == (tmp_path / "home" / "jaxkin" / "xla").resolve()
    assert _mode(path) == 0o700
    assert _mode(path.parent) == 0o700 and _mode(path.parent.parent) == 0o700


@posix
@pytest.mark.parametrize("mode", [0o777, 0o775, 0o722])
def test_a_cache_directory_others_can_write_to_is_refused(monkeypatch, tmp_path, mode):
    shared = tmp_path / "shared"
    shared.mkdir()
    os.chmod(shared, mode)
    wanted = rf"(?s){re.escape(str(shared))}.*{mode:04o}.*chmod go-w"
    with pytest.raises(jk.JaxkinError, match=wanted):
        _enable_restoring(monkeypatch, shared)
    # through the environment variable, and through a symlink to it: the same check
    monkeypatch.setenv("JAXKIN_CACHE_DIR", str(shared))
    with pytest.raises(jk.JaxkinError, match="chmod go-w"):
        _enable_restoring(monkeypatch)
    (tmp_path / "link").symlink_to(shared)
    with pytest.raises(jk.JaxkinError, match=re.escape(str(shared))):
        _enable_restoring(monkeypatch, tmp_path / "link")
    os.chmod(shared, 0o755)  # the fix the message names
    assert _enable_restoring(monkeypatch, tmp_path / "link") == shared.resolve()


@posix
def test_a_cache_directory_below_a_world_writable_one_is_refused(monkeypatch, tmp_path):
    os.chmod(tmp_path, 0o777)
    try:
        with pytest.raises(jk.JaxkinError, match="above the compilation cache"):
            _enable_restoring(monkeypatch, tmp_path / "cache")
        os.chmod(tmp_path, 0o1777)  # sticky, as /tmp: others cannot rename what is yours
        assert _mode(_enable_restoring(monkeypatch, tmp_path / "cache")) == 0o700
    finally:
        os.chmod(tmp_path, 0o700)


@posix
def test_a_cache_directory_another_user_owns_is_refused(monkeypatch, tmp_path):
    me = os.geteuid()
    monkeypatch.setattr(os, "geteuid", lambda: me + 4242)
    with pytest.raises(jk.JaxkinError, match=f"owned by user id {me}"):
        _enable_restoring(monkeypatch, tmp_path)


def test_a_cache_path_that_is_a_file_is_refused(monkeypatch, tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(jk.JaxkinError, match="not a directory"):
        _enable_restoring(monkeypatch, tmp_path / "f")
