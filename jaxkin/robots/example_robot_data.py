"""The URDFs of ``example-robot-data`` as jaxkin robots (optional; never a runtime dependency).

``example-robot-data`` (``pip install example-robot-data``; Pinocchio's collection of about 70
robot descriptions) ships its files under ``cmeel.prefix/share/example-robot-data/robots`` in
site-packages and, from version 5, no Python loader. This module finds them through the
installed distribution's file list (nothing is imported or executed) and loads them with
:func:`jaxkin.load_urdf`.

Names
-----
Every ``.urdf`` file is one robot named ``"erd/<stem>"``, ``<stem>`` being the file name without
``.urdf``: ``"erd/panda"``, ``"erd/ur5_robot"``, ``"erd/kinova"``, ``"erd/talos_reduced"``. The
``erd/`` prefix keeps them apart from the zoo's hand-written models (``"panda"`` and ``"ur5"``
are the zoo's DH models): nothing is shadowed. When two files share a stem, each is named
``"erd/<package>/<stem>"``, ``<package>`` being its description folder without
``_description`` (``"erd/anymal_b_simple/anymal"``, ``"erd/anymal_c_simple/anymal"``).

``jk.robots.erd_names()`` lists them (empty when the package is not installed);
``jk.robots.load("erd/panda", dtype=..., tip=..., base=...)`` loads one;
``jk.robots.info("erd/panda").source`` is its path. Some files of the collection are not
loadable kinematic models, and loading them raises a :class:`jaxkin.ModelError` that says why
and lists the other files of the same package (``ur3.urdf`` of 6.0 is an empty xacro output,
use ``"erd/ur3_robot"``; ``quadrotor_base`` and ``iris_simple`` have no moving joint;
``alex_psyonic_hands`` has mimic joints whose leader does not exist).

Set ``JAXKIN_EXAMPLE_ROBOT_DATA`` to a ``robots`` folder to use another copy (e.g. a source
checkout).
"""

from __future__ import annotations

import functools
import importlib.metadata
import os
from pathlib import Path
from typing import Any

from ..errors import UnknownRobotError
from ..model import Robot

__all__ = ["PREFIX", "entry", "load", "names", "path", "robots_dir"]

PREFIX = "erd/"
ENV = "JAXKIN_EXAMPLE_ROBOT_DATA"
_DIST = "example-robot-data"
_MARKER = "example-robot-data/robots/"


@functools.lru_cache(maxsize=1)
def robots_dir() -> Path | None:
    """The ``robots`` folder of the installed example-robot-data, or None if there is none."""
    env = os.environ.get(ENV)
    if env:
        return Path(env) if Path(env).is_dir() else None
    try:
        dist = importlib.metadata.distribution(_DIST)
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in dist.files or ():
        s = str(f).replace("\\", "/")
        k = s.find(_MARKER)
        if k >= 0 and s.endswith(".urdf"):
            root = Path(str(dist.locate_file(s[: k + len(_MARKER)])))
            return root if root.is_dir() else None
    return None


@functools.lru_cache(maxsize=1)
def _index() -> dict[str, Path]:
    root = robots_dir()
    if root is None:
        return {}
    files = sorted(p for p in root.rglob("*.urdf") if p.is_file())
    stems: dict[str, list[Path]] = {}
    for p in files:
        stems.setdefault(p.stem, []).append(p)
    out: dict[str, Path] = {}
    for stem, paths in stems.items():
        if len(paths) == 1:
            out[PREFIX + stem] = paths[0]
            continue
        for p in paths:
            package = p.relative_to(root).parts[0].removesuffix("_description")
            out[f"{PREFIX}{package}/{stem}"] = p
    return dict(sorted(out.items()))


def names() -> list[str]:
    """Names (``"erd/..."``) of every example-robot-data URDF, sorted; [] if not installed."""
    return list(_index())


def path(name: str) -> Path:
    """The URDF file of ``name``."""
    index = _index()
    if name in index:
        return index[name]
    if not index:
        raise UnknownRobotError(
            f"robot {name!r} needs example-robot-data, which is not installed (or has no URDF "
            f"files). Install it with `pip install example-robot-data`, or set {ENV} to its "
            "robots folder."
        )
    import difflib

    close = difflib.get_close_matches(name, list(index), n=3, cutoff=0.75)
    hint = f" Did you mean {', '.join(repr(c) for c in close)}?" if close else ""
    raise UnknownRobotError(
        f"unknown example-robot-data robot {name!r}.{hint} jk.robots.erd_names() lists all "
        f"{len(index)}."
    )


def load(name: str, dtype: Any = None, tip: str | None = None, base: str | None = None) -> Robot:
    """Load the example-robot-data robot ``name`` (see :func:`names`) with
    :func:`jaxkin.load_urdf` (``tip``/``base`` select a chain or subtree)."""
    from ..urdf import URDFError, load_urdf

    p = path(name)
    try:
        return load_urdf(p, tip=tip, base=base, dtype=dtype, name=name)
    except URDFError as e:
        siblings = [n for n, q in _index().items() if q.parent == p.parent and n != name]
        folder = p.parent.relative_to(robots_dir()) if robots_dir() else p.parent
        more = f" Other example-robot-data robots in {folder}/: {siblings}." if siblings else ""
        raise URDFError(
            e.problem,
            file=e.file,
            line=e.line,
            element=e.element,
            attribute=e.attribute,
            value=e.value,
            fix=((e.fix or "") + more).strip() or None,
        ) from None


def entry(name: str):
    """The :class:`jaxkin.robots.ZooEntry` of an ``"erd/..."`` name."""
    from . import ZooEntry

    p = path(name)
    rel = p.relative_to(robots_dir()) if robots_dir() is not None else p
    try:
        version = importlib.metadata.version(_DIST)
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - env override
        version = "unknown version"

    def builder(dtype: Any = None, tip: str | None = None, base: str | None = None) -> Robot:
        return load(name, dtype=dtype, tip=tip, base=base)

    return ZooEntry(
        name=name,
        builder=builder,
        description=f"example-robot-data {rel} (URDF, loaded with jk.load_urdf)",
        source=f"{p} (example-robot-data {version})",
    )
