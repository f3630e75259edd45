"""Atomic files: write a hidden temporary file beside the destination, fsync it, rename it into place, fsync the
folder. Every file both packages write goes through :func:`atomic_path` (or :func:`write_atomically`, its form for
writers that take a path).

On any exception (KeyboardInterrupt, SIGTERM under the command line and a full disk included) the
temporary file is removed and the final name keeps what it held: nothing, or the previous complete file.
A run killed outright can leave a ``.*.tmp`` file behind, never a half-written file under a final name
(``docs/outputs.md``, ``docs/errors.md``).
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["PathLike", "StreamingWriter", "atomic_open", "atomic_path", "existing_parent", "fsync_dir", "write_atomically"]

PathLike = str | os.PathLike


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(directory: Path) -> None:
    """Flush a folder's entries (renames, new files) to disk, where the platform has directory fds."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def existing_parent(final: Path) -> Path:
    """The directory of ``final``; raises ValueError if it does not exist."""
    parent = final.parent if str(final.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(
            f"output path {str(final)!r}: directory {str(parent)!r} does not exist; create it first"
        )
    return parent


@contextlib.contextmanager
def atomic_path(final_path: PathLike, keep_suffix: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``final_path``; on success move it onto ``final_path``.

    The body writes the whole file to the yielded path (and closes it). On normal exit the file is
    fsynced and renamed onto ``final_path`` with ``os.replace`` (atomic on POSIX and Windows), then
    the directory is fsynced. If the body raises (any exception, KeyboardInterrupt included), the
    temporary file is removed, ``final_path`` is untouched and the exception propagates.

    The temporary name is hidden and ends in ``.tmp`` (``.points.las.1a2b3c4d.tmp``), so a run
    killed outright never leaves a file that looks complete; with ``keep_suffix`` the final name's suffix follows
    (``.plot.png.1a2b3c4d.tmp.png``), for a writer that picks its format by the suffix (matplotlib's ``savefig``).

    Raises ValueError if the parent directory of ``final_path`` does not exist or ``final_path`` is
    a directory.
    """
    final = Path(final_path)
    parent = existing_parent(final)
    if final.is_dir():
        raise ValueError(f"output path {str(final)!r} is a directory; give a file name")
    tmp = final.with_name(f".{final.name}.{secrets.token_hex(4)}.tmp{final.suffix if keep_suffix else ''}")
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"atomic_path: nothing was written to {tmp} for {final}")
        _fsync_path(tmp)
        os.replace(tmp, final)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename in (None, str(tmp)):
            exc.filename = str(final)  # a failed write (ENOSPC) names no file, or the hidden one; say which
        raise
    fsync_dir(parent)


def write_atomically(write, path: PathLike) -> None:
    """``write(tmp)`` (``tmp`` a str path ending in ``path``'s suffix) inside :func:`atomic_path`: for a writer that
    takes a path rather than giving one."""
    with atomic_path(path, keep_suffix=True) as tmp:
        write(str(tmp))


@contextlib.contextmanager
def atomic_open(final_path: PathLike, mode: str = "wb", **kwargs) -> Iterator[Any]:
    """Open a temporary file for writing inside :func:`atomic_path`; yield the file object.

    ``mode`` and ``kwargs`` as :func:`open` (``"w"`` with ``encoding=`` for text).
    """
    with atomic_path(final_path) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh
        fh.flush()


class StreamingWriter:
    """Context-manager protocol of the streaming writers (LAS points, dropouts).

    ``open`` on entry; on a clean exit ``close`` (the file appears complete under its final name),
    on an exception ``abort`` (nothing appears). Subclasses define the three methods.
    """

    def __enter__(self):
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
