"""The ``>>>`` examples in jaxkin's docstrings run and print what they show.

Every module of the package is searched (``pkgutil.walk_packages``); each module's examples run
in the suite's configuration (float64, warnings as errors) except rank promotion, which is JAX's
default ("allow") there: examples are user code (``qs >= robot.lower`` broadcasts a bound over a
batch), and the suite's strict setting is meant for the library's own arithmetic, which the other
tests cover. The totals are pinned from below so that examples cannot disappear unnoticed: raise
them when you add some.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import jax
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


def _doctests(name: str) -> list[doctest.DocTest]:
    """The docstrings with examples among what module ``name`` defines (the finder leaves out
    names a module imports: they are tested at home)."""
    module = importlib.import_module(name)
    return [t for t in doctest.DocTestFinder().find(module, name) if t.examples]


MODULES = _module_names()
WITH_EXAMPLES = [name for name in MODULES if _doctests(name)]


@pytest.mark.parametrize("name", WITH_EXAMPLES)
def test_docstring_examples_run(name):
    runner = doctest.DocTestRunner(optionflags=OPTIONFLAGS)
    report: list[str] = []
    with jax.numpy_rank_promotion("allow"):
        for test in _doctests(name):
            runner.run(test, out=report.append)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, "".join(report)


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
