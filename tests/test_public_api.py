"""The top-level namespace: ``jaxkin.__all__`` is exactly what ``jaxkin/__init__.py`` re-exports,
and a star import binds those names only (never a submodule that shadows the standard library,
such as ``jaxkin.io``)."""

from __future__ import annotations

import ast
import pathlib
import subprocess
import sys

import jaxkin as jk

INIT = pathlib.Path(jk.__file__)


def test_all_is_the_reexported_names():
    tree = ast.parse(INIT.read_text())
    reexported = {
        alias.asname
        for node in tree.body
        if isinstance(node, ast.ImportFrom) and node.level == 1
        for alias in node.names
        if alias.asname == alias.name
    }
    assert sorted(jk.__all__) == sorted(reexported)
    assert all(hasattr(jk, name) for name in jk.__all__)


def test_star_import_does_not_shadow_the_standard_library():
    code = (
        "import io, jaxkin.io, jaxkin.batch\n"
        "from jaxkin import *\n"
        "assert io.StringIO is not None, io\n"
        "assert fk is not None and load_urdf is not None\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
