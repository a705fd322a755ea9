"""``python3 -m bench [--quick] [--write-readme]``: the whole Jacobian comparison (see
bench/README.md); ``python3 -m bench.scale`` is the 10-million-configuration streaming run."""

from __future__ import annotations

import os
import sys

from .jacobians import main

if __name__ == "__main__":
    rc = main()
    # Leave without the interpreter's teardown: the Robotics Toolbox's nanobind extension
    # otherwise prints pages of "leaked instance" warnings at exit. Everything is written.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)
