"""A signal that arrives while a compiled kernel runs is still that signal's exit, not an internal error."""

import pytest

from muls.infra.command import EXIT_SIGINT, EXIT_SIGTERM, Terminated, run_guarded


@pytest.mark.parametrize("signal_exc, code", [(KeyboardInterrupt(), EXIT_SIGINT), (Terminated(15), EXIT_SIGTERM)])
def test_regression_signal_inside_a_numba_kernel_exits_as_the_signal(signal_exc, code, capsys):
    """Root cause: the SIGTERM handler raises in the main thread; when that happens while a numba dispatcher
    returns (``_plan`` in CI), numba reports "returned a result with an exception set" as a SystemError
    caused by the signal's exception, and the command ended as an internal error with exit 1. The guard now
    looks through the cause chain."""

    def kernel_interrupted():
        try:
            raise signal_exc
        except BaseException as exc:
            raise SystemError("CPUDispatcher(<function _plan>) returned a result with an exception set") from exc

    assert run_guarded("scanner-sim run", kernel_interrupted) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "internal error" not in err[0]


def test_a_system_error_of_its_own_stays_an_internal_error(capsys):
    def broken():
        raise SystemError("something else")

    assert run_guarded("scanner-sim run", broken) == 1
    assert "internal error" in capsys.readouterr().err
