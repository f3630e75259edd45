"""``python -m scanner_sim.cli``: the ``scanner-sim`` command."""

import sys

from scanner_sim.cli import main

sys.exit(main())
