"""The output folder (docs/errors.md), in process: the run folder (lock, hidden sibling, swap) never damages an earlier run,
atomic files leave nothing half-written, and a seed gives byte-identical files on any day.
"""

import datetime
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from scanner_sim.config import load_scene
from scanner_sim.io import atomic_path, read_las, write_las
from scanner_sim.io import las as las_module
from scanner_sim.io.run_dir import OutputBusyError, RunDirectory, abort_on_error
from scanner_sim.records.point_records import PointRecords
from scanner_sim.survey.pipeline import run_pass
from scanner_sim.survey.setup import PassOptions


def _earlier_run(out, text="earlier"):
    out.mkdir(parents=True)
    (out / "summary.json").write_text(json.dumps({"run": text}))
    (out / "points.las").write_text(text)


def _listing(folder):
    return sorted(p.name for p in folder.iterdir())


def test_a_complete_run_replaces_the_earlier_one_whole(tmp_path):
    out = tmp_path / "out"
    _earlier_run(out)
    (out / "points.class.png").write_text("a picture of the earlier run")
    with RunDirectory(out) as folder:
        assert folder.parent == tmp_path and folder.name.startswith(".out.run-")
        assert json.loads((out / "summary.json").read_text()) == {"run": "earlier"}  # untouched while writing
        (folder / "summary.json").write_text(json.dumps({"run": "new"}))
    assert _listing(out) == ["summary.json"] and json.loads((out / "summary.json").read_text()) == {"run": "new"}
    assert _listing(tmp_path) == ["out"]  # no lock, no hidden folder, no earlier run left aside


@pytest.mark.parametrize("error", [KeyboardInterrupt, SystemExit, OSError, ValueError])
def test_an_unfinished_run_leaves_the_earlier_one_as_it_was(error, tmp_path):
    out = tmp_path / "out"
    _earlier_run(out)
    with pytest.raises(error), RunDirectory(out) as folder:
        (folder / "points.las").write_text("half a new run")
        raise error()
    assert _listing(out) == ["points.las", "summary.json"] and (out / "points.las").read_text() == "earlier"
    assert _listing(tmp_path) == ["out"]


def test_run_pass_leaves_the_earlier_run_when_it_fails(tmp_path, monkeypatch):
    """run_pass opens its folder without a with-block; abort_on_error removes the unfinished one."""
    from scanner_sim import io

    out = tmp_path / "out"
    _earlier_run(out)

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(io, "write_summary_json", full_disk)
    with pytest.raises(OSError):
        run_pass(load_scene("pool_panel"), out, PassOptions(max_pulses=20, progress=False, render=False))
    assert (out / "points.las").read_text() == "earlier" and _listing(tmp_path) == ["out"]


def test_abort_on_error_aborts_what_the_function_left_open(tmp_path):
    @abort_on_error
    def writes_then_fails():
        run = RunDirectory(tmp_path / "out").open()
        (run.path / "x").write_text("x")
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        writes_then_fails()
    assert _listing(tmp_path) == []


def test_a_second_run_is_refused_while_the_first_writes(tmp_path):
    first = RunDirectory(tmp_path / "out").open()
    try:
        with pytest.raises(OutputBusyError, match=rf"is being written by another run \(pid {os.getpid()}, lock"):
            RunDirectory(tmp_path / "out").open()
        code = ("import sys; from scanner_sim.io.run_dir import RunDirectory, OutputBusyError\n"
                "try:\n    RunDirectory(sys.argv[1]).open()\nexcept OutputBusyError as e:\n    print(e); sys.exit(3)")
        proc = subprocess.run([sys.executable, "-c", code, str(tmp_path / "out")], capture_output=True, text=True)
        assert proc.returncode == 3 and f"pid {os.getpid()}" in proc.stdout
    finally:
        first.abort()
    with RunDirectory(tmp_path / "out"):
        pass


def test_a_stale_lock_and_leftovers_of_a_killed_run_are_taken_over(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    (tmp_path / ".out.lock").write_text(f"{dead}\n")
    (tmp_path / f".out.run-{dead}-0badc0de").mkdir()
    (tmp_path / f".out.run-{dead}-0badc0de" / ".points.las.1234.tmp").write_text("half")
    with RunDirectory(tmp_path / "out") as folder:
        assert (tmp_path / ".out.lock").read_text().split() == [str(os.getpid())]
        (folder / "summary.json").write_text("{}")
    assert _listing(tmp_path) == ["out"]


@pytest.mark.parametrize("setup, message", [
    (lambda t: (t / "out").write_text("a file"), "is a file"),
    (lambda t: (t / "f").write_text("a file"), "lies under"),
    (lambda t: ((t / "out").mkdir(), (t / "out" / "thesis.tex").write_text("mine")), "holds files but no complete run"),
])
def test_folders_that_are_not_runs_are_never_replaced(setup, message, tmp_path):
    setup(tmp_path)
    target = tmp_path / ("f/out" if message == "lies under" else "out")
    before = sorted(str(p) for p in tmp_path.rglob("*"))
    with pytest.raises(ValueError, match=message):
        RunDirectory(target).open()
    assert sorted(str(p) for p in tmp_path.rglob("*")) == before


def test_the_current_folder_is_never_replaced(tmp_path, monkeypatch):
    _earlier_run(tmp_path / "here")
    monkeypatch.chdir(tmp_path / "here")
    for target in (".", tmp_path / "here", tmp_path):
        with pytest.raises(ValueError, match="is the current folder or holds it"):
            RunDirectory(target).open()


def test_atomic_file_is_removed_on_any_error_and_names_the_file(tmp_path):
    final = tmp_path / "table.csv"
    final.write_text("previous")
    with pytest.raises(OSError) as exc, atomic_path(final) as tmp:
        tmp.write_text("half")
        raise OSError(28, "No space left on device")
    assert exc.value.filename == str(final)
    assert _listing(tmp_path) == ["table.csv"] and final.read_text() == "previous"


# -- reproducible files --------------------------------------------------------------------------------------
def _records(n=5) -> PointRecords:
    fields = {}
    for name, col in PointRecords.columns().items():
        shape = (n,) if col.width is None else (n, col.width)
        fields[name] = np.ones(shape, dtype=col.dtype)
    return PointRecords(**fields)


class _OtherDay(datetime.date):
    """A clock on another day: date.today() and datetime.now() both move."""

    @classmethod
    def today(cls):
        return cls(1999, 12, 31)


def test_las_header_date_comes_from_the_pass_not_the_clock(tmp_path, monkeypatch):
    monkeypatch.delenv("SOURCE_DATE_EPOCH", raising=False)
    write_las(tmp_path / "a.las", _records())
    monkeypatch.setattr(las_module, "date", _OtherDay)  # were the clock read, the header would say 1999-12-31
    write_las(tmp_path / "b.las", _records())
    assert (tmp_path / "a.las").read_bytes() == (tmp_path / "b.las").read_bytes()
    import laspy

    assert laspy.read(tmp_path / "a.las").header.creation_date == datetime.date(2011, 9, 14)  # GPS 1e9 s
    write_las(tmp_path / "c.las", _records(), gps_time_offset_s=3.0e8)  # a pass placed at another epoch
    assert laspy.read(tmp_path / "c.las").header.creation_date == datetime.date(2021, 3, 17)


def test_source_date_epoch_sets_the_las_date(tmp_path, monkeypatch):
    import laspy

    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    write_las(tmp_path / "a.las", _records())
    assert laspy.read(tmp_path / "a.las").header.creation_date == datetime.date(2023, 11, 14)
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "yesterday")
    with pytest.raises(ValueError, match="SOURCE_DATE_EPOCH = 'yesterday': must be whole seconds"):
        write_las(tmp_path / "b.las", _records())
    assert not (tmp_path / "b.las").exists()


def test_a_seed_gives_byte_identical_files_on_any_day(tmp_path, monkeypatch):
    """Two passes of one seed, the second on a faked other day: every file but the summary's timings is the same
    byte for byte."""
    monkeypatch.delenv("SOURCE_DATE_EPOCH", raising=False)
    options = PassOptions(max_pulses=400, waveforms=2, progress=False, render=False)
    config = load_scene("mine_field")
    run_pass(config, tmp_path / "a", options)
    monkeypatch.setattr(las_module, "date", _OtherDay)
    run_pass(config, tmp_path / "b", options)
    names = _listing(tmp_path / "a")
    assert names == _listing(tmp_path / "b")
    assert {"points.las", "dropouts.npz", "coverage_grid.npz", "waveforms.npz", "scene.ply"} <= set(names), names
    for name in names:
        a, b = (tmp_path / "a" / name).read_bytes(), (tmp_path / "b" / name).read_bytes()
        if name == "summary.json":
            timings = ("wall_s", "setup_s", "compile_s", "pulses_per_s")
            a, b = ({k: v for k, v in json.loads(x).items() if k not in timings} for x in (a, b))
        assert a == b, name
    assert len(read_las(tmp_path / "a" / "points.las")) > 0
