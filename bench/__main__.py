"""``python3 -m bench [--quick] [--write-readme]``: the whole Jacobian comparison (see
bench/README.md); ``python3 -m bench.scale`` is the 10-million-configuration streaming run."""

from __future__ import annotations

from .jacobians import main
from .report import exit_without_teardown

if __name__ == "__main__":
    exit_without_teardown(main())
