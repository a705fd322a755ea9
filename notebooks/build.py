"""Build the notebooks: each jupytext percent source ``NN_name.py`` becomes ``NN_name.ipynb``.

Edit the ``.py`` sources, never the ``.ipynb`` files, then run from the repository root::

    python notebooks/build.py            # every notebook
    python notebooks/build.py 04_niryo   # the sources whose name starts with 04_niryo

Each notebook is converted with jupytext, given the install cell below as its first code cell,
executed with nbclient in ``notebooks/`` (so ``data/...`` paths resolve) and written with its
outputs. ``python notebooks/build.py --check`` executes nothing: it exits 1 when a committed
notebook's cells differ from its source's (tests/test_notebooks.py checks the same and more).
Needs the ``notebooks`` extra (``pip install -e ".[notebooks]"``).
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import os
import pathlib
import sys
from collections.abc import Iterator, Mapping

import jupytext
import nbclient
import nbformat
from nbclient.util import run_sync

HERE = pathlib.Path(__file__).resolve().parent

# Every notebook's first code cell, self-contained (jaxkin is not installed yet where it acts).
# jaxkin is not on PyPI, and a package of that name there would be someone else's: the cell never
# installs by name, only from a jaxkin checkout above the notebook or from a wheel the user puts
# beside it.
INSTALL_CELL = """\
# Needs jaxkin: does nothing where it imports. Elsewhere installs jaxkin[notebooks] from the jaxkin
# checkout holding this notebook or, without one, from a wheel jaxkin-*.whl in this directory
# (jaxkin is not on PyPI; in a checkout, `pip install build && python3 -m build --wheel` writes
# the wheel, dist/jaxkin-VERSION-py3-none-any.whl).
import importlib.util

if importlib.util.find_spec("jaxkin") is None:
    import pathlib
    import subprocess
    import sys

    here = pathlib.Path.cwd().resolve()
    checkouts = [
        d
        for d in (here, *here.parents)
        if (d / "pyproject.toml").is_file()
        and 'name = "jaxkin"' in (d / "pyproject.toml").read_text(errors="replace")
    ]
    wheels = sorted(here.glob("jaxkin-*.whl"), key=lambda p: p.stat().st_mtime)
    if not checkouts and not wheels:
        raise RuntimeError(
            f"jaxkin is not installed, no jaxkin checkout holds {here} and it has no "
            "jaxkin-*.whl: build the wheel in a jaxkin checkout (python3 -m build --wheel), "
            "copy dist/jaxkin-*.whl here and run this cell again"
        )
    source = checkouts[0] if checkouts else wheels[-1]
    print(f"installing jaxkin[notebooks] from {source}")
    pip = [sys.executable, "-m", "pip", "install", f"jaxkin[notebooks] @ {source.as_uri()}"]
    subprocess.run(pip, check=True)"""

KERNELSPEC = {"display_name": "Python 3", "language": "python", "name": "python3"}
CELL_TIMEOUT_S = 300


def sources() -> list[pathlib.Path]:
    """The notebook sources, ``notebooks/NN_*.py``, sorted."""
    return sorted(HERE.glob("[0-9][0-9]_*.py"))


def from_source(path: pathlib.Path) -> nbformat.NotebookNode:
    """The notebook of one percent source, not executed: install cell first, stable cell ids."""
    nb = jupytext.read(path, fmt="py:percent")
    first_code = next(i for i, c in enumerate(nb.cells) if c.cell_type == "code")
    nb.cells.insert(first_code, nbformat.v4.new_code_cell(INSTALL_CELL))
    for i, cell in enumerate(nb.cells):
        cell.id = f"c{i:02d}"  # stable ids keep diffs small
        cell.metadata = {}
    nb.metadata = {"kernelspec": KERNELSPEC, "language_info": {"name": "python"}}
    return nb


def cells(nb: nbformat.NotebookNode) -> list[tuple[str, str]]:
    """(type, source) of every cell: what must agree between a source and its notebook."""
    return [(c.cell_type, c.source.strip()) for c in nb.cells]


# Run in a kernel before each notebook that follows another there (see :func:`execute`): what a
# notebook can leave behind goes back to how a fresh kernel has it (the user's names, open figures,
# matplotlib's settings, numpy's print options, JAX's float64 switch, the working directory).
# Imported modules stay imported: that is the saving (jax, matplotlib, sympy, jaxkin: seconds).
RESET_CELL = """\
def reset_kernel():
    import os, sys, types
    import jax, matplotlib, matplotlib.pyplot as plt, numpy as np
    if "fresh_kernel_state" not in sys.modules:  # the first run: the kernel is fresh
        fresh = types.ModuleType("fresh_kernel_state")
        fresh.printoptions = np.get_printoptions()
        fresh.x64, fresh.cwd = jax.config.jax_enable_x64, os.getcwd()
        sys.modules["fresh_kernel_state"] = fresh
    fresh = sys.modules["fresh_kernel_state"]
    plt.close("all")
    matplotlib.rc_file_defaults()
    np.set_printoptions(**fresh.printoptions)
    jax.config.update("jax_enable_x64", fresh.x64)
    os.chdir(fresh.cwd)
    # figures drawn once, not twice: the inline backend's bbox_inches="tight" draws each figure
    # to find its extent before drawing it again (a third of the figures' cost; only here, in
    # the tests' kernel: the committed outputs keep the default)
    from matplotlib_inline.config import InlineBackend
    InlineBackend.instance().print_figure_kwargs = {"bbox_inches": None}


reset_kernel()
get_ipython().reset(new_session=True)"""


def _client(nb: nbformat.NotebookNode, km=None) -> nbclient.NotebookClient:
    return nbclient.NotebookClient(
        nb,
        km=km,
        timeout=CELL_TIMEOUT_S,
        kernel_name="python3",
        record_timing=False,
        resources={"metadata": {"path": str(HERE)}},
    )


def _env(extra: Mapping[str, str]) -> dict[str, str]:
    return {**os.environ, "MATPLOTLIBRC": str(HERE / "matplotlibrc"), **extra}


class Kernel:
    """One kernel that runs notebooks one after the other (see :func:`execute`)."""

    def __init__(self, env: Mapping[str, str]):
        self.env = _env(env)
        self.km = _client(nbformat.v4.new_notebook()).create_kernel_manager()

    def run(self, nb: nbformat.NotebookNode) -> None:
        """Execute ``nb`` here (the kernel starts with the first notebook)."""
        client = _client(nb, self.km)
        try:
            client.execute(env=self.env)
        finally:
            if client.kc is not None:
                client.kc.stop_channels()

    def shutdown(self) -> None:
        if self.km.has_kernel:
            run_sync(self.km.shutdown_kernel)(now=True)


@contextlib.contextmanager
def kernel(env: Mapping[str, str] | None = None) -> Iterator[Kernel]:
    """A :class:`Kernel` in ``notebooks/`` with the environment plus ``env``, shut down on
    exit."""
    shared = Kernel(env or {})
    try:
        yield shared
    finally:
        shared.shutdown()


def execute(nb: nbformat.NotebookNode, shared: Kernel | None = None) -> nbformat.NotebookNode:
    """A copy of ``nb`` executed in ``notebooks/`` with ``notebooks/matplotlibrc`` (72 dpi figures);
    raises on the first failing cell.

    Without ``shared``, in a kernel of its own (what :func:`main` does: the committed outputs
    come from fresh kernels). With ``shared`` (from :func:`kernel`), in that kernel after
    :data:`RESET_CELL`, which saves a kernel's start and imports per notebook (the tests); a
    notebook that fails there shuts the kernel down, so that the next one starts afresh.
    """
    nb = copy.deepcopy(nb)
    if shared is None:
        _client(nb).execute(env=_env({}))
        return nb
    try:
        shared.run(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(RESET_CELL)]))
        shared.run(nb)
    except BaseException:
        shared.shutdown()
        raise
    return nb


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="build only sources whose name starts so")
    parser.add_argument("--check", action="store_true", help="compare cells, execute nothing")
    args = parser.parse_args(argv)
    paths = [p for p in sources() if not args.names or p.stem.startswith(tuple(args.names))]
    if not paths:
        parser.error(f"no notebook source matches {args.names}")
    stale = []
    for path in paths:
        target = path.with_suffix(".ipynb")
        nb = from_source(path)
        if args.check:
            if not target.exists() or cells(nbformat.read(target, as_version=4)) != cells(nb):
                stale.append(target.name)
            continue
        nbformat.write(execute(nb), target)
        print("wrote", target.relative_to(HERE.parent))
    if stale:
        print("stale (run python notebooks/build.py):", ", ".join(stale))
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
