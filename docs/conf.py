"""Sphinx configuration of jaxkin's documentation site (see docs/README.md).

The source directory is the repository root, so that the site renders notebooks/*.ipynb and
bench/*.md where they live (no copies); ``include_patterns`` picks the files that are pages.
Build: ``python -m sphinx -W --keep-going -c docs . build/site`` from the repository root.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import os
import pathlib

from docutils import nodes
from sphinx import addnodes
from sphinx.util.docutils import SphinxDirective

import jaxkin

project = "jaxkin"
author = "jaxkin contributors"
copyright = "jaxkin contributors"
release = version = jaxkin.__version__

root_doc = "docs/index"
include_patterns = ["docs/**", "notebooks/*.ipynb", "notebooks/README.md", "bench/*.md"]
exclude_patterns = ["docs/README.md", "build/**", "**/.ipynb_checkpoints"]

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    # MathJax 3 shipped in the package and copied into _static/mathjax: equations render offline
    "sphinx-mathjax-offline",
    "matplotlib.sphinxext.plot_directive",
    "myst_nb",
]

# Docstrings: Google-style sections ("Args:", "Returns:", "Raises:") with reST markup inside.
napoleon_google_docstring = True
napoleon_numpy_docstring = False
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
# Signatures come from annotations; jaxkin has no "# type: (...) -> ..." comments, which autodoc
# would otherwise look for by reading and parsing each function's source again.
autodoc_use_type_comments = False

# Strict: every cross-reference must resolve (run with -W). Types from other libraries are not
# documented here (the build has no network for intersphinx), so only they are exempt.
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(jax|jnp|np|numpy|optax|matplotlib|mpl_toolkits|hypothesis|argparse)(\..*)?"),
    (r"py:.*", r"(typing|collections|pathlib|os|io|types|dataclasses|enum|abc)(\..*)?"),
    (r"py:class", r"(Any|Callable|Iterable|Iterator|Mapping|Sequence|NamedTuple|Path|TextIO)"),
    (r"py:class", r"(int|float|str|bool|bytes|dict|list|tuple|object|type|None|slice)"),
    (r"py:class", r"(Array|ArrayLike|PyTree|Module|ndarray|dtype)"),
    (r"py:(exc|class)", r"(ValueError|TypeError|ImportError|RuntimeError|KeyError|Exception)"),
    (r"py:(exc|class)", r"(UserWarning|Warning|OSError|FileNotFoundError)"),
]

# Quotes stay as written: "rpy" in prose is what a user types (and copies), not “rpy”. (Also
# spares the build docutils' smart-quotes pass over every page, about a second.)
smartquotes = False

# Notebooks are rendered with the outputs committed in them, never executed here.
nb_execution_mode = "off"
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
myst_heading_anchors = 3

# The conventions figure is drawn by docs/conventions_figure.py at build time.
plot_basedir = str(pathlib.Path(__file__).resolve().parent)
plot_include_source = False
plot_html_show_source_link = False
plot_html_show_formats = False
plot_formats = [("png", 110)]
plot_rcparams = {"savefig.bbox": "tight"}

html_theme = "furo"
html_title = f"jaxkin {version}"
html_static_path: list[str] = []


def _public() -> dict[int, str]:
    """``id(object) -> "jaxkin.name"`` for the functions and classes the package re-exports
    (``jk.fk``): they are documented once, under that name, on the first API page."""
    return {
        id(obj): f"jaxkin.{name}"
        for name, obj in vars(jaxkin).items()
        if not name.startswith("_") and (inspect.isfunction(obj) or inspect.isclass(obj))
    }


PUBLIC = _public()


def _lookup(target: str, module: str | None):
    """``(object, documented name)`` for a dotted ``target``, looked up as Python would: from
    ``jaxkin`` when it starts with ``jaxkin.``, else in the namespace of ``module``, the module
    whose docstring refers to it; ``(None, None)`` when no such object exists. The documented
    name is the public name (``jaxkin.fk``) or else the home ``module.qualname`` of the innermost
    class or function on the path, plus the rest (``jaxkin.Robot.tip_frame`` stays itself,
    ``jaxkin.jacobians.FrameJacobian.J`` is documented where it is defined)."""
    parts = target.split(".")
    if parts[0] == "jaxkin":
        obj, parts = jaxkin, parts[1:]
    elif module:
        obj = importlib.import_module(module)
    else:
        return None, None
    name = None
    for i, part in enumerate(parts):
        obj = getattr(obj, part, None)
        if obj is None:
            return None, None
        home, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
        if id(obj) in PUBLIC:
            name = ".".join([PUBLIC[id(obj)], *parts[i + 1 :]])
        elif isinstance(home, str) and isinstance(qualname, str) and home.startswith("jaxkin"):
            outer, *inner = qualname.split(".")
            public = PUBLIC.get(id(getattr(importlib.import_module(home), outer, None)))
            name = ".".join([public or f"{home}.{outer}", *inner, *parts[i + 1 :]])
    return obj, name


def _home_module(node) -> str | None:
    """The module a docstring's reference is read in: the home module of the innermost entry
    that holds it (``jaxkin.fk``'s docstring speaks in ``jaxkin.kinematics``), else the page's."""
    module = node.get("py:module")
    entry = node.parent
    while entry is not None and not isinstance(entry, addnodes.desc):
        entry = entry.parent
    signature = entry and next(
        (c for c in entry.children if isinstance(c, addnodes.desc_signature)), None
    )
    if not signature or not signature.get("module"):
        return module
    obj = importlib.import_module(signature["module"])
    for part in signature.get("fullname", "").split("."):
        obj = getattr(obj, part, None)
        home = getattr(obj, "__module__", None)
        if isinstance(home, str) and home.startswith("jaxkin"):
            module = home
    return module


def _resolve_by_import(app, env, node, contnode):
    """Resolve what a reader of the source would: a name in the docstring's home module or a
    re-export links to where it is documented (``geometric_jacobian`` in ``jaxkin.analysis``
    and ``jaxkin.jacobians.geometric_jacobian`` to ``jaxkin.geometric_jacobian``; a name
    imported into the module, such as ``JaxkinPrecisionWarning`` in ``jaxkin.build``, likewise).
    A name that exists but has no entry here (a private helper such as ``_chunking``, a constant
    outside ``__all__``) is rendered as code, unlinked. A name that does not exist stays a
    missing reference, which fails the strict build."""
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~.")
    try:
        obj, name = _lookup(target, _home_module(node))
    except ImportError:
        return None
    if obj is None:
        return None
    if name and name != target:
        node["reftarget"] = name
        found = env.get_domain("py").resolve_xref(
            env, node["refdoc"], app.builder, node["reftype"], name, node, contnode
        )
        if found is not None:
            return found
    return contnode


def _skip_public_on_module_pages(app, what, name, obj, skip, options):
    """A module page leaves out what the package re-exports: ``jaxkin.fk`` is documented once,
    on the public API page, not again as ``jaxkin.kinematics.fk`` (nor as
    ``jaxkin.ik.sample_configurations``, which ``jaxkin.ik`` imports and lists)."""
    if what == "module" and id(obj) in PUBLIC:
        return True
    return None


def _drop_field_aliases(app, what, name, obj, options, lines):
    """NamedTuple fields: drop Python's "Alias for field number N" (says nothing to a reader)."""
    if len(lines) == 1 and lines[0].startswith("Alias for field number"):
        lines.clear()


def _redirect_root(app, exception):
    """The root page lives at docs/index.html: write index.html pointing there."""
    if exception is None and app.builder.format == "html":
        html = '<meta http-equiv="refresh" content="0; url=docs/index.html">\n'
        pathlib.Path(app.outdir, "index.html").write_text(html, encoding="utf-8")


class CliHelp(SphinxDirective):
    """``{jaxkin-cli-help}``: what ``jaxkin --help`` and ``jaxkin COMMAND --help`` print, taken
    from ``jaxkin.cli.build_parser()`` at build time (80 columns), one section per command."""

    def run(self):
        from jaxkin.cli import build_parser

        saved = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = "80"
        try:
            parser = build_parser()
            commands = next(
                a.choices for a in parser._actions if isinstance(a, argparse._SubParsersAction)
            )
            helps = [("jaxkin", parser.format_help())]
            helps += [(f"jaxkin {name}", sub.format_help()) for name, sub in commands.items()]
        finally:
            if saved is None:
                del os.environ["COLUMNS"]
            else:
                os.environ["COLUMNS"] = saved
        out = []
        for title, text in helps:
            section = nodes.section(ids=[nodes.make_id(title)])
            section += nodes.title(text=title)
            section += nodes.literal_block(text, text, language="text")
            out.append(section)
        return out


def setup(app):
    # The bundled MathJax's SVG output (the extension sets tex-chtml.js, whose web fonts browsers
    # may refuse to load from file:// pages); a path relative to _static/, so never a CDN.
    app.config.mathjax_path = "mathjax/tex-svg.js"
    app.add_directive("jaxkin-cli-help", CliHelp)
    app.connect("missing-reference", _resolve_by_import)
    app.connect("autodoc-skip-member", _skip_public_on_module_pages)
    app.connect("autodoc-process-docstring", _drop_field_aliases)
    app.connect("build-finished", _redirect_root)
    return {"parallel_read_safe": True}
