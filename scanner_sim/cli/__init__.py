"""``scanner-sim`` command line.

Subcommands are listed in :data:`~scanner_sim.cli.registry.SUBCOMMANDS` with the module that builds and runs
each, one module per group of them (:mod:`~scanner_sim.cli.passes`, :mod:`~scanner_sim.cli.clouds`,
:mod:`~scanner_sim.cli.studies`, :mod:`~scanner_sim.cli.perf`...), imported only for the subcommand being parsed:
adding one is a line in the registry and, in its module, ``def _add_name(p)`` that adds its options and sets
``func``, listed in that module's ``BUILDERS``. They hold only the parsers and the thin functions that call the
package; the work itself lives in the modules they call. A ``ValueError`` (bad scene
file, bad parameter) becomes one line on stderr and exit code 2, without a traceback; every option is
range-checked by argparse through the typed helpers of :mod:`muls.infra.command`, and any other ending is one line too
(a full disk 1, Ctrl-C 130, SIGTERM 143; ``docs/errors.md``).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from muls.infra.command import OneLineParser, checked_types, package_version, parse_guarded, run_guarded
from scanner_sim.cli.registry import SUBCOMMANDS

#: Build every subcommand's options (the default of :func:`build_parser`).
EVERY = object()


def build_parser(command=EVERY) -> argparse.ArgumentParser:
    """The ``scanner-sim`` parser; ``command``: the one subcommand whose options to add (importing its module), None
    for none (``scanner-sim --help``), :data:`EVERY` for all."""
    parser = OneLineParser(prog="scanner-sim", description="Underwater lidar survey simulator (MULS)")
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    sub.required = True
    for name, (module, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text)
        if command is EVERY or command == name:
            importlib.import_module(f"{__name__}.{module}").BUILDERS[name](p)
    checked_types(parser)  # an option a builder left with a plain type still rejects empty text and nan
    return parser


def main(argv=None) -> int:
    """Entry point of ``scanner-sim``; returns the exit code: 0, 1 (a failure such as a full disk), 2 (bad
    input), 130 (Ctrl-C) or 143 (SIGTERM), with one line on stderr for anything but 0 (``docs/errors.md``)."""
    from muls.infra.runtime import configure_process, end_of_command

    configure_process()  # threads, memory and the kernel cache, before any kernel runs (muls/infra/runtime.py)
    words = sys.argv[1:] if argv is None else argv
    command = next((w for w in words if w in SUBCOMMANDS), None)
    args, code = parse_guarded(build_parser(command), argv)
    if args is None:  # --help, --version (0) or a bad argument (2, one line printed)
        return code
    code = run_guarded(f"scanner-sim {args.command}", lambda: args.func(args), bad_input=corrupt_file_errors)
    if argv is None:  # the console script's own process, which ends now
        end_of_command()
    return code


def corrupt_file_errors() -> tuple[type[BaseException], ...]:
    """The errors of a corrupt LAS or YAML file, bad input like a wrong scene key (exit 2): those of the readers the
    command imported (no other can have raised one), so that ``validate`` need not import laspy to name its error."""
    readers = (("laspy", "LaspyException"), ("yaml", "YAMLError"))
    return tuple(getattr(sys.modules[name], error) for name, error in readers if name in sys.modules)
