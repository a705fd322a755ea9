"""Test-only libraries (oracles, the viewer's viser) imported when a test first uses them, not
while pytest collects.

Each xdist worker collects every test module, but runs only some: an oracle imported at module
level (importing the Robotics Toolbox, with spatialmath, SciPy and matplotlib, took 4.3 s on this
machine) costs the workers that never run its tests. ``lazy_module("roboticstoolbox")`` stands for
the module: the first attribute read imports it (DeprecationWarnings of the import ignored, as
warnings are errors in this suite) or skips the test, saying so, where it is not installed.
Underscore names are not passed on: pytest reads ``__wrapped__``, ``_pytestfixturefunction`` and
the like from every module-level object while it collects, and answering them would import the
module there after all.
"""

from __future__ import annotations

import importlib.util
import warnings
from types import ModuleType

import pytest


class _LazyModule:
    def __init__(self, name: str):
        self._name = name
        self._module: ModuleType | None = None

    def _load(self) -> ModuleType:
        if self._module is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DeprecationWarning)
                self._module = pytest.importorskip(self._name)
        return self._module

    def __getattr__(self, attr: str):
        if attr.startswith("_"):
            raise AttributeError(f"{attr!r}: {self._name}'s stand-in passes public names only")
        return getattr(self._load(), attr)


def lazy_module(name: str, reason: str | None = None) -> _LazyModule:
    """A stand-in for module ``name`` that imports it at first use; the calling test module is
    skipped (with ``reason``, or "NAME is not installed") where it is not installed."""
    if importlib.util.find_spec(name.split(".")[0]) is None:
        pytest.skip(reason or f"{name} is not installed", allow_module_level=True)
    return _LazyModule(name)
