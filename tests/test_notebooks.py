"""The notebooks: each committed .ipynb matches its jupytext source, runs, and holds its outputs.

notebooks/NN_name.py (jupytext percent format) is the source; notebooks/build.py turns it into
NN_name.ipynb, executed, with outputs. Each notebook is executed once here; its cells are compared
with the committed file's, and every cell that outputs something must have outputs committed.
"""

import importlib.util
import pathlib
import time

import nbformat
import pytest

pytest.importorskip("jupytext")
pytest.importorskip("nbclient")

NOTEBOOK_DIR = pathlib.Path(__file__).resolve().parent.parent / "notebooks"
_spec = importlib.util.spec_from_file_location("notebook_build", NOTEBOOK_DIR / "build.py")
build = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(build)

SOURCES = build.sources()
# Per notebook. On a quiet 2-core CPU each runs in well under a minute (05, a million
# configurations, and 06 are the longest); the margin absorbs a busy machine.
NOTEBOOK_BUDGET_S = 420
REBUILD = "rebuild it: python notebooks/build.py {}"


def test_every_source_has_its_notebook_and_no_notebook_lacks_a_source():
    assert SOURCES, "notebooks/ should hold at least one NN_name.py source"
    notebooks = sorted(p.stem for p in NOTEBOOK_DIR.glob("*.ipynb"))
    assert notebooks == [p.stem for p in SOURCES]


def test_install_cell_comes_first_and_nothing_is_downloaded():
    for path in SOURCES:
        nb = nbformat.read(path.with_suffix(".ipynb"), as_version=4)
        code = [c.source for c in nb.cells if c.cell_type == "code"]
        assert code[0] == build.INSTALL_CELL, REBUILD.format(path.stem)
        text = "\n".join(c.source for c in nb.cells)
        for word in ("colab", "urlretrieve", "urlopen", "requests.get", "http://", "https://"):
            assert word not in text.lower(), f"{path.name}: {word}"


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: p.stem)
def test_notebook_matches_its_source_runs_and_holds_its_outputs(path):
    committed = nbformat.read(path.with_suffix(".ipynb"), as_version=4)
    source = build.from_source(path)
    assert build.cells(committed) == build.cells(source), REBUILD.format(path.stem)

    start = time.perf_counter()
    executed = build.execute(source)  # raises CellExecutionError on the first failing cell
    elapsed = time.perf_counter() - start
    assert elapsed < NOTEBOOK_BUDGET_S, f"{path.name} took {elapsed:.0f} s"

    for k, (ran, kept) in enumerate(zip(executed.cells, committed.cells, strict=True)):
        if ran.cell_type != "code":
            continue
        assert not [o for o in ran.outputs if o.output_type == "error"]
        kinds = {o.output_type for o in ran.outputs}
        if kinds:
            kept_kinds = {o.output_type for o in kept.outputs}
            assert kept_kinds, f"{path.name} cell {k} has no outputs; {REBUILD.format(path.stem)}"
            assert kinds <= kept_kinds | {"stream"}, (path.name, k, kinds, kept_kinds)
            assert "error" not in kept_kinds
