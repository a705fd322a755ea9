"""The documentation site builds in strict mode, and the Python examples on its pages run.

The build is the one command of docs/README.md (Sphinx with ``-W``: a broken cross-reference, a
docstring that does not parse, a missing page or figure fails it), run into a temporary folder
in a subprocess. It needs the ``docs`` extra and is skipped, saying so, where that is not
installed. The pages' ``python`` code blocks need only jaxkin and run everywhere.
"""

from __future__ import annotations

import html as html_module
import importlib.util
import os
import pathlib
import re
import subprocess
import sys

import jax
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
DOCS_EXTRA = ("sphinx", "myst_nb", "furo")


def _missing_docs_extra() -> list[str]:
    return [name for name in DOCS_EXTRA if importlib.util.find_spec(name) is None]


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> pathlib.Path:
    missing = _missing_docs_extra()
    if missing:
        pytest.skip(
            f"the docs extra is not installed (no {', '.join(missing)}): "
            "python3 -m pip install -e '.[docs]' builds the site here"
        )
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONWARNINGS": "ignore"}
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-c", "docs", ".", str(out)]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, f"strict docs build failed:\n{proc.stdout}\n{proc.stderr}"
    return out


def test_strict_build_has_every_page(site):
    pages = [DOCS / "index.md", *sorted(DOCS.glob("*.md")), *sorted(DOCS.glob("api/*.md"))]
    pages = [p for p in pages if p.name != "README.md"]
    pages += [*sorted(ROOT.glob("notebooks/*.ipynb")), ROOT / "notebooks/README.md"]
    pages += sorted(ROOT.glob("bench/*.md"))
    expected = {p.relative_to(ROOT).with_suffix(".html") for p in pages}
    missing = sorted(str(p) for p in expected if not (site / p).is_file())
    assert not missing, missing
    assert "docs/index.html" in (site / "index.html").read_text(encoding="utf-8")


def test_api_reference_comes_from_the_docstrings(site):
    html = (site / "docs/api/kinematics.html").read_text(encoding="utf-8")
    # the function's entry, its docstring's first sentence and its example, rendered
    assert 'id="jaxkin.jacobians.geometric_jacobian"' in html
    text = _text(html)
    assert "Built column by column from one forward pass" in text
    assert ">>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))" in text
    # a re-exported name in a docstring links to where it is documented
    analysis = (site / "docs/api/analysis.html").read_text(encoding="utf-8")
    assert 'href="kinematics.html#jaxkin.jacobians.geometric_jacobian"' in analysis


def _text(html: str) -> str:
    """The page's text: tags dropped (syntax highlighting splits code into spans), unescaped."""
    return html_module.unescape(re.sub(r"<[^>]+>", "", html))


def test_cli_reference_is_the_parser_help(site):
    from jaxkin.cli import build_parser

    html = _text((site / "docs/cli.html").read_text(encoding="utf-8"))
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices
    assert {"robots", "jacobian", "velocities"} <= set(commands)
    assert "usage: jaxkin [-h]" in html
    for name in commands:
        assert f"usage: jaxkin {name}" in html, name


def test_conventions_figure_is_drawn(site):
    html = (site / "docs/conventions.html").read_text(encoding="utf-8")
    images = re.findall(r'<img[^>]+src="([^"]+conventions_figure[^"]*\.png)"', html)
    assert images, "no conventions figure on the page"
    png = (site / "docs" / images[0]).resolve()
    assert png.is_file() and png.stat().st_size > 10_000, png


def _python_blocks(page: pathlib.Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", page.read_text(encoding="utf-8"), re.S | re.M)


PAGES_WITH_CODE = [p for p in sorted(DOCS.rglob("*.md")) if _python_blocks(p)]


def test_getting_started_has_an_example():
    assert DOCS / "getting_started.md" in PAGES_WITH_CODE


@pytest.mark.parametrize("page", PAGES_WITH_CODE, ids=lambda p: p.name)
def test_page_examples_run(page):
    # user code, as the docstring examples: JAX's default rank promotion, not the suite's "raise"
    with jax.numpy_rank_promotion("allow"):
        for block in _python_blocks(page):
            exec(compile(block, str(page), "exec"), {})


# Documented elsewhere: the command line by its parser's help (docs/cli.md); __main__ runs it.
NOT_ON_API_PAGES = {"jaxkin.__main__", "jaxkin.cli"}


def test_every_public_module_has_an_api_page():
    import pkgutil

    import jaxkin

    modules = {
        m.name
        for m in pkgutil.walk_packages(jaxkin.__path__, prefix="jaxkin.")
        if not m.name.rpartition(".")[2].startswith("_")
    }
    pages = "".join(p.read_text(encoding="utf-8") for p in DOCS.glob("api/*.md"))
    documented = set(re.findall(r"^\.\. automodule:: (\S+)$", pages, re.M))
    missing = sorted(modules - documented - NOT_ON_API_PAGES)
    assert not missing, f"add these to a page in docs/api/: {missing}"
    assert documented <= modules, sorted(documented - modules)
