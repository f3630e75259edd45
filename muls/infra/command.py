"""Command-line plumbing shared by ``muls`` and ``scanner-sim`` (``docs/errors.md``): exit codes, the
one-line parser, argument types that range-check every option inside argparse (:func:`positive_int`,
:func:`seed`, :func:`output_file`...), :func:`run_guarded`, which turns any error into one line and an exit
code (2 bad input, 1 failure such as a full disk, 130 Ctrl-C, 143 SIGTERM), and atomic picture writes."""

from __future__ import annotations

import argparse
import contextlib
import errno
import math
import os
import signal
import sys
import warnings
from importlib import metadata
from pathlib import Path

from .signals import Terminated, signal_behind, signals_as_exceptions, stop_if_signalled

EXIT_FAILURE = 1  # a run that could not finish: a full disk, no permission, not enough memory
EXIT_USAGE = 2  # bad input: an option, a scene, a file
EXIT_SIGINT = 128 + signal.SIGINT  # 130
EXIT_SIGTERM = 128 + signal.SIGTERM  # 143
#: Largest seed: numpy's generators and muls's noise keys take 0 .. 2**63 - 1 without wrapping.
MAX_SEED = 2**63 - 1


def package_version() -> str:
    """The installed version of the muls-scanner package (``--version``)."""
    try:
        return metadata.version("muls-scanner")
    except metadata.PackageNotFoundError:  # pragma: no cover - run from a source tree that was never installed
        return "unknown (not installed)"


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's help ends with its default, unless the help already says it or there is none to show."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text or action.default in (None, argparse.SUPPRESS) or isinstance(action.default, bool):
            return text
        return f"{text} (default: %(default)s)".strip()


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    """argparse that reports a bad argument on one line (no usage dump), for exit code 2, and shows every
    default in ``--help``."""

    def __init__(self, *args, formatter_class=HelpFormatter, **kwargs):
        super().__init__(*args, formatter_class=formatter_class, **kwargs)

    def error(self, message):
        raise _UsageError(f"{self.prog}: error: {' '.join(str(message).split())}")


OneLineParser, UsageError = _Parser, _UsageError


# -- argument types: argparse itself rejects a bad value, in one line naming the option ----------------------
def _arg_type(name: str, convert, ok, allowed: str, bad_values: tuple[str, ...], key: str | None = None):
    """An argparse ``type``: ``convert(text)``, accepted when ``ok(value)``; else "[key ]must be <allowed>,
    not 'text'". ``bad_values`` are inputs it rejects (the tests feed them to every option of this type;
    ``{file}``, ``{dir}`` and ``{missing}`` stand for an existing file, folder and a path that is not there)."""

    def parse(text: str):
        value = None
        with contextlib.suppress(ValueError, OverflowError, TypeError):
            value = convert(text) if text.strip() and "\0" not in text else None
        if value is None or not ok(value):  # ok may raise ArgumentTypeError with a message of its own
            raise argparse.ArgumentTypeError(f"{key + ' ' if key else ''}must be {allowed}, not {text!r}")
        return value

    parse.__name__, parse.allowed, parse.bad_values = name, allowed, bad_values
    return parse


def _finite(text: str) -> float:
    value = float(text)
    return value if math.isfinite(value) else None


def positive_int(key: str | None = None):
    """An integer >= 1 (counts: pulses, shots, repeats...)."""
    return _arg_type("positive_int", int, lambda v: v >= 1, "an integer >= 1", ("0", "-1", "1.5", "x", ""), key)


def non_negative_int(key: str | None = None):
    """An integer >= 0."""
    return _arg_type("non_negative_int", int, lambda v: v >= 0, "an integer >= 0", ("-1", "1.5", "x", ""), key)


def seed(key: str | None = None):
    """A seed: an integer from 0 to 2**63 - 1 (never wrapped)."""
    return _arg_type("seed", int, lambda v: 0 <= v <= MAX_SEED, f"an integer from 0 to 2**63 - 1 ({MAX_SEED})",
                     ("-1", str(MAX_SEED + 1), "1.5", "x", ""), key)


def positive_float(key: str | None = None):
    """A finite number > 0 (lengths, ranges, sizes)."""
    return _arg_type("positive_float", _finite, lambda v: v > 0, "a finite number > 0",
                     ("0", "-1", "nan", "inf", "x", ""), key)


def non_negative_float(key: str | None = None):
    """A finite number >= 0 (delays)."""
    return _arg_type("non_negative_float", _finite, lambda v: v >= 0, "a finite number >= 0",
                     ("-1", "nan", "-inf", "x", ""), key)


def fraction(key: str | None = None):
    """A number in [0, 1] (reflectances)."""
    return _arg_type("fraction", _finite, lambda v: 0 <= v <= 1, "a number from 0 to 1", ("-0.1", "1.5", "nan", ""),
                     key)


def finite_float(key: str | None = None):
    """Any finite number."""
    return _arg_type("finite_float", _finite, lambda v: True, "a finite number", ("nan", "inf", "x", ""), key)


def integer(key: str | None = None):
    """Any integer."""
    return _arg_type("integer", int, lambda v: True, "an integer", ("1.5", "x", ""), key)


def nonempty(key: str | None = None):
    """Non-empty text (names, presets, input paths)."""
    return _arg_type("nonempty", str, lambda v: bool(v.strip()), "non-empty text", ("", "  "), key)


#: [bytes] The longest name of one file or folder on the usual file systems (ext4, XFS, Btrfs, tmpfs: 255).
NAME_MAX_BYTES = 255
#: [bytes] What a writer adds to a name for its hidden temporary beside it: ``.NAME.1a2b3c4d.tmp`` for a file (14),
#: ``.NAME.run-PID-1a2b3c4d`` for an output folder (22, a pid of up to 7 digits).
FILE_ROOM_BYTES, FOLDER_ROOM_BYTES = 14, 22


def check_name_lengths(path: str, room: int = 0) -> None:
    """Refuse (argparse.ArgumentTypeError, one line) a path with a name longer than the file system takes, the last
    one ``room`` bytes shorter (the hidden temporary beside it); before anything stats it, which would raise
    ``OSError: File name too long`` inside argparse."""
    parts = Path(path).parts
    for i, part in enumerate(parts):
        size, limit = len(os.fsencode(part)), NAME_MAX_BYTES - (room if i == len(parts) - 1 else 0)
        if size > limit:
            shown = part if len(part) <= 40 else part[:37] + "..."
            extra = f", less the {room} its hidden temporary beside it adds" if room and i == len(parts) - 1 else ""
            raise argparse.ArgumentTypeError(f"the name {shown!r} has {size:,} bytes, more than the {limit} a name may "
                                             f"have ({NAME_MAX_BYTES} on the usual file systems{extra})")


def _output_file_ok(path: str) -> bool:
    check_name_lengths(path, FILE_ROOM_BYTES)
    p = Path(path)
    return not p.is_dir() and p.parent.is_dir()


def output_file(key: str | None = None):
    """A file to write: not a folder, in a folder that exists (argparse names the option otherwise)."""
    return _arg_type("output_file", str, _output_file_ok, "a file path in an existing folder",
                     ("", "{dir}", "{missing}/out.png", "{file}/out.png"), key)


def _output_dir_ok(path: str) -> bool:
    check_name_lengths(path, FOLDER_ROOM_BYTES)
    p = Path(os.path.abspath(path))
    return not any(q.exists() and not q.is_dir() for q in (p, *p.parents))


def output_dir(key: str | None = None):
    """A folder to write (created when missing): not a file, and under no file."""
    return _arg_type("output_dir", str, _output_dir_ok, "a folder path (not a file, nor under one)",
                     ("", "{file}", "{file}/sub"), key)


def checked_types(parser: argparse.ArgumentParser) -> None:
    """Give every option of ``parser`` and its subcommands that still has a plain type a checked one (text not
    empty for str, integers and finite numbers for int and float), and a help line that shows its default
    where it has none. Options added later are so checked and documented too."""
    plain = {None: nonempty(), str: nonempty(), int: integer(), float: finite_float()}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in set(action.choices.values()):
                checked_types(sub)
            continue
        if action.nargs != 0 and not action.choices and action.type in plain:
            action.type = plain[action.type]
        if not (action.help or "").strip() and action.default not in (None, argparse.SUPPRESS) \
                and not isinstance(action.default, bool):
            action.help = "(default: %(default)s)"


# -- running a command: every error one line, signals an exit code, never a traceback ------------------------
def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _show_warning(prog: str):
    def show(message, category, filename, lineno, file=None, line=None):
        kind = "" if issubclass(category, UserWarning) else f"{category.__name__}: "
        print(f"{prog}: warning: {kind}{_one_line(message)}", file=sys.stderr)

    return show


def run_guarded(prog: str, func, bad_input=()) -> int:
    """``func()``'s exit code, with every way it can end as one line on stderr and no traceback: a bad value
    (ValueError, or one of the ``bad_input`` types, such as a reader's error on a corrupt file; a tuple, or a
    function returning it when an error is raised, so that a library is not imported only to name its errors)
    exit 2; a full disk, a permission or another OS error, or too little memory exit 1; Ctrl-C 130 and SIGTERM 143
    (the ``finally`` blocks and atomic writers have removed the temporary files by then); anything else exit 1 as
    an internal error (``MULS_TRACEBACK=1`` shows its traceback). Warnings print as one line each."""
    try:
        with signals_as_exceptions(), warnings.catch_warnings():
            warnings.simplefilter("default")
            warnings.showwarning = _show_warning(prog)
            try:
                code = int(func() or 0)
                stop_if_signalled()  # a signal whose exception was dropped: the command did not end as asked
                return code
            except Exception as exc:
                if isinstance(exc, bad_input() if callable(bad_input) else bad_input):
                    raise ValueError(_one_line(exc)) from None
                if isinstance(exc, SystemError):  # a signal raised while a compiled kernel returned: numba wraps it
                    raise signal_behind(exc) or exc from None
                raise
    except KeyboardInterrupt:
        print(f"{prog}: interrupted (Ctrl-C); temporary files removed, earlier outputs kept", file=sys.stderr)
        return EXIT_SIGINT
    except Terminated:
        print(f"{prog}: terminated (SIGTERM); temporary files removed, earlier outputs kept", file=sys.stderr)
        return EXIT_SIGTERM
    except BrokenPipeError:  # the reader of stdout went away (``| head``): nothing more to say to it
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAILURE
    except ValueError as exc:  # ParameterError, ConfigError and every other bad input
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except MemoryError:
        print(f"{prog}: error: out of memory; use smaller chunks (survey.chunk_pulses) or a shorter pass",
              file=sys.stderr)
        return EXIT_FAILURE
    except OSError as exc:
        where = f" writing {exc.filename}" if exc.filename else ""
        if exc.errno == errno.ENAMETOOLONG:  # a name the user gave (a file, --out, a sweep value): bad input
            shown = os.fsdecode(exc.filename or "")
            shown = shown if len(shown) <= 80 else f"{shown[:77]}... ({len(os.fsencode(shown)):,} bytes)"
            print(f"{prog}: error: file name too long: {shown!r}; a name may have at most {NAME_MAX_BYTES} bytes "
                  f"(less for a folder a run writes beside: {FOLDER_ROOM_BYTES}), a path 4,096", file=sys.stderr)
            return EXIT_USAGE
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            print(f"{prog}: error: the disk is full ({exc.strerror}){where}; no partial file was left under a "
                  "final name: free some space or write elsewhere", file=sys.stderr)
        else:
            print(f"{prog}: error: {exc.strerror or _one_line(exc)}{where and ': ' + str(exc.filename)}",
                  file=sys.stderr)
        return EXIT_FAILURE
    except Exception as exc:
        if os.environ.get("MULS_TRACEBACK"):
            raise
        print(f"{prog}: internal error: {type(exc).__name__}: {_one_line(exc)} (please report it; MULS_TRACEBACK=1 "
              "shows the traceback)", file=sys.stderr)
        return EXIT_FAILURE


def parse_guarded(parser: argparse.ArgumentParser, argv) -> tuple[argparse.Namespace | None, int]:
    """``(args, 0)``, or ``(None, exit code)`` after ``--help``/``--version`` (0) or a bad argument (one line, 2)."""
    try:
        return parser.parse_args(argv), 0
    except _UsageError as exc:
        print(str(exc), file=sys.stderr)
        return None, EXIT_USAGE
    except SystemExit as exc:  # --help, --version
        return None, int(exc.code or 0)
