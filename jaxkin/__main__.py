"""``python -m jaxkin``: the command line (see :mod:`jaxkin.cli`)."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
