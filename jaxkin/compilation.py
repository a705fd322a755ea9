"""Compilation: JAX's persistent compilation cache switched on in one call, and the eager cache.

jaxkin compiles its entry points (``solve_ik``, ``calibrate``, ``resolved_rate_control``) and,
for calls made outside any transformation, its building blocks (``fk``, the Jacobians, twists,
derivatives: see :func:`jaxkin._jit.eager`), once per robot value, shapes and options. In a new
process everything compiles again; JAX's persistent compilation cache keeps the executables on
disk so that the next process loads them instead (the first ``solve_ik`` of a new process then
costs a load, not a compile). jaxkin never changes JAX's global settings by itself: call
:func:`enable_persistent_cache` once, at the top of a script or notebook.

>>> import jaxkin as jk
>>> info = jk.compilation.eager_cache_info()
>>> sorted(info)
['entries', 'executables']
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

from ._jit import EAGER_CACHE_SIZE, eager_cache_clear, eager_cache_info

__all__ = [
    "EAGER_CACHE_SIZE",
    "default_cache_directory",
    "eager_cache_clear",
    "eager_cache_info",
    "enable_persistent_cache",
]


def default_cache_directory() -> Path:
    """``$JAXKIN_CACHE_DIR``, else ``$XDG_CACHE_HOME/jaxkin/xla``, else ``~/.cache/jaxkin/xla``."""
    if os.environ.get("JAXKIN_CACHE_DIR"):
        return Path(os.environ["JAXKIN_CACHE_DIR"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "jaxkin" / "xla"


def enable_persistent_cache(
    directory: str | os.PathLike | None = None, min_compile_time_s: float = 0.5
) -> Path:
    """Switch on JAX's persistent compilation cache for this process; returns its directory.

    Sets JAX's ``jax_compilation_cache_dir`` (default :func:`default_cache_directory`, created if
    missing) and ``jax_persistent_cache_min_compile_time_secs`` (executables that took at least
    this long to compile are stored; JAX's default is 1 s). A global JAX setting: it applies to
    every ``jax.jit`` of the process, jaxkin's and yours. Call it before the first compile.

    >>> import jaxkin as jk
    >>> jk.compilation.enable_persistent_cache()  # doctest: +SKIP
    PosixPath('/home/you/.cache/jaxkin/xla')
    """
    path = Path(directory).expanduser() if directory is not None else default_cache_directory()
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time_s))
    return path
