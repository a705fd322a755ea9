"""Sphinx configuration of jaxkin's documentation site (see docs/README.md).

The source directory is the repository root, so that the site renders notebooks/*.ipynb and
bench/*.md where they live (no copies); ``include_patterns`` picks the files that are pages.
Build: ``python -m sphinx -W --keep-going -c docs . build/site`` from the repository root.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pathlib

from docutils import nodes
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
    "matplotlib.sphinxext.plot_directive",
    "myst_nb",
]

# Docstrings: Google-style sections ("Args:", "Returns:", "Raises:") with reST markup inside.
napoleon_google_docstring = True
napoleon_numpy_docstring = False
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "signature"
autodoc_preserve_defaults = True

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


def _lookup(target: str, module: str | None):
    """``(object, documented name)`` for a dotted ``target``, looked up as Python would: from
    ``jaxkin`` when it starts with ``jaxkin.``, else in the namespace of the module whose
    docstring refers to it; ``(None, None)`` when no such object exists. The documented name is
    the home ``module.qualname`` of the innermost class or function on the path plus the rest
    (``jaxkin.Robot.tip_frame`` -> ``jaxkin.model.Robot.tip_frame``)."""
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
        if isinstance(home, str) and isinstance(qualname, str) and home.startswith("jaxkin"):
            name = ".".join([home, qualname, *parts[i + 1 :]])
    return obj, name


def _resolve_by_import(app, env, node, contnode):
    """Resolve what a reader of the source would: a re-export (``jaxkin.geometric_jacobian`` is
    documented as ``jaxkin.jacobians.geometric_jacobian``) or a name imported into the module
    (``JaxkinPrecisionWarning`` in ``jaxkin.build``) links to where it is documented. A name that
    exists but has no entry here (a private helper such as ``_chunking``, a constant outside
    ``__all__``) is rendered as code, unlinked. A name that does not exist stays a missing
    reference, which fails the strict build."""
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~.")
    try:
        obj, name = _lookup(target, node.get("py:module"))
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
    app.add_directive("jaxkin-cli-help", CliHelp)
    app.connect("missing-reference", _resolve_by_import)
    app.connect("autodoc-process-docstring", _drop_field_aliases)
    app.connect("build-finished", _redirect_root)
    return {"parallel_read_safe": True}
