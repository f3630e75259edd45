"""dropouts.npz: every pulse without a point (time, aim, cause) as a compressed numpy archive, streamed."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from muls.infra.atomic import PathLike, StreamingWriter, atomic_open, existing_parent
from scanner_sim.records.point_records import DROPOUT_CAUSES, DropoutRecords

__all__ = ["DropoutWriter", "read_dropouts_npz", "write_dropouts_npz"]


def write_dropouts_npz(path: PathLike, records: DropoutRecords) -> None:
    """Write dropouts to a compressed ``.npz``, atomically.

    Arrays: ``pulse_index`` (n,) int64, ``time_s`` (n,) float64 [s], ``origin`` (n, 3) float64 [m],
    ``direction`` (n, 3) float32, ``cause`` (n,) uint8 and ``cause_names`` (6,) str (the code
    table, index = code). Read back with :func:`read_dropouts_npz`.
    """
    if not isinstance(records, DropoutRecords):
        raise TypeError(f"write_dropouts_npz: expected DropoutRecords, got {type(records).__name__}")
    with atomic_open(path) as fh:
        np.savez_compressed(fh, cause_names=np.array(DROPOUT_CAUSES), **records.as_dict())


def read_dropouts_npz(path: PathLike) -> DropoutRecords:
    """Read a dropouts ``.npz`` back; causes are re-mapped by name if the stored table differs."""
    with np.load(path, allow_pickle=False) as z:
        cause = z["cause"]
        names = [str(s) for s in z["cause_names"]]
        if tuple(names) != DROPOUT_CAUSES:
            lut = np.array([DROPOUT_CAUSES.index(s) if s in DROPOUT_CAUSES else 255 for s in names], dtype=np.uint8)
            cause = lut[cause]
        return DropoutRecords(
            pulse_index=z["pulse_index"],
            time_s=z["time_s"],
            origin=z["origin"],
            direction=z["direction"],
            cause=cause,
        )


class DropoutWriter(StreamingWriter):
    """Streaming, atomic dropouts writer with memory flat in the length of the pass.

    Each :meth:`write` appends the chunk's fields to raw spool files beside the destination
    (hidden ``.tmp`` files); :meth:`close` memory-maps them into the compressed ``.npz`` (numpy
    streams them into the archive in buffered blocks), renames it into place and removes the spool.
    On an exception inside the ``with`` block everything temporary is removed and no final file
    appears. The result is the same file as :func:`write_dropouts_npz` of all chunks concatenated.
    """

    def __init__(self, path: PathLike) -> None:
        self.path = Path(path)
        self._dir = existing_parent(self.path)
        self._spool: dict[str, tuple[Path, Any]] | None = None
        self.count = 0
        self._counts = np.zeros(len(DROPOUT_CAUSES), dtype=np.int64)
        self._closed = False

    def open(self) -> None:
        """Start the spool. Called by ``__enter__``."""
        if self._spool is not None or self._closed:
            raise ValueError(f"DropoutWriter({str(self.path)!r}) is already open or closed")
        self._spool = {}
        try:
            for name in DropoutRecords.field_names():
                fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.{name}.", suffix=".tmp", dir=self._dir)
                self._spool[name] = (Path(tmp), os.fdopen(fd, "wb"))
        except BaseException:
            self.abort()
            raise

    def write(self, records: DropoutRecords) -> None:
        """Append one chunk of dropouts."""
        if self._spool is None:
            self.open()
        if not isinstance(records, DropoutRecords):
            raise TypeError(f"DropoutWriter.write: expected DropoutRecords, got {type(records).__name__}")
        try:
            for name, (_, fh) in self._spool.items():
                fh.write(getattr(records, name).tobytes())
        except BaseException:
            self.abort()
            raise
        self.count += len(records)
        self._counts += np.bincount(records.cause, minlength=len(DROPOUT_CAUSES))

    def counts_by_cause(self) -> dict[str, int]:
        """Dropouts written so far, per cause name (all causes present)."""
        return {name: int(self._counts[i]) for i, name in enumerate(DROPOUT_CAUSES)}

    def close(self) -> None:
        """Build the ``.npz`` from the spool, move it into place, remove the spool."""
        if self._closed:
            return
        if self._spool is None:
            self.open()
        try:
            arrays = {}
            columns = DropoutRecords.columns()
            for name, (tmp, fh) in self._spool.items():
                fh.close()
                col = columns[name]
                shape = (self.count,) if col.width is None else (self.count, col.width)
                if self.count:
                    arrays[name] = np.memmap(tmp, dtype=col.dtype, mode="r", shape=shape)
                else:
                    arrays[name] = np.zeros(shape, dtype=col.dtype)
            with atomic_open(self.path) as out:
                np.savez_compressed(out, cause_names=np.array(DROPOUT_CAUSES), **arrays)
            del arrays
        finally:
            self._remove_spool()
            self._closed = True

    def abort(self) -> None:
        """Remove the spool; no final file is written."""
        self._remove_spool()
        self._closed = True

    def _remove_spool(self) -> None:
        for tmp, fh in (self._spool or {}).values():
            with contextlib.suppress(Exception):
                fh.close()
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        self._spool = None
