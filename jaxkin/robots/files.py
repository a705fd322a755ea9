"""Robot files by path: how :func:`jaxkin.robots.load` tells a file from a robot name, and
which loader reads it.

A path (``os.PathLike``, or a ``str`` that ends in ``.urdf``, ``.xml`` or ``.xacro``, holds a
``/`` or names an existing file) loads with :func:`jaxkin.load_mjcf` when the file's root
element is ``<mujoco>`` (:func:`root_tag`), with :func:`jaxkin.load_urdf` otherwise; a
``.xacro`` file only with ``trust=True`` (it runs the file's code; see :mod:`jaxkin.urdf`).
Robot names win over files: a file called like a zoo robot needs a path (``./niryo_one``), and
a ``str`` with a prefix of :data:`NAME_PREFIXES`, no file suffix and no file of that name is a
robot name (a mistyped one gets :func:`jaxkin.robots.info`'s suggestions).
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any
from xml.parsers import expat

from ..errors import JaxkinError
from ..model import Robot

__all__ = [
    "FILE_SUFFIXES",
    "NAME_PREFIXES",
    "SNIFF_BYTES",
    "XACRO_SUFFIX",
    "is_path",
    "load",
    "root_tag",
]

FILE_SUFFIXES = (".urdf", ".xml", ".xacro")
"""Suffixes (any case) that make a ``str`` a robot file's path."""
XACRO_SUFFIX = ".xacro"
NAME_PREFIXES = ("erd/", "mjcf/")
"""Names with these prefixes are robots of :mod:`jaxkin.robots` (example-robot-data, MJCF
packages) unless a file of that name exists."""
SNIFF_BYTES = 1 << 16
"""Bytes of a robot file read to find its root element (URDF or MJCF)."""
_OPTIONS = ("tip", "base", "name", "trust")


def is_path(spec: Any) -> bool:
    """Whether :func:`jaxkin.robots.load` reads ``spec`` as a file path (see the module doc);
    the robot names are listed only for a ``str`` that also looks like a path."""
    if isinstance(spec, os.PathLike):
        return True
    if not isinstance(spec, str) or not spec:
        return False
    lowered = spec.lower()
    if spec.startswith(NAME_PREFIXES) and not lowered.endswith(FILE_SUFFIXES):
        if not os.path.lexists(spec):
            return False
    if not (lowered.endswith(FILE_SUFFIXES) or os.sep in spec or os.path.lexists(spec)):
        return False
    from . import erd_names, mjcf_names, names

    return spec not in (*names(), *erd_names(), *mjcf_names())


def load(path: Any, dtype: Any = None, **options: Any) -> Robot:
    """The robot of the file ``path``: MJCF when its root element is ``<mujoco>``, else URDF
    (xacro for a ``.xacro`` path, which needs ``trust=True``). ``options``: ``tip``, ``base``,
    ``name`` and ``trust`` (xacro only), passed on to :func:`jaxkin.load_urdf` or
    :func:`jaxkin.load_mjcf`."""
    unknown = sorted(set(options) - set(_OPTIONS))
    if unknown:
        raise JaxkinError(
            f"a robot file takes the options {list(_OPTIONS)}, got {unknown}; load it with "
            "jk.load_urdf or jk.load_mjcf for the others."
        )
    from .. import load_mjcf, load_urdf  # the package's entries, looked up at each call

    trust = options.pop("trust", False)
    xacro = str(path).lower().endswith(XACRO_SUFFIX)
    if not xacro and root_tag(Path(path)) == "mujoco":
        return load_mjcf(path, dtype=dtype, **options)
    return load_urdf(path, dtype=dtype, trust=trust, **options)


class _RootFound(Exception):
    """Stops the parse of :func:`root_tag` at the first element."""


def root_tag(path: Path) -> str | None:
    """The name of the first element of the XML file ``path``, from at most :data:`SNIFF_BYTES`
    of it; None when they hold none, a DTD comes first, it is not XML or not a regular file (the
    URDF loader then says what is wrong). Only the start of a regular file is read; nothing is
    expanded."""
    if not path.is_file():
        return None
    found: list[str] = []

    def start(name: str, attributes: Any) -> None:
        found.append(name)
        raise _RootFound

    def doctype(*args: Any) -> None:
        raise _RootFound  # no DTD is processed here; the loaders refuse or handle it

    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    parser.StartElementHandler, parser.StartDoctypeDeclHandler = start, doctype
    with open(path, "rb") as f:
        head = f.read(SNIFF_BYTES)
    with contextlib.suppress(_RootFound, expat.ExpatError):
        parser.Parse(head, False)
    return found[0] if found else None
