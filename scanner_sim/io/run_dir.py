"""Run folders: a pass writes into a locked, hidden sibling of its output folder and is swapped in whole.

For ``scanner-sim run --out out/survey``::

    out/.survey.lock                  held while a run writes into out/survey; holds the run's pid
    out/.survey.run-4242-1a2b3c4d/    the new run, written here
    out/survey/                       the previous run, untouched until the new one is complete

:meth:`RunDirectory.commit` swaps the new folder in with one atomic rename (Linux ``renameat2``
``RENAME_EXCHANGE``; elsewhere two renames, the old folder moved aside first) and then deletes the old run.
So a folder holds a complete run, the previous one or the new one, at every instant: an interrupted run
(Ctrl-C, SIGTERM, a full disk, an error) removes its hidden folder and leaves the previous run as it was; a
run killed outright (``kill -9``, power loss) leaves its hidden folder, which the next run into the same
folder removes.

A second run into a folder while one writes it is refused (:class:`OutputBusyError`). The lock
(:class:`OutputLock`) is an ``flock`` on the lock file, which the kernel releases when its process dies, so the
lock file a killed run leaves (with a dead pid in it) is simply taken over. Where ``flock`` is unsupported the pid
in the file decides: a live process keeps the folder, a dead one's lock is taken over. The commands that write a
folder of many passes (``coverage``, ``campaign``, ``tradeoff``) hold the same lock on their folder for as long as
they run (:func:`hold_output`; ``run`` takes it before it builds the pass), so any two writers of one folder,
whatever their commands, exclude each other.

Only a folder that holds a complete run (a ``summary.json``) or nothing is replaced; any other folder is
refused, so that ``--out .`` or ``--out ~/Documents`` can never delete files that are not a run's.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import functools
import os
import secrets
import shutil
import threading
from pathlib import Path

from muls.infra.atomic import PathLike, fsync_dir

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

__all__ = ["OutputBusyError", "OutputLock", "RunDirectory", "abort_on_error", "held_output", "hold_output"]

#: The file whose presence makes a folder a complete run (written last by every pass).
COMPLETE_MARKER = "summary.json"


class OutputBusyError(ValueError):
    """Another live run is writing the same output folder."""


_open = threading.local()


def _open_runs() -> list[RunDirectory]:
    if not hasattr(_open, "runs"):
        _open.runs = []
    return _open.runs


class RunDirectory:
    """The output folder ``final`` of one run, written through a locked temporary sibling.

    ``with RunDirectory(final) as folder:`` writes into ``folder`` (the hidden sibling) and swaps it in for
    ``final`` when the block ends without an exception; on an exception (KeyboardInterrupt and SystemExit
    included) it deletes the sibling and ``final`` keeps what it held. Without a ``with`` block, call
    :meth:`open`, write into :attr:`path`, then :meth:`commit` (or :meth:`abort`), inside a function
    decorated with :func:`abort_on_error`.

    ``complete_marker``: the file whose presence makes a folder complete (a pass's summary.json; a ROS 2 bag's
    metadata.yaml, :mod:`scanner_sim.io.rosbag`).

    Raises ValueError (one line) when ``final`` is a file or lies under one, is the current folder or holds
    it, or holds files but no complete run; :class:`OutputBusyError` when another live run holds its lock.
    """

    def __init__(self, final: PathLike, complete_marker: str = COMPLETE_MARKER):
        self.final = Path(final)
        self.complete_marker = complete_marker
        self.path: Path | None = None
        self._target = Path(os.path.abspath(self.final))
        self._lock: OutputLock | None = None

    # -- the protocol ------------------------------------------------------------------------------------
    def open(self) -> RunDirectory:
        """Check ``final``, take the lock, remove what killed runs left, and create the hidden sibling."""
        if self.path is not None:
            raise ValueError(f"output folder {str(self.final)!r} is already open")
        self._check_target()
        # the lock this thread holds on the folder (the command took it, hold_output), else its own
        self._lock = None if held_output(self.final) else OutputLock(self.final).acquire()
        try:
            self._remove_leftovers()
            self.path = self._target.parent / f".{self._target.name}.run-{os.getpid()}-{secrets.token_hex(4)}"
            self.path.mkdir()
        except BaseException:
            self._release()
            raise
        _open_runs().append(self)
        return self

    def commit(self) -> Path:
        """Swap the finished run in for ``final``, delete the previous run, release the lock; returns ``final``."""
        if self.path is None:
            raise ValueError(f"output folder {str(self.final)!r} is not open")
        new, target = self.path, self._target
        try:
            fsync_dir(new)
            if target.exists():
                self._check_target()  # it may have changed while the run was written
                if _exchange(new, target):
                    old = new  # the exchange left the previous run under the temporary name
                else:
                    old = target.parent / f".{target.name}.old-{secrets.token_hex(4)}"
                    os.rename(target, old)
                    try:
                        os.rename(new, target)
                    except BaseException:
                        os.rename(old, target)
                        raise
                fsync_dir(target.parent)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.rename(new, target)
            fsync_dir(target.parent)
        except BaseException:
            self.abort()
            raise
        self.path = None
        self._close()
        return self.final

    def abort(self) -> None:
        """Delete the unfinished run and release the lock; ``final`` keeps what it held."""
        if self.path is not None:
            shutil.rmtree(self.path, ignore_errors=True)
            self.path = None
        self._close()

    def __enter__(self) -> Path:
        return self.open().path

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.name_final(exc)
            self.abort()

    def name_final(self, exc: BaseException) -> None:
        """Make an OS error about a file of the hidden folder (a full disk) name it as the user knows it."""
        if self.path is not None and isinstance(exc, OSError) and exc.filename:
            with contextlib.suppress(ValueError, TypeError):
                exc.filename = str(self.final / Path(os.fsdecode(exc.filename)).relative_to(self.path))

    # -- checks ------------------------------------------------------------------------------------------
    def _check_target(self) -> None:
        target, shown = self._target, str(self.final)
        for folder in reversed([target, *target.parents]):
            if folder.exists() and not folder.is_dir():
                what = "is a file" if folder == target else f"lies under {str(folder)!r}, a file"
                raise ValueError(f"output folder {shown!r} {what}; give a folder path")
        with contextlib.suppress(FileExistsError):
            target.parent.mkdir(parents=True, exist_ok=True)
        if not target.exists():
            return
        here = Path(os.path.abspath(Path.cwd()))
        if target.resolve() in (here.resolve(), *here.resolve().parents):
            raise ValueError(f"output folder {shown!r} is the current folder or holds it; give a folder for the run")
        entries = sorted(e for e in os.listdir(target) if not e.startswith("."))
        if entries and self.complete_marker not in entries:
            listed = ", ".join(entries[:3]) + (", ..." if len(entries) > 3 else "")
            raise ValueError(f"output folder {shown!r} holds files but no complete run ({listed}: no "
                             f"{self.complete_marker}); a run replaces only an empty folder or an earlier run's, so "
                             "give another folder or empty this one")

    def _remove_leftovers(self) -> None:
        """Hidden folders of runs killed outright (we hold the lock, so no live run owns one)."""
        for pattern in (f".{self._target.name}.run-*", f".{self._target.name}.old-*"):
            for leftover in self._target.parent.glob(pattern):
                if leftover.is_dir() and not leftover.is_symlink():
                    shutil.rmtree(leftover, ignore_errors=True)

    def _release(self) -> None:
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def _close(self) -> None:
        self._release()
        with contextlib.suppress(ValueError):
            _open_runs().remove(self)


class OutputLock:
    """The lock of the output folder ``folder``: an exclusive ``flock`` on ``.NAME.lock`` beside it (hidden, so it
    never looks like an output), holding the pid of its process.

    :meth:`acquire` raises :class:`OutputBusyError` (one line naming the holder's pid and the lock file) while
    another open lock holds it, in this process or any other; :meth:`release` unlinks the file. A process killed
    outright leaves the file, but the kernel drops its ``flock``, so the next writer takes the lock over.
    """

    def __init__(self, folder: PathLike):
        self.folder = Path(folder)
        target = Path(os.path.abspath(self.folder))
        self.path = target.parent / f".{target.name}.lock"
        self._fd: int | None = None

    def acquire(self) -> OutputLock:
        """Take the lock (the folder's parent is created when missing)."""
        if self._fd is not None:
            raise ValueError(f"the lock of output folder {str(self.folder)!r} is already held")
        with contextlib.suppress(FileExistsError):
            self.path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                state = _flock(fd)
                if state == "busy":
                    raise self._busy(_pid_in(fd))
                if state == "unsupported":
                    holder = _pid_in(fd)
                    if holder is not None and holder != os.getpid() and _alive(holder):
                        raise self._busy(holder)
                # The writer that held the lock may have removed the file since we opened it: hold the one named so.
                if os.fstat(fd).st_ino != os.stat(self.path).st_ino:
                    os.close(fd)
                    continue
            except FileNotFoundError:
                os.close(fd)
                continue
            except BaseException:
                os.close(fd)
                raise
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            self._fd = fd
            return self

    def release(self) -> None:
        """Give the lock up and remove its file (nothing when not held)."""
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            os.unlink(self.path)
        with contextlib.suppress(OSError):
            os.close(self._fd)
        self._fd = None

    def _busy(self, pid: int | None) -> OutputBusyError:
        who = f"pid {pid}" if pid is not None else "another process"
        return OutputBusyError(f"output folder {str(self.folder)!r} is being written by another run ({who}, lock "
                               f"{str(self.path)!r}); wait for it to finish or give another folder")

    def __enter__(self) -> OutputLock:
        return self.acquire()

    def __exit__(self, exc_type, exc, tb) -> None:
        self.release()


_held = threading.local()


def _held_folders() -> dict[str, OutputLock]:
    if not hasattr(_held, "folders"):
        _held.folders = {}
    return _held.folders


def held_output(folder: PathLike) -> bool:
    """Whether this thread holds the lock of ``folder`` through :func:`hold_output`."""
    return os.path.abspath(folder) in _held_folders()


@contextlib.contextmanager
def hold_output(folder: PathLike):
    """Hold the :class:`OutputLock` of ``folder`` for the block, on any ending (an error, Ctrl-C and SIGTERM
    included). Nested blocks of one thread on the same folder, and a :class:`RunDirectory` opened inside, share
    the lock: a command takes it before its slow set-up (a scene, a Dask cluster), and the library function it
    calls takes it again."""
    held, key = _held_folders(), os.path.abspath(folder)
    if key in held:
        yield held[key]
        return
    with OutputLock(folder) as lock:
        held[key] = lock
        try:
            yield lock
        finally:
            del held[key]


def _flock(fd: int) -> str:
    """Try an exclusive ``flock`` on ``fd``: "locked", "busy" (another open file holds it), or "unsupported"
    (a file system without ``flock``: the pid in the file decides then)."""
    if fcntl is None:  # pragma: no cover
        return "unsupported"
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return "busy"
    except OSError as exc:  # pragma: no cover - e.g. ENOLCK on some network file systems
        if exc.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
            return "unsupported"
        raise
    return "locked"


def _pid_in(fd: int) -> int | None:
    try:
        return int(os.pread(fd, 32, 0).split()[0])
    except (OSError, ValueError, IndexError):
        return None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def _exchange(a: Path, b: Path) -> bool:
    """Swap two existing paths in one atomic step (Linux ``renameat2(RENAME_EXCHANGE)``); False where the
    C library or the file system cannot."""
    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def abort_on_error(func):
    """Decorate a function that opens :class:`RunDirectory` objects without a ``with`` block: those it leaves
    open, because it raised (Ctrl-C and SIGTERM included) or returned without committing, are aborted."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        runs = _open_runs()
        depth = len(runs)
        try:
            return func(*args, **kwargs)
        except BaseException as exc:
            for run in runs[depth:]:
                run.name_final(exc)
            raise
        finally:
            while len(runs) > depth:
                runs[-1].abort()

    return wrapper
