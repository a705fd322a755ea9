"""The ``>>>`` examples in jaxkin's docstrings run and print what they show.

Every module of the package is searched (``pkgutil.walk_packages``); each module's examples run
in the suite's configuration (float64, warnings as errors) except rank promotion, which is JAX's
default ("allow") there: examples are user code (``qs >= robot.lower`` broadcasts a bound over a
batch), and the suite's strict setting is meant for the library's own arithmetic, which the other
tests cover. The totals are pinned from below so that examples cannot disappear unnoticed: raise
them when you add some.

The examples of every module run in one fresh interpreter (a module fixture; each module's test
reads its report), which inherits the suite's ``XLA_FLAGS`` (LLVM's optimisation off,
tests/conftest.py: the examples' time is mostly compiling). It is
configured as the suite is: float64, and warnings raised as errors (but the persistent
compilation cache's, as in tests/conftest.py, and SyntaxWarning, as in pyproject.toml).
"""

from __future__ import annotations

import doctest
import functools
import importlib
import json
import pkgutil
import subprocess
import sys
import textwrap

import pytest

import jaxkin

# Counted when this test was written: 3 docstrings with 12 examples before; then fk, fk_all,
# geometric_jacobian, jacobian_fwd/rev, analytical_jacobian, twist, point_velocity, the
# derivatives, from_dh and from_joints got theirs. Docstrings with examples; ">>>" statements.
# Issue 21: 32 and 138 on main then, plus 16 docstrings with 85 for the public functions that
# had none (analysis, inverse velocity, representations, change_reference, classify_twist,
# pose_error, to_urdf).
MIN_DOCSTRINGS = 48
MIN_EXAMPLES = 223
# Issue 21: at least 30 of the functions ``import jaxkin as jk`` offers (jk.fk, jk.solve_ik, ...)
# show a call that runs (19 did then).
MIN_PUBLIC_FUNCTIONS_WITH_EXAMPLES = 30

# Import-time side effects only (the command line's entry point); it holds no docstring examples.
SKIP_MODULES = {"jaxkin.__main__"}

OPTIONFLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def _module_names() -> list[str]:
    names = ["jaxkin"]
    for info in pkgutil.walk_packages(jaxkin.__path__, prefix="jaxkin."):
        if info.name not in SKIP_MODULES:
            names.append(info.name)
    return sorted(names)


@functools.cache
def _doctests(name: str) -> tuple[doctest.DocTest, ...]:
    """The docstrings with examples among what module ``name`` defines (the finder leaves out
    names a module imports: they are tested at home). Searched once per module: collection and
    :func:`test_number_of_examples` read the same."""
    module = importlib.import_module(name)
    return tuple(t for t in doctest.DocTestFinder().find(module, name) if t.examples)


MODULES = _module_names()
WITH_EXAMPLES = [name for name in MODULES if _doctests(name)]


# Runs in the subprocess: {module: [examples failed, doctest's report]} for the modules read from
# stdin, each module's examples in turn, as the suite runs tests (float64; warnings are errors,
# except those pyproject.toml and tests/conftest.py let pass).
_RUNNER = textwrap.dedent(
    """
    import doctest, importlib, json, sys, warnings
    import jax
    jax.config.update("jax_enable_x64", True)
    names, optionflags, ignored = json.loads(sys.stdin.read())
    modules = [importlib.import_module(name) for name in names]
    warnings.simplefilter("error")
    for message in ignored:
        warnings.filterwarnings("ignore", message=message, category=UserWarning)
    warnings.filterwarnings("ignore", category=SyntaxWarning)
    reports = {}
    with jax.numpy_rank_promotion("allow"):
        for name, module in zip(names, modules):
            runner = doctest.DocTestRunner(optionflags=optionflags)
            report = []
            for test in doctest.DocTestFinder().find(module, name):
                if test.examples:
                    runner.run(test, out=report.append)
            reports[name] = [runner.summarize(verbose=False).failed, "".join(report)]
    print("REPORTS " + json.dumps(reports))
    """
)
# What tests/conftest.py lets pass (a persistent-cache entry read while another process writes it).
IGNORED_WARNINGS = [
    f"Error {verb} persistent compilation cache entry" for verb in ("reading", "writing")
]


@pytest.fixture(scope="module")
def reports(request) -> dict[str, list]:
    """The reports of the modules whose test this run selected (``-k``), from one subprocess."""
    names = [
        item.callspec.params["name"]
        for item in request.session.items
        if getattr(item, "originalname", None) == "test_docstring_examples_run"
    ]
    proc = subprocess.run(
        [sys.executable, "-c", _RUNNER],
        input=json.dumps([names or WITH_EXAMPLES, OPTIONFLAGS, IGNORED_WARNINGS]),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-6000:]
    return json.loads(proc.stdout.rsplit("REPORTS ", 1)[1])


@pytest.mark.parametrize("name", WITH_EXAMPLES)
def test_docstring_examples_run(name, reports):
    failed, report = reports[name]
    assert failed == 0, report


def test_number_of_examples():
    tests = [t for name in MODULES for t in _doctests(name)]
    n_examples = sum(len(t.examples) for t in tests)
    assert len(tests) >= MIN_DOCSTRINGS, sorted(t.name for t in tests)
    assert n_examples >= MIN_EXAMPLES, sorted(t.name for t in tests)


def test_public_functions_have_examples():
    """Counted on the re-exported functions (the first API page), each by its own docstring."""
    import inspect

    public = {
        name: obj
        for name, obj in vars(jaxkin).items()
        if not name.startswith("_") and inspect.isfunction(obj)
    }
    finder = doctest.DocTestFinder(recurse=False)
    with_examples = sorted(
        name for name, obj in public.items() if any(t.examples for t in finder.find(obj, name))
    )
    without = sorted(set(public) - set(with_examples))
    assert len(with_examples) >= MIN_PUBLIC_FUNCTIONS_WITH_EXAMPLES, f"none in: {without}"
