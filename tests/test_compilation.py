"""jk.compilation: the persistent cache is switched on only when asked, and a second process loads
what the first compiled (counted by JAX's own cache-hit log, not timed)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import jax

import jaxkin as jk

SCRIPT = textwrap.dedent(
    """
    import logging, sys
    import jax, jax.numpy as jnp
    import jaxkin as jk
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
    robot = jk.robots.load("puma560")
    J = jax.jit(jax.vmap(lambda q: jk.geometric_jacobian(robot, q)))(jnp.zeros((3, 6)))
    print(len(hits), float(J[0, 2, 0]))
    """
)


def test_not_switched_on_by_importing_jaxkin():
    assert not jax.config.jax_compilation_cache_dir


def test_a_second_process_loads_what_the_first_compiled(tmp_path):
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    runs = [
        subprocess.run(
            [sys.executable, "-c", SCRIPT, str(tmp_path)],
            capture_output=True,
            text=True,
            timeout=300,
            env=env,
        )
        for _ in range(2)
    ]
    for run in runs:
        assert run.returncode == 0, run.stderr
    (hits1, value1), (hits2, value2) = (run.stdout.split() for run in runs)
    assert int(hits1) == 0 and int(hits2) >= 1
    assert value1 == value2
    assert any(tmp_path.iterdir())


def test_default_directory_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("JAXKIN_CACHE_DIR", str(tmp_path / "x"))
    assert jk.compilation.default_cache_directory() == tmp_path / "x"
    monkeypatch.delenv("JAXKIN_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert jk.compilation.default_cache_directory() == tmp_path / "jaxkin" / "xla"
