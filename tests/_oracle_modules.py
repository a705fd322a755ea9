"""Oracle libraries imported when a test first uses them, not while pytest collects.

Each xdist worker collects every test module, but runs only some: an oracle imported at module
level (the Robotics Toolbox and spatialmath take 1-1.5 s of CPU each) costs the workers that never
run its tests. ``lazy_module("roboticstoolbox")`` stands for the module: the first attribute read
imports it (DeprecationWarnings of the import ignored, as warnings are errors in this suite) or
skips the test, saying so, where it is not installed.
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
        return getattr(self._load(), attr)


def lazy_module(name: str) -> _LazyModule:
    """A stand-in for module ``name`` that imports it (or skips the test) at first use."""
    if importlib.util.find_spec(name.split(".")[0]) is None:
        pytest.skip(f"{name} is not installed", allow_module_level=True)
    return _LazyModule(name)
