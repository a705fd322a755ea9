"""The documentation site builds in strict mode, and the Python examples on its pages run.

The build is the one command of docs/README.md (Sphinx with ``-W``: a broken cross-reference, a
docstring that does not parse, a missing page or figure fails it), run into a temporary folder
in a subprocess. It needs the ``docs`` extra and is skipped, saying so, where that is not
installed. The pages' ``python`` code blocks need only jaxkin and run everywhere.
"""

from __future__ import annotations

import functools
import html as html_module
import importlib.util
import json
import os
import pathlib
import re
import subprocess
import sys
import textwrap

import jax
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
DOCS_EXTRA = ("sphinx", "myst_nb", "furo", "sphinx-mathjax-offline", "hypothesis", "matplotlib")


def _missing_docs_extra() -> list[str]:
    return [name for name in DOCS_EXTRA if importlib.util.find_spec(name) is None]


# Runs in the subprocess: first records which top-level modules importing the API pages' modules
# loads beyond what importing the required distributions' modules loads (the docs extra's test
# below), in a fresh interpreter, then builds the site there (``python -m sphinx ARGS``), which
# would import all of them again in an interpreter of its own.
_BUILD = textwrap.dedent(
    """
    import importlib, json, sys
    required, modules, record, argv = json.loads(sys.stdin.read())
    for m in required:
        try:
            importlib.import_module(m)
        except Exception:
            pass
    before = {n.split(".")[0] for n in sys.modules}
    for m in modules:
        importlib.import_module(m)
    with open(record, "w", encoding="utf-8") as f:
        json.dump(sorted({n.split(".")[0] for n in sys.modules} - before), f)
    from sphinx.cmd.build import main
    sys.exit(main(argv))
    """
)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> pathlib.Path:
    """The site, built by the command of docs/README.md in a subprocess, which first records
    what the API pages import (:func:`api_page_imports`)."""
    missing = _missing_docs_extra()
    if missing:
        pytest.skip(
            f"the docs extra is not installed (no {', '.join(missing)}): "
            "python3 -m pip install -e '.[docs]' builds the site here"
        )
    work = tmp_path_factory.mktemp("docs")
    out, record = work / "site", work / "api_page_imports.json"
    argv = ["-W", "--keep-going", "-q", "-c", "docs", ".", str(out)]
    # (Python 3.10 has no tomllib to read pyproject.toml: nothing recorded, the test skips)
    imports = [_required_modules(), _api_page_modules()] if _has_tomllib() else [[], []]
    request = [*imports, str(record), argv]
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONWARNINGS": "ignore", "JAX_PLATFORMS": "cpu"}
    proc = subprocess.run(
        [sys.executable, "-c", _BUILD],
        input=json.dumps(request),
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, f"strict docs build failed:\n{proc.stdout}\n{proc.stderr}"
    return out


@pytest.fixture(scope="module")
def api_page_imports(site) -> list[str]:
    """The top-level modules that importing the modules of the API pages loads, beyond what
    importing those of jaxkin's required distributions and the docs extra's loads (recorded by
    the build's interpreter before it builds)."""
    return json.loads((site.parent / "api_page_imports.json").read_text(encoding="utf-8"))


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
    html = (site / "docs/api/public.html").read_text(encoding="utf-8")
    # the function's entry, under the name users call it by, its docstring's first sentence and
    # its example, rendered
    assert 'id="jaxkin.geometric_jacobian"' in html
    text = _text(html)
    assert "Built column by column from one forward pass" in text
    assert ">>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))" in text
    # a name in a docstring, re-exported or in the docstring's module, links to its entry
    analysis = (site / "docs/api/analysis.html").read_text(encoding="utf-8")
    assert 'href="public.html#jaxkin.geometric_jacobian"' in analysis
    assert 'href="#jaxkin.geometric_jacobian"' in html


def _api_pages() -> list[str]:
    """The API pages (``api/NAME``) in the order of the tables of contents in docs/index.md."""
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    return re.findall(r"^(api/\w+)$", index, re.M)


def _entries(html: str) -> list[str]:
    """The ids of the documented objects on a page (functions, classes, members), in order."""
    return re.findall(r'<dt class="sig sig-object py" id="([^"]+)"', html)


def _object(dotted: str):
    """The object a documented id names, imported as Python would; None where there is none."""
    import importlib

    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for part in parts[i:]:
            obj = getattr(obj, part, None)
        return obj
    return None


def _public_names() -> dict[str, object]:
    """What ``import jaxkin as jk`` offers to call: the re-exported functions and classes."""
    import inspect

    import jaxkin

    return {
        name: obj
        for name, obj in vars(jaxkin).items()
        if not name.startswith("_") and (inspect.isfunction(obj) or inspect.isclass(obj))
    }


def test_api_reference_starts_with_the_public_names_each_documented_once(site):
    import inspect

    pages = _api_pages()
    assert pages and pages[0] == "api/public", pages
    entries = {p: _entries((site / f"docs/{p}.html").read_text(encoding="utf-8")) for p in pages}
    public = _public_names()
    # the first entry is one a user calls: jk.fk, not a building block such as ForwardPass
    first = entries[pages[0]][0]
    assert first.startswith("jaxkin.") and first.count(".") == 1, first
    assert inspect.isfunction(public.get(first.removeprefix("jaxkin."))), first
    # every public name is on the first page under the name users call it by
    missing = sorted(n for n in public if f"jaxkin.{n}" not in entries[pages[0]])
    assert not missing, f"add these to docs/api/public.md: {missing}"
    # no function or class is documented twice (jaxkin.ik lists sample_configurations, which
    # is documented once, as jaxkin.sample_configurations)
    where: dict[int, list[str]] = {}
    for ids in entries.values():
        for dotted in ids:
            obj = _object(dotted)
            if inspect.isfunction(obj) or inspect.isclass(obj):
                where.setdefault(id(obj), []).append(dotted)
    twice = sorted(ids for ids in where.values() if len(ids) > 1)
    assert not twice, twice
    # the modules beyond the namespace are there (the IK's implicit derivatives included)
    every = [dotted for ids in entries.values() for dotted in ids]
    assert "jaxkin.ik_gradients.solution_tangent" in every
    assert "jaxkin.robots.load" in every


def test_api_reference_shows_no_private_name(site):
    for page in _api_pages():
        html = (site / f"docs/{page}.html").read_text(encoding="utf-8")
        private = [e for e in _entries(html) if any(p.startswith("_") for p in e.split("."))]
        assert not private, (page, private)
        # nor in the text: a docstring that sends the reader to jaxkin._checks.check_q
        mentions = sorted(set(re.findall(r"jaxkin\._\w+(?:\.\w+)*", _text(html))))
        assert not mentions, (page, mentions)


def test_site_loads_no_script_from_the_network_and_bundles_mathjax(site):
    remote = re.compile(r"<(?:script|img|iframe)\b[^>]*\bsrc=\"(?:https?:)?//", re.I)
    with_math = []
    for page in sorted(site.rglob("*.html")):
        html = page.read_text(encoding="utf-8")
        found = remote.findall(html)
        assert not found, (page.relative_to(site), found)
        if 'class="math' in html:
            with_math.append(page)
    # the chapter's equations (notebooks 01-03) are on the site, and each page with math loads
    # the MathJax shipped with it
    assert len(with_math) >= 3, with_math
    for page in with_math:
        html = page.read_text(encoding="utf-8")
        scripts = re.findall(r'<script[^>]*src="([^"]*mathjax[^"]*\.js)[^"]*"', html)
        assert scripts, f"{page.relative_to(site)} has math but loads no MathJax"
        for src in scripts:
            path = (page.parent / src.split("?")[0]).resolve()
            assert path.is_file() and path.stat().st_size > 100_000, (page, src)
            assert site.resolve() in path.parents, (page, src)


def test_equations_render_offline_in_headless_chromium(site):
    import shutil

    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("no chromium binary (Debian: apt-get install chromium)")
    page = site / "notebooks/01_analytical_jacobian.html"
    n_math = page.read_text(encoding="utf-8").count('class="math notranslate')
    offline = "--host-resolver-rules=MAP * ~NOTFOUND"  # no host name resolves: no network
    cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", offline]
    cmd += ["--virtual-time-budget=20000", "--dump-dom", page.as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    dom = proc.stdout
    rendered = len(re.findall(r"<mjx-container\b[^>]*>\s*<svg\b", dom))
    assert rendered >= n_math > 0, (rendered, n_math, proc.stderr[-2000:])
    assert '<g data-mml-node="merror"' not in dom  # MathJax's mark of a formula it cannot read


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


def _normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _required(names: list[str]) -> set[str]:
    """The distributions ``names`` (requirement strings) need, with all they need in turn as
    installed here (requirements behind an extra or another platform's marker left out)."""
    from importlib import metadata

    from packaging.requirements import Requirement

    found: set[str] = set()
    todo = [Requirement(n) for n in names]
    while todo:
        req = todo.pop()
        name = _normalise(req.name)
        if name in found or (req.marker is not None and not req.marker.evaluate({"extra": ""})):
            continue
        found.add(name)
        try:
            todo += [Requirement(r) for r in metadata.requires(req.name) or []]
        except metadata.PackageNotFoundError:
            pass
    return found


@functools.cache
def _owners() -> dict[str, list[str]]:
    """``{top-level module: [distributions]}`` of what is installed (read once: it reads every
    installed distribution's file list)."""
    from importlib import metadata

    return metadata.packages_distributions()


def _has_tomllib() -> bool:
    return importlib.util.find_spec("tomllib") is not None


def _direct_requirements() -> list[str]:
    """The requirement strings of jaxkin's dependencies and of its docs extra."""
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    return project["dependencies"] + project["optional-dependencies"]["docs"]


def _required_modules() -> list[str]:
    """The top-level modules of the distributions :func:`_direct_requirements` names."""
    owners = _owners()
    direct = _direct_requirements()
    direct_names = {_normalise(re.split(r"[\s\[<>=!~;]", r, maxsplit=1)[0]) for r in direct}
    return sorted(n for n, dists in owners.items() if direct_names & {_normalise(d) for d in dists})


def _api_page_modules() -> list[str]:
    """The modules the API pages document (``.. automodule::``)."""
    pages = "".join(p.read_text(encoding="utf-8") for p in DOCS.glob("api/*.md"))
    return sorted(set(re.findall(r"^\.\. automodule:: (\S+)$", pages, re.M)))


def test_docs_extra_holds_what_the_api_pages_import(api_page_imports):
    # `pip install -e ".[docs]"` then the build of docs/README.md: autodoc imports every module
    # on the API pages (jaxkin.testing imports hypothesis), so each distribution that importing
    # them loads, beyond what importing the required ones loads, must be jaxkin's own dependency
    # or the docs extra's, directly or through theirs. The build's interpreter records the
    # imports in a fresh interpreter before it builds (the ``site`` fixture).
    pytest.importorskip("tomllib")
    allowed = _required(_direct_requirements())
    owners = _owners()
    loaded = {_normalise(d) for name in api_page_imports for d in owners.get(name, [])}
    missing = sorted(loaded - allowed - {"jaxkin"})
    assert not missing, f"add to the docs extra in pyproject.toml: {missing}"
