"""The notebooks: each committed .ipynb matches its jupytext source, runs, and holds its outputs.

notebooks/NN_name.py (jupytext percent format) is the source; notebooks/build.py turns it into
NN_name.ipynb, executed, with outputs. Each notebook is executed once here; its cells are compared
with the committed file's, and every cell that outputs something must have outputs committed.

The notebooks run one after the other in one kernel (``build.kernel``; ``build.RESET_CELL`` clears
what the previous one left: names, figures, print options, JAX's float64 switch), which saves
each one a kernel's start and the imports of jax, matplotlib, sympy and jaxkin; ``python
notebooks/build.py`` still runs each in a fresh kernel. The kernel inherits the suite's
``XLA_FLAGS`` (LLVM's optimisation off, tests/conftest.py) and draws each figure once (no
``bbox_inches="tight"``, which draws it twice; every figure still drawn and shown); the committed
outputs come from XLA's and the inline backend's defaults.
"""

import importlib.util
import pathlib

import nbformat
import pytest

pytest.importorskip("jupytext")
pytest.importorskip("nbclient")

NOTEBOOK_DIR = pathlib.Path(__file__).resolve().parent.parent / "notebooks"
_spec = importlib.util.spec_from_file_location("notebook_build", NOTEBOOK_DIR / "build.py")
build = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(build)

SOURCES = build.sources()
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


def _run_install_cell(monkeypatch, cwd: pathlib.Path, installed: bool) -> list[list[str]]:
    """Run the install cell in ``cwd`` as in a kernel where jaxkin is (not) importable; the pip
    commands it would run, recorded instead of run."""
    import importlib.util as util
    import subprocess

    real_find_spec = util.find_spec
    commands: list[list[str]] = []

    def find_spec(name, *args):
        return real_find_spec(name, *args) if installed or name != "jaxkin" else None

    monkeypatch.setattr(util, "find_spec", find_spec)
    monkeypatch.setattr(subprocess, "run", lambda cmd, **kw: commands.append(cmd))
    monkeypatch.chdir(cwd)
    exec(compile(build.INSTALL_CELL, "install cell", "exec"), {})
    return commands


def test_install_cell_installs_from_the_checkout_or_a_wheel_never_by_name(monkeypatch, tmp_path):
    # where jaxkin imports: nothing
    assert _run_install_cell(monkeypatch, tmp_path, installed=True) == []
    # a fresh machine with the notebook alone: no checkout, no wheel, so it says what it needs
    # (installing "jaxkin" by name from the registry would get someone else's package)
    with pytest.raises(RuntimeError, match=r"python3 -m build --wheel.*jaxkin-\*\.whl"):
        _run_install_cell(monkeypatch, tmp_path, installed=False)
    # the wheel the user put beside the notebook
    wheel = tmp_path / "jaxkin-0.1.0-py3-none-any.whl"
    wheel.write_bytes(b"")
    (cmd,) = _run_install_cell(monkeypatch, tmp_path, installed=False)
    assert cmd[-1] == f"jaxkin[notebooks] @ {wheel.as_uri()}", cmd
    # a checkout, found from a folder below it (not only from notebooks/), past another project
    checkout = tmp_path / "checkout"
    deep = checkout / "other" / "notebooks"
    deep.mkdir(parents=True)
    (checkout / "pyproject.toml").write_text('[project]\nname = "jaxkin"\n')
    (checkout / "other" / "pyproject.toml").write_text('[project]\nname = "other"\n')
    (cmd,) = _run_install_cell(monkeypatch, deep, installed=False)
    assert cmd[-1] == f"jaxkin[notebooks] @ {checkout.as_uri()}", cmd


@pytest.fixture(scope="module")
def kernel():
    """One kernel for the notebooks of this file (see the module's docstring)."""
    with build.kernel() as shared:
        yield shared


def test_a_notebook_finds_nothing_of_the_one_before_it_in_the_kernel(kernel):
    def notebook(code: str) -> nbformat.NotebookNode:
        return nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(code)])

    # what a fresh kernel had, recorded by build.RESET_CELL before the first notebook
    fresh = "sys.modules['fresh_kernel_state']"
    leave = f"""\
import os, sys, jax, matplotlib, numpy as np
left_behind = 1
jax.config.update("jax_enable_x64", not {fresh}.x64)
np.set_printoptions(precision=2)
matplotlib.rcParams["lines.linewidth"] = 9.0
os.chdir("..")"""
    find_nothing = f"""\
import os, sys, jax, matplotlib, numpy as np
assert "left_behind" not in globals()
assert jax.config.jax_enable_x64 == {fresh}.x64
assert np.get_printoptions()["precision"] != 2
assert matplotlib.rcParams["lines.linewidth"] != 9.0
assert os.getcwd() == {str(NOTEBOOK_DIR)!r}"""
    build.execute(notebook(leave), kernel)
    build.execute(notebook(find_nothing), kernel)


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: p.stem)
def test_notebook_matches_its_source_runs_and_holds_its_outputs(path, kernel):
    committed = nbformat.read(path.with_suffix(".ipynb"), as_version=4)
    source = build.from_source(path)
    assert build.cells(committed) == build.cells(source), REBUILD.format(path.stem)

    # raises CellExecutionError on the first failing cell, and nbclient's TimeoutError on a cell
    # still running after build.CELL_TIMEOUT_S (a watchdog for a hang, not a speed check: speed
    # is measured in bench/, never asserted as wall-clock time)
    executed = build.execute(source, kernel)

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
