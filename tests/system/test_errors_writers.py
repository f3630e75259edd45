"""One writer per output folder: every command that writes a folder (``run``, ``coverage``, ``campaign``, ``dataset``,
``tradeoff``) holds the folder's lock (``.NAME.lock`` beside it) while it runs, on any ending; a second writer is
refused with exit 2 and one line naming the holder's pid, before it writes anything.

The holder is a separate process that took the lock (:class:`~scanner_sim.io.run_dir.RunDirectory`, the lock
``run`` takes); the second writer is the command, in this process, with a small pass, so that on a tree where a
command took no lock it runs to the end and the test fails on its exit code.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from scanner_sim.cli import main
from scanner_sim.io.run_dir import OutputBusyError, OutputLock, RunDirectory, hold_output

REPO = Path(__file__).resolve().parents[2]
#: A process that takes the lock of the folder argv[1] the way ``run`` does, prints "held" and waits.
HOLDER = ("import sys, time; from scanner_sim.io.run_dir import RunDirectory\n"
          "RunDirectory(sys.argv[1]).open(); print('held', flush=True); time.sleep(600)")


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


@pytest.fixture
def holder():
    """Start a process holding the lock of a folder; yields a function folder -> the holder's pid."""
    procs = []

    def hold(folder: Path) -> int:
        proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(folder)], stdout=subprocess.PIPE, text=True,
                                env=_env())
        procs.append(proc)
        assert proc.stdout.readline().strip() == "held"
        return proc.pid

    yield hold
    for proc in procs:
        proc.kill()
        proc.communicate(timeout=30)


def _campaign_file(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text("format_version: 1\nscene: pool_panel\nsweep:\n  seed: [1]\n"
                    "options:\n  max_pulses: 20\n  render: false\n")
    return path


def _dataset_file(tmp_path: Path) -> Path:
    path = tmp_path / "tiny_dataset.yaml"
    path.write_text("scene: pool_panel\nseed: 1\nscenes: 1\nmax_pulses: 20\n")
    return path


COMMANDS = {
    "coverage": lambda t, out: ["coverage", "cable_survey", "--waters", "scene", "--instruments", "mul2023",
                                "--max-pulses", "20", "--workers", "0", "--no-render", "--quiet", "--out", str(out)],
    "campaign": lambda t, out: ["campaign", str(_campaign_file(t)), "--workers", "0", "--quiet", "--out", str(out)],
    "dataset": lambda t, out: ["dataset", str(_dataset_file(t)), "--workers", "0", "--quiet", "--out", str(out)],
    "tradeoff": lambda t, out: ["tradeoff", "pool_panel", "--levels", "fast", "--knobs", "--pulses", "30",
                                "--waveform-pulses", "5", "--repeat", "1", "--no-render", "--no-convergence",
                                "--json", "--out", str(out)],
    "run": lambda t, out: ["run", "pool_panel", "--max-pulses", "20", "--no-render", "--quiet", "--out", str(out)],
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_second_writer_of_a_study_folder_is_refused_naming_the_holder(command, holder, tmp_path, capsys):
    """Root cause: only ``run`` locked its folder (inside run_pass); ``coverage``, ``campaign`` and ``tradeoff``
    wrote their passes, tables and charts into a folder another process was writing, so one folder could hold a
    summary of one run beside the points of another, which a re-run then took as complete."""
    out = tmp_path / "study"
    pid = holder(out)
    code = main(COMMANDS[command](tmp_path, out))
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1, err
    assert f"pid {pid}" in err[0] and str(out) in err[0] and ".study.lock" in err[0], err[0]
    assert not out.exists()  # refused before anything was written


def test_the_lock_is_released_on_any_ending_and_never_looks_like_an_output(tmp_path):
    out = tmp_path / "study"
    for ending in (KeyboardInterrupt, SystemExit, ValueError):
        with pytest.raises(ending), hold_output(out):
            assert [p.name for p in tmp_path.iterdir()] == [".study.lock"]  # hidden, beside the folder
            raise ending()
        with OutputLock(out):  # free again
            pass
    assert list(tmp_path.iterdir()) == []


def test_nested_holds_of_one_command_share_the_lock_and_other_writers_are_refused(tmp_path):
    out = tmp_path / "study"
    with hold_output(out), hold_output(tmp_path / "." / "study"):  # a command and the library function it calls
        with RunDirectory(out) as folder:  # run: the command's lock, then run_pass's folder
            (folder / "summary.json").write_text("{}")
        assert (tmp_path / ".study.lock").read_text().split() == [str(os.getpid())]  # still held
        with pytest.raises(OutputBusyError, match=rf"pid {os.getpid()}"):
            OutputLock(out).acquire()  # any other lock of the folder is refused
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study"]


def test_a_writer_killed_outright_leaves_no_stale_lock(tmp_path):
    """The lock is an flock, which the kernel drops when its process dies: after kill -9 the lock file (with the
    dead pid) is still there, and the next writer takes it over at once."""
    out = tmp_path / "study"
    proc = subprocess.Popen([sys.executable, "-c", "import sys, time; from scanner_sim.io.run_dir import hold_output\n"
                             "with hold_output(sys.argv[1]):\n    print('held', flush=True); time.sleep(600)",
                             str(out)], stdout=subprocess.PIPE, text=True, env=_env())
    assert proc.stdout.readline().strip() == "held"
    with pytest.raises(OutputBusyError, match=rf"pid {proc.pid}"):
        OutputLock(out).acquire()
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)
    assert (tmp_path / ".study.lock").read_text().split() == [str(proc.pid)]
    started = time.monotonic()
    with OutputLock(out):
        assert (tmp_path / ".study.lock").read_text().split() == [str(os.getpid())]
    assert time.monotonic() - started < 1.0
