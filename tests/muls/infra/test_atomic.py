"""The one atomic writer of both packages (muls/infra/atomic.py): a file appears under its final name whole or not at
all, and the rename is flushed with the folder."""

from __future__ import annotations

import errno
import os

import pytest

from muls.infra import atomic


def test_interrupt_removes_temp_and_keeps_old(tmp_path):
    final = tmp_path / "summary.json"
    final.write_text("old")
    with pytest.raises(KeyboardInterrupt), atomic.atomic_path(final) as tmp:
        tmp.write_text("half")
        assert tmp.name.startswith(".summary.json.") and tmp.name.endswith(".tmp")
        raise KeyboardInterrupt
    assert final.read_text() == "old" and os.listdir(tmp_path) == ["summary.json"]
    with pytest.raises(ValueError, match="does not exist"), atomic.atomic_path(tmp_path / "missing" / "x.json"):
        pass


def test_write_atomically_keeps_the_suffix_and_fsyncs_the_folder(tmp_path, monkeypatch):
    """A writer that picks its format by the suffix (matplotlib) is given a hidden name ending in the final suffix;
    the file lands whole, nothing else is left, and the folder holding the rename is fsynced (the callback form
    once had its own copy of the write, which never fsynced the folder)."""
    synced, seen = [], []
    real = atomic.fsync_dir
    monkeypatch.setattr(atomic, "fsync_dir", lambda folder: (synced.append(folder), real(folder)))

    def write(tmp: str) -> None:
        seen.append(tmp)
        with open(tmp, "w") as fh:
            fh.write("picture")

    final = tmp_path / "plot.png"
    atomic.write_atomically(write, final)
    assert os.path.basename(seen[0]).startswith(".plot.png.") and seen[0].endswith(".tmp.png")
    assert final.read_text() == "picture" and os.listdir(tmp_path) == ["plot.png"]
    assert synced == [tmp_path]


def test_a_failed_write_names_the_final_file_and_leaves_nothing(tmp_path):
    """A full disk raised while writing the hidden file is reported under the name the user asked for."""
    def write(tmp: str) -> None:
        with open(tmp, "w") as fh:
            fh.write("half")
        raise OSError(errno.ENOSPC, "No space left on device", tmp)

    final = tmp_path / "experiment.json"
    with pytest.raises(OSError) as exc:
        atomic.write_atomically(write, final)
    assert exc.value.filename == str(final) and os.listdir(tmp_path) == []
