"""Command-line arguments (docs/errors.md): every option of every subcommand of ``scanner-sim`` and ``muls`` is range-checked by
argparse; a malformed value is exit code 2 and one line on stderr naming the option, never a traceback.

The cases come from the parsers themselves: each option's type carries the values it must reject
(``bad_values``), so an option added later is covered without touching this file.
"""

import argparse

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import muls.cli as muls_cli
import muls.infra.command as muls_command
import scanner_sim.cli as sim_cli

COMMANDS = {"scanner-sim": sim_cli, "muls": muls_cli}
PROPERTY = settings(max_examples=150, derandomize=True, deadline=1000)


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _takes_values(action: argparse.Action) -> bool:
    return action.nargs != 0 and not isinstance(action, (argparse._HelpAction, argparse._VersionAction,
                                                          argparse._SubParsersAction))


def _good(action: argparse.Action, paths) -> str:
    """A value the option accepts."""
    if action.choices:
        return str(next(iter(action.choices)))
    name = getattr(action.type, "__name__", "")
    return {"positive_int": "1", "non_negative_int": "0", "seed": "1", "integer": "1", "positive_float": "1",
            "non_negative_float": "0", "fraction": "0.5", "finite_float": "1", "output_file": str(paths["out_file"]),
            "output_dir": str(paths["out_dir"])}.get(name, "x")


def _bad(action: argparse.Action) -> list[str]:
    """Values the option must reject: its type's own, and for choices one that is not among them."""
    bad = list(getattr(action.type, "bad_values", ()))
    if action.choices:
        bad.append("no-such-choice")
    return bad


def _values(action, value, paths) -> list[str]:
    n = action.nargs
    count = n if isinstance(n, int) else 1
    return [value] + [_good(action, paths)] * (count - 1)


def _argv(sub: str, parser: argparse.ArgumentParser, target: argparse.Action, value: str, paths) -> list[str]:
    """``sub`` with ``target`` given ``value`` and every other required argument a good value."""
    argv = [sub]
    for action in parser._actions:
        if not _takes_values(action):
            continue
        positional = not action.option_strings
        if action is target:
            given = _values(action, value, paths)
        elif positional and action.nargs not in ("?", "*"):
            given = _values(action, _good(action, paths), paths)
        elif action.required:
            given = _values(action, _good(action, paths), paths)
        else:
            continue
        argv += given if positional else [action.option_strings[0], *given]
    return argv


def _cases():
    for command, module in COMMANDS.items():
        for sub, parser in _subparsers(module.build_parser()).items():
            for action in parser._actions:
                if _takes_values(action):
                    for bad in _bad(action):
                        name = action.option_strings[0] if action.option_strings else action.dest
                        yield pytest.param(command, sub, action.dest, bad, id=f"{command}-{sub}-{name}-{bad!r}")


@pytest.fixture
def paths(tmp_path):
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "a_dir").mkdir()
    return {"file": tmp_path / "a_file", "dir": tmp_path / "a_dir", "missing": tmp_path / "missing",
            "out_file": tmp_path / "out.png", "out_dir": tmp_path / "out"}


def _run(capsys, module, argv) -> tuple[int, str, str]:
    try:
        code = module.main(argv)
    except SystemExit as exc:  # pragma: no cover - main returns its exit code; this would be a regression
        pytest.fail(f"main raised SystemExit({exc.code}) instead of returning it")
    out, err = capsys.readouterr()
    return code, out, err


def test_every_option_has_a_checked_type():
    """No option reads a value without a type that rejects something (empty text at least)."""
    for command, module in COMMANDS.items():
        for sub, parser in _subparsers(module.build_parser()).items():
            for action in parser._actions:
                if _takes_values(action):
                    assert action.choices or getattr(action.type, "bad_values", ()), (command, sub, action.dest)


@pytest.mark.parametrize("command, sub, dest, bad", list(_cases()))
def test_malformed_value_of_every_option_is_exit_2_and_one_line(command, sub, dest, bad, paths, capsys):
    module = COMMANDS[command]
    parser = _subparsers(module.build_parser())[sub]
    action = next(a for a in parser._actions if a.dest == dest and _takes_values(a))
    value = bad.format(**{k: str(v) for k, v in paths.items()})
    code, out, err = _run(capsys, module, _argv(sub, parser, action, value, paths))
    lines = err.strip().splitlines()
    assert code == 2, (code, err)
    assert len(lines) == 1 and "Traceback" not in err, err
    name = "/".join(action.option_strings) or action.metavar or action.dest
    assert f"argument {name}" in lines[0] and lines[0].startswith(f"{command} {sub}: error: "), lines[0]
    assert out == ""


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_unknown_option_and_subcommand_are_one_line(command, capsys):
    module = COMMANDS[command]
    for argv in (["no-such-command"], *([sub, "--no-such-option"] for sub in _subparsers(module.build_parser())), []):
        code, _, err = _run(capsys, module, argv)
        assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, (argv, err)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_version(command, capsys):
    from importlib.metadata import version

    code, out, _ = _run(capsys, COMMANDS[command], ["--version"])
    assert code == 0 and out.strip() == f"{command} {version('muls-scanner')}"


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_help_shows_every_default(command, capsys):
    module = COMMANDS[command]
    for sub, parser in _subparsers(module.build_parser()).items():
        formatter = parser._get_formatter()
        assert isinstance(formatter, argparse.ArgumentDefaultsHelpFormatter), sub
        for action in parser._actions:
            if action.default in (None, argparse.SUPPRESS) or isinstance(action.default, bool):
                continue
            text = formatter._format_action(action)
            assert "default" in text, (sub, action.dest, text)
        code, out, _ = _run(capsys, module, [sub, "--help"])
        assert code == 0 and "usage:" in out


# -- properties of the argument types ------------------------------------------------------------------------
TYPES = {"positive_int": (muls_command.positive_int(), lambda v: isinstance(v, int) and v >= 1),
         "non_negative_int": (muls_command.non_negative_int(), lambda v: isinstance(v, int) and v >= 0),
         "seed": (muls_command.seed(), lambda v: isinstance(v, int) and 0 <= v <= 2**63 - 1),
         "positive_float": (muls_command.positive_float(), lambda v: v > 0 and v < float("inf")),
         "non_negative_float": (muls_command.non_negative_float(), lambda v: 0 <= v < float("inf")),
         "fraction": (muls_command.fraction(), lambda v: 0 <= v <= 1),
         "nonempty": (muls_command.nonempty(), lambda v: bool(v.strip()))}

_numbers = st.one_of(st.integers(min_value=-(2**70), max_value=2**70).map(str),
                     st.floats(allow_nan=True, allow_infinity=True).map(repr), st.text(max_size=12),
                     st.sampled_from(["", " ", "1e400", "-0", "0x10", "1_000", "٣", "\0"]))


@PROPERTY
@given(name=st.sampled_from(sorted(TYPES)), text=_numbers)
def test_argument_types_accept_only_what_they_promise(name, text):
    """Any text: either a value inside the type's range, or ArgumentTypeError with one line naming the text;
    never a wrapped seed, a NaN or an exception of another kind."""
    parse, ok = TYPES[name]
    try:
        value = parse(text)
    except argparse.ArgumentTypeError as exc:
        message = str(exc)
        assert "\n" not in message and message.startswith("must be ") and repr(text) in message
    else:
        assert ok(value), (name, text, value)
