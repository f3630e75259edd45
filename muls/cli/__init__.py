"""``muls``: the MULS studies from the command line (waveform, maxrange, precision, coaxial, bench, edge-bias), the
multiple-scattering Monte Carlo beside MULS (multiscatter, multiscatter-study, validate-pass) and against a published
benchmark (mobley1993).

Subcommands are listed in :data:`~muls.cli.registry.SUBCOMMANDS` with the module that builds and runs each
(:mod:`muls.cli.studies`, :mod:`muls.cli.montecarlo`, :mod:`muls.cli.sensitivity`), imported only for the subcommand
being parsed. Each command runs one function of :mod:`muls.studies` or :mod:`muls.montecarlo`, prints its result as
JSON with ``--json`` (otherwise a short table), and, except ``bench``, writes a picture (``--out``, a default name
otherwise; ``--no-plot`` skips it). Bad arguments give one line on stderr naming the option and what is allowed, and
exit code 2. The command-line plumbing it shares with ``scanner-sim`` (argument types, one-line errors, exit codes)
is in :mod:`muls.infra.command`.
"""

from __future__ import annotations

import argparse
import importlib
import json

from ..infra.atomic import write_atomically
from ..infra.command import OneLineParser, checked_types, package_version, parse_guarded, run_guarded
from ..infra.runtime import configure_process, end_of_command
from .registry import SUBCOMMANDS

#: Build every subcommand's options (the default of :func:`build_parser`).
EVERY = object()


def build_parser(command=EVERY) -> argparse.ArgumentParser:
    """The ``muls`` parser; ``command``: the one subcommand whose options to add (importing its module), None for
    none (``muls --help``), :data:`EVERY` for all."""
    parser = OneLineParser(prog="muls", description="MULS studies: waveforms, maximum range, precision, coaxial "
                           "vs non-coaxial, speed.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    for name, (module, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text)
        if command is EVERY or command == name:
            importlib.import_module(f"{__name__}.{module}").BUILDERS[name](p)
    checked_types(parser)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``muls`` console script; returns the exit code (``run_guarded``: 0, 1, 2, 130, 143)."""
    import sys

    configure_process()  # threads, memory and the kernel cache, before any kernel runs (muls/infra/runtime.py)
    words = sys.argv[1:] if argv is None else argv
    command = next((w for w in words if w in SUBCOMMANDS), None)
    args, code = parse_guarded(build_parser(command), argv)
    if args is None:
        return code
    code = run_guarded(f"muls {args.command}", lambda: _run(args))
    if argv is None:  # the console script's own process, which ends now
        end_of_command()
    return code


def _run(args) -> int:
    result, text, plot = args.run(args)
    out = None
    if plot is not None and not args.no_plot:
        commands = importlib.import_module(f"{__name__}.{SUBCOMMANDS[args.command][0]}")
        out = args.out or commands.DEFAULT_OUT[args.command].format(**vars(args))
        if args.command in commands.FOLDER_OUTPUTS:  # a folder of files, each written whole
            plot(result, out)
        else:
            write_atomically(lambda tmp: plot(result, tmp), out)
    if args.json:
        print(json.dumps(result, allow_nan=False))
    else:
        print(text)
        if out:
            print(f"picture: {out}")
    return 0
