"""``scanner-sim`` command line.

Subcommands live in :data:`~scanner_sim.cli.registry.SUBCOMMANDS`, a registry of builder functions, one module per
group of them (:mod:`~scanner_sim.cli.passes`, :mod:`~scanner_sim.cli.clouds`, :mod:`~scanner_sim.cli.studies`,
:mod:`~scanner_sim.cli.perf`): adding one is a small, separate edit: write ``def _add_name(sub)`` that adds its
parser and sets ``func``, and decorate it with ``@subcommand("name")``. They hold only the parsers and the thin
functions that call the package; the work itself lives in the modules they call. A ``ValueError`` (bad scene
file, bad parameter) becomes one line on stderr and exit code 2, without a traceback; every option is
range-checked by argparse through the typed helpers of :mod:`muls.infra.command`, and any other ending is one line too
(a full disk 1, Ctrl-C 130, SIGTERM 143; ``docs/errors.md``).
"""

from __future__ import annotations

import argparse

from muls.infra.command import OneLineParser, checked_types, package_version, parse_guarded, run_guarded
from scanner_sim.cli import clouds, datasets, features, passes, perf, studies, uncertainty  # noqa: F401  each registers its subcommands
from scanner_sim.cli.registry import SUBCOMMANDS

#: The order ``scanner-sim --help`` lists the subcommands in: the main job first.
HELP_ORDER = ("run", "scenes", "validate", "schema", "view", "swath", "coverage", "features", "campaign", "plan", "dataset",
              "tradeoff", "overlap", "bench", "bench-rays")

def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="scanner-sim", description="Underwater lidar survey simulator (MULS)")
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    sub.required = True
    for name in sorted(SUBCOMMANDS, key=lambda n: HELP_ORDER.index(n) if n in HELP_ORDER else len(HELP_ORDER)):
        SUBCOMMANDS[name](sub)
    checked_types(parser)  # an option a builder left with a plain type still rejects empty text and nan
    return parser


def main(argv=None) -> int:
    """Entry point of ``scanner-sim``; returns the exit code: 0, 1 (a failure such as a full disk), 2 (bad
    input), 130 (Ctrl-C) or 143 (SIGTERM), with one line on stderr for anything but 0 (``docs/errors.md``)."""
    from muls.infra.runtime import configure_process

    configure_process()  # threads, memory and the kernel cache, before any kernel runs (muls/infra/runtime.py)
    args, code = parse_guarded(build_parser(), argv)
    if args is None:  # --help, --version (0) or a bad argument (2, one line printed)
        return code
    import laspy
    import yaml

    # a corrupt LAS or YAML file is bad input like a wrong scene key: exit 2
    return run_guarded(f"scanner-sim {args.command}", lambda: args.func(args),
                       bad_input=(laspy.LaspyException, yaml.YAMLError))
