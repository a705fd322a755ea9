"""Compilation: JAX's persistent compilation cache switched on in one call, and the eager cache.

jaxkin compiles its entry points (``solve_ik``, ``calibrate``, ``resolved_rate_control``) and,
for calls made outside any transformation, its building blocks (``fk``, the Jacobians, twists,
derivatives: the eager cache below), once per robot value, shapes and options. In a new
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
import stat
from pathlib import Path

import jax

from ._jit import EAGER_CACHE_SIZE, eager_cache_clear, eager_cache_info
from .errors import JaxkinError

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

    The directory holds native code that JAX will run, so it must be yours alone: a missing one
    is created with mode 0700 (whatever the umask), and one that another user owns, or that
    group or others can write to (or that lies below such a directory without the sticky bit)
    is refused with a :class:`~jaxkin.JaxkinError` naming it and the fix (``chmod go-w DIR``,
    or another directory): see :func:`private_directory`. ``$JAXKIN_CACHE_DIR`` is checked
    alike.

    >>> import jaxkin as jk
    >>> jk.compilation.enable_persistent_cache()  # doctest: +SKIP
    PosixPath('/home/you/.cache/jaxkin/xla')
    """
    path = Path(directory).expanduser() if directory is not None else default_cache_directory()
    path = private_directory(path)
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time_s))
    return path


def private_directory(path: Path) -> Path:
    """``path`` made (mode 0700, whatever the umask) or checked as a directory only its owner can
    change; returns its resolved path (a symlink is followed, and its target checked).

    The cache holds native executables that JAX loads and runs, so, as ``ssh`` does for keys,
    a directory that another user owns, or that group or others can write to, is refused
    (:class:`~jaxkin.JaxkinError` naming it and the fix), and so is one below a directory
    that others could rename it out of (group/other-writable without the sticky bit, or owned
    by another user than you or root). Not checked where the system has no user ids (Windows).
    """
    path = Path(os.path.abspath(path))
    missing = [p for p in (path, *path.parents) if not os.path.lexists(p)]
    for p in reversed(missing):
        try:
            os.mkdir(p, 0o700)
        except FileExistsError:
            pass
        else:
            os.chmod(p, 0o700)  # the mode asked of mkdir is masked by the umask
    real = path.resolve()
    if not real.is_dir():
        raise JaxkinError(
            f"the compilation cache directory {str(path)!r} is not a directory; "
            "pass a directory to enable_persistent_cache (or set JAXKIN_CACHE_DIR to one)"
        )
    if hasattr(os, "geteuid"):
        _check_private(real, own=True)
        for parent in real.parents:
            _check_private(parent, own=False)
    return real


def _check_private(path: Path, own: bool) -> None:
    """Refuse ``path`` (the cache directory if ``own``, else one above it) if another user can
    change what it holds."""
    st = os.stat(path)
    me = os.geteuid()
    owners = (me,) if own else (me, 0)
    writable = st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)
    sticky = not own and st.st_mode & stat.S_ISVTX
    if st.st_uid in owners and not (writable and not sticky):
        return
    what = "the compilation cache directory" if own else "a directory above the compilation cache"
    why = (
        f"is owned by user id {st.st_uid}, not you ({me})"
        if st.st_uid not in owners
        else f"has mode {stat.S_IMODE(st.st_mode):04o}: group or others can write to it"
    )
    fix = "chmod go-w " + str(path) if st.st_uid in owners else "use a directory of your own"
    raise JaxkinError(
        f"{what} {str(path)!r} {why}; JAX loads and runs the native code kept there, so "
        f"jaxkin refuses it. Fix: {fix}, or pass another directory to "
        "jk.compilation.enable_persistent_cache (or set JAXKIN_CACHE_DIR)"
    )
