"""The built-in robot zoo.

``jk.robots.load(name, dtype=None, **params)`` builds a zoo robot, or loads a robot file given
its path (URDF, MJCF, xacro: :mod:`jaxkin.robots.files`); ``jk.robots.names()`` lists
them; ``jk.robots.info(name)`` tells where its numbers come from (``source``) and, for robots
loaded from a file, where that file is (``path``). Robots whose dimensions are
symbols in the textbook (the chapter's examples) take them as keyword arguments, e.g.
``load("two_link_planar", a1=1.0, a2=0.5)``.

Every entry states units (metres, radians), the source of its numbers and its named
configurations (``robot.configurations``).

When ``example-robot-data`` is installed, its URDFs load by ``"erd/..."`` names as well
(``load("erd/panda", tip=..., base=...)``); ``erd_names()`` lists them (they are not in
``names()``, which is the zoo). Well-known arms load as the chain to their standard tool frame
(``erd/panda``: ``panda_hand_tcp``, 7 dof); the others, UR arms included, load whole, with
:func:`jaxkin.load_urdf`'s default frame (``erd/ur5_robot``: ``tool0``); see
:mod:`jaxkin.robots.example_robot_data`. MJCF arm and hand models shipped inside installed
packages (dm-control, gymnasium-robotics) load by ``"mjcf/..."`` names (``mjcf_names()``; needs
the ``mjcf`` extra): see :mod:`jaxkin.robots.mjcf`.
"""

from __future__ import annotations

import difflib
import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import JaxkinError, UnknownRobotError
from ..model import Robot

__all__ = [
    "ZooEntry",
    "close_names",
    "did_you_mean",
    "erd_names",
    "info",
    "load",
    "mjcf_names",
    "names",
    "register",
]


@dataclass(frozen=True)
class ZooEntry:
    """A zoo robot: its builder and where its numbers come from.

    ``source``: where the numbers come from, for people to read (a datasheet, a paper, or a
    file and the version of the package that ships it); not a path. ``path``: the file the robot
    is loaded from (a :class:`~pathlib.Path` that exists), or None for robots written in Python
    (DH tables, ``niryo_one``); with ``tip`` and ``base``, the part of the file the zoo loads
    (None: the whole file, the loader's default frame), so that
    ``jk.load_urdf(entry.path, tip=entry.tip, base=entry.base, name=entry.name)`` (for
    ``"erd/..."`` names; ``jk.load_mjcf`` for ``"mjcf/..."`` names) builds the robot
    ``jk.robots.load(entry.name)`` does.
    """

    name: str
    builder: Callable[..., Robot]
    description: str
    source: str
    path: Path | None = None
    tip: str | None = None
    base: str | None = None

    @property
    def parameters(self) -> dict[str, Any]:
        """Keyword parameters (symbolic dimensions) the builder takes, with defaults."""
        sig = inspect.signature(self.builder)
        return {
            k: p.default
            for k, p in sig.parameters.items()
            if k != "dtype" and p.default is not inspect.Parameter.empty
        }


_REGISTRY: dict[str, ZooEntry] = {}


def register(name: str, description: str, source: str):
    """Decorator adding a builder ``f(dtype=None, **params) -> Robot`` to the zoo."""

    def deco(fn: Callable[..., Robot]) -> Callable[..., Robot]:
        _REGISTRY[name] = ZooEntry(name, fn, description, source)
        return fn

    return deco


def names() -> list[str]:
    """Names of the zoo robots, sorted."""
    return sorted(_REGISTRY)


def erd_names() -> list[str]:
    """Names (``"erd/..."``) of the example-robot-data URDFs, sorted; [] if not installed."""
    from . import example_robot_data

    return example_robot_data.names()


def mjcf_names() -> list[str]:
    """Names (``"mjcf/..."``) of the MJCF models of installed packages, sorted."""
    from . import mjcf

    return mjcf.names()


def close_names(name: Any, candidates: Sequence[str], n: int = 3) -> list[str]:
    """The names of ``candidates`` most likely meant by ``name``: first those that start with
    it (``"erd/ur5"`` -> ``"erd/ur5_robot"``), then those that contain it, shortest first, then
    the closest by spelling (:func:`difflib.get_close_matches`); at most ``n``."""
    if not isinstance(name, str) or not name:
        return []
    typed = name.lower()
    lowered = {c: c.lower() for c in candidates}
    starts = sorted((c for c, low in lowered.items() if low.startswith(typed)), key=len)
    contains = sorted((c for c, low in lowered.items() if typed in low), key=len)
    spelled = difflib.get_close_matches(name, list(candidates), n=n, cutoff=0.75)
    return list(dict.fromkeys([*starts, *contains, *spelled]))[:n]


def did_you_mean(name: Any, candidates: Sequence[str]) -> str:
    """`` Did you mean 'a' or 'b'?`` for :func:`close_names`, or ``""``."""
    close = close_names(name, candidates)
    return f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


def info(name: str) -> ZooEntry:
    """The zoo entry of ``name``: ``description``, ``source`` (where the numbers come from, in
    words), ``path``/``tip``/``base`` (the file and the part of it loaded, or None; see
    :class:`ZooEntry`) and ``parameters``."""
    if isinstance(name, str) and name.startswith("mjcf/"):
        from . import mjcf

        return mjcf.entry(name)
    if isinstance(name, str) and name.startswith("erd/"):
        from . import example_robot_data

        return example_robot_data.entry(name)
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        everything = [*names(), *erd_names(), *mjcf_names()]
        raise UnknownRobotError(
            f"unknown robot {name!r}.{did_you_mean(name, everything)} The zoo has {names()} "
            "(jk.robots.erd_names() and jk.robots.mjcf_names() list the robots of installed "
            "packages). Load your own with jk.Robot.from_dh(...) or jk.load_urdf(...)."
        ) from None


def load(name: Any, /, dtype: Any = None, **params: Any) -> Robot:
    """The robot ``name`` names: a zoo robot (see :func:`names`), optionally with its symbolic
    dimensions, an ``"erd/..."`` or ``"mjcf/..."`` robot (``tip=``, ``base=``), or a file: the
    path of a URDF, MJCF or xacro file (``tip=``, ``base=``, ``name=``, and ``trust=True`` for
    xacro, which runs the file's code), loaded with :func:`jaxkin.load_urdf` or
    :func:`jaxkin.load_mjcf` (the root element decides; see :mod:`jaxkin.robots.files` for
    how a name is told from a path: names win), e.g.
    ``jk.robots.load("robot.urdf", tip="tool0")`` is ``jk.load_urdf("robot.urdf", tip="tool0")``.

    >>> import jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar", a1=1.0, a2=0.5)
    >>> robot.dof, robot.name
    (2, 'two_link_planar')
    """
    if files.is_path(name):
        return files.load(name, dtype=dtype, **params)
    entry = info(name)
    allowed = entry.parameters
    unknown = set(params) - set(allowed)
    if unknown:
        hint = f"it takes {sorted(allowed)}" if allowed else "it takes no parameters"
        raise JaxkinError(f"robot {name!r} has no parameter(s) {sorted(unknown)}; {hint}.")
    return entry.builder(dtype=dtype, **params)


# Entries register themselves on import.
from . import chapter as chapter  # noqa: E402
from . import example_robot_data as example_robot_data  # noqa: E402
from . import files as files  # noqa: E402
from . import industrial as industrial  # noqa: E402
from . import mjcf as mjcf  # noqa: E402
from . import niryo_one as niryo_one  # noqa: E402
