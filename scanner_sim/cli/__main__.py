"""``python -m scanner_sim.cli``: the ``scanner-sim`` command."""

import sys

from scanner_sim.cli import main

if __name__ == "__main__":  # not when a child process (the pictures' worker) imports the parent's main module
    sys.exit(main())
