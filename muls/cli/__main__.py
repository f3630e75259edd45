"""``python -m muls.cli``: the ``muls`` command."""

import sys

from muls.cli import main

sys.exit(main())
