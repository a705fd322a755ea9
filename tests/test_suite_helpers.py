"""The suite's own helpers do what the suite's time relies on."""

from __future__ import annotations

import sys

from _oracle_modules import lazy_module


def test_lazy_module_is_not_imported_by_what_collection_reads(tmp_path, monkeypatch):
    """pytest reads private and dunder names of every module-level object while it collects
    (``__wrapped__``, ``_pytestfixturefunction``, ...): those must not import the module; the
    first public name does."""
    (tmp_path / "lazy_probe_module.py").write_text("VALUE = 7\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "lazy_probe_module", raising=False)
    probe = lazy_module("lazy_probe_module")
    for name in ("__wrapped__", "_pytestfixturefunction", "__test__", "_private"):
        assert getattr(probe, name, None) is None
    assert "lazy_probe_module" not in sys.modules
    assert probe.VALUE == 7
    assert "lazy_probe_module" in sys.modules
