"""``python3 -m bench [--quick]``: run every benchmark (today: the Jacobian one)."""

from __future__ import annotations

import sys

from .jacobians import main

if __name__ == "__main__":
    sys.exit(main())
