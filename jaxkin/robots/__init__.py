"""The built-in robot zoo.

``jk.robots.load(name, dtype=None, **params)`` builds a zoo robot; ``jk.robots.names()`` lists
them; ``jk.robots.info(name)`` tells where its numbers come from. Robots whose dimensions are
symbols in the textbook (the chapter's examples) take them as keyword arguments, e.g.
``load("two_link_planar", a1=1.0, a2=0.5)``.

Every entry states units (metres, radians), the source of its numbers and its named
configurations (``robot.configurations``).

When ``example-robot-data`` is installed, its URDFs load by ``"erd/..."`` names as well
(``load("erd/panda", tip=..., base=...)``); ``erd_names()`` lists them (they are not in
``names()``, which is the zoo). Well-known arms load as the chain to their standard tool frame
(``erd/panda``: ``panda_hand_tcp``, 7 dof; ``erd/ur5_robot``: ``tool0``), the default frame;
see :mod:`jaxkin.robots.example_robot_data`. MJCF arm and hand models shipped inside installed
packages (dm-control, gymnasium-robotics) load by ``"mjcf/..."`` names (``mjcf_names()``; needs
the ``mjcf`` extra): see :mod:`jaxkin.robots.mjcf`.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..errors import JaxkinError, UnknownRobotError
from ..model import Robot

__all__ = ["ZooEntry", "erd_names", "info", "load", "mjcf_names", "names", "register"]


@dataclass(frozen=True)
class ZooEntry:
    """A zoo robot: its builder and where its numbers come from."""

    name: str
    builder: Callable[..., Robot]
    description: str
    source: str

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


def info(name: str) -> ZooEntry:
    """The zoo entry of ``name`` (description, source, parameters)."""
    if isinstance(name, str) and name.startswith("mjcf/"):
        from . import mjcf

        return mjcf.entry(name)
    if isinstance(name, str) and name.startswith("erd/"):
        from . import example_robot_data

        return example_robot_data.entry(name)
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise UnknownRobotError(
            f"unknown robot {name!r}; the zoo has {names()}. "
            "Load your own with jk.Robot.from_dh(...) or jk.load_urdf(...)."
        ) from None


def load(name: str, dtype: Any = None, **params: Any) -> Robot:
    """Build the zoo robot ``name`` (see :func:`names`), optionally with its symbolic dimensions."""
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
from . import industrial as industrial  # noqa: E402
from . import mjcf as mjcf  # noqa: E402
from . import niryo_one as niryo_one  # noqa: E402
