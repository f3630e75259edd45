"""Signals as exceptions for a command (``docs/errors.md``): SIGINT (Ctrl-C) raised as KeyboardInterrupt and SIGTERM as
:class:`Terminated` in the main thread, so that every ``finally`` and atomic writer cleans up, and
:func:`stop_if_signalled` for long loops, which raises again a signal whose first exception Python dropped.
No heavy import: the Monte Carlo's loop calls it."""

from __future__ import annotations

import contextlib
import signal
import threading


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that every ``finally`` and atomic writer cleans up."""


#: The signals the running command received, kept after the first was raised: Python drops an exception raised
#: where it cannot propagate (in a ``__del__``, a weakref or garbage-collector callback it only prints "Exception
#: ignored in ..."), and the first signal set both to be ignored, so a command would go on past its Ctrl-C.
#: :func:`stop_if_signalled` raises it again.
_received: list[int] = []


def _signal_exception(signum: int) -> BaseException:
    return KeyboardInterrupt() if signum == signal.SIGINT else Terminated(signum)


def _raise_on_signal(signum, frame):
    for s in (signal.SIGINT, signal.SIGTERM):  # a second signal during the clean-up is ignored
        signal.signal(s, signal.SIG_IGN)
    _received.append(signum)
    raise _signal_exception(signum)


def stop_if_signalled() -> None:
    """Raise again the Ctrl-C (KeyboardInterrupt) or SIGTERM (:class:`Terminated`) the running command received, in
    case its first raise was dropped where Python cannot propagate an exception. Loops that run long (a pass's
    chunks, a dataset's scenes) call it between their steps; :func:`muls.infra.command.run_guarded` calls it when the
    command returns. Does nothing outside a guarded command or when no signal came."""
    if _received:
        raise _signal_exception(_received[0])


@contextlib.contextmanager
def signals_as_exceptions():
    """In the main thread: SIGINT raised as KeyboardInterrupt and SIGTERM as :class:`Terminated` while the block runs
    (the first signal; a second during the clean-up is ignored), the handlers before restored after it. Elsewhere:
    nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _received.clear()
    previous = {s: signal.signal(s, _raise_on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        _received.clear()


def signal_behind(exc: BaseException) -> BaseException | None:
    """The KeyboardInterrupt or :class:`Terminated` that ``exc`` was raised from, if any (its cause chain)."""
    seen = exc.__cause__ or exc.__context__
    while seen is not None:
        if isinstance(seen, (KeyboardInterrupt, Terminated)):
            return seen
        seen = seen.__cause__ or seen.__context__
    return None
