"""Reliability, bounded before it starts: every count and size a user gives is checked against what the machine can
do before anything is allocated, and refused with exit 2 and one line naming the option, its value and its limit
(docs/errors.md, "Command-line arguments").

Each case runs the command in a subprocess with its address space capped (RLIMIT_AS), so that code without the
check fails fast and harmlessly (a MemoryError, or VTK's abort) instead of filling the machine's memory.
"""

import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from muls.cli import main as muls_main
from scanner_sim import io
from scanner_sim.records.point_records import PointRecords
from scanner_sim.render import point_cloud

REPO = Path(__file__).resolve().parents[2]
#: The address space of each subprocess [bytes]: a command starts in well under this.
CAP_BYTES = 6 * 2**30
#: What a refusal ends with: the limit on this machine, in the option's own terms.
LIMIT = r"; (at most [\d,]+ [a-z ()]+|cells of at least [\d.e-]+ m) on this machine$"
#: The memory figures of a refusal (muls.infra.memory.check_memory).
MEMORY = (r" would need about [\d,.]+ [GM]B of memory, more than the [\d,.]+ [GM]B it may use "
          r"\(80% of the [\d,.]+ [GM]B available\)")


def _run(module: str, *argv: str, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env.pop("MULS_TRACEBACK", None)
    return subprocess.run([sys.executable, "-m", module, *argv], capture_output=True, text=True, env=env, cwd=cwd,
                          timeout=300, preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (CAP_BYTES, CAP_BYTES)))


def _lines(stderr: str) -> list[str]:
    """stderr without the set-up's warnings (pool_panel's gate) and the first-run notice."""
    return [line for line in stderr.strip().splitlines() if ": warning: " not in line and not line.startswith("first run:")]


MEMORY_CASES = {
    "experiment --shots": ("muls.cli", "muls experiment", ["experiment", "pond", "--shots", "1000000000", "--no-plot"],
                           "--shots = 1000000000: 3 distances x 1,000,000,000 shots"),
    "maxrange --shots": ("muls.cli", "muls maxrange", ["maxrange", "--shots", "1000000000", "--no-plot"],
                         "--shots = 1000000000: up to 36 ranges at once x 1,000,000,000 shots"),
    "precision --shots": ("muls.cli", "muls precision", ["precision", "--shots", "1000000000", "--no-plot"],
                          "--shots = 1000000000: 3 ranges x 1,000,000,000 shots"),
    "bench --pulses": ("muls.cli", "muls bench", ["bench", "--pulses", "1000000000"],
                       "--pulses = 1000000000: 1,000,000,000 windowed pulses"),
    "bench --full-pulses": ("muls.cli", "muls bench", ["bench", "--full-pulses", "100000000"],
                            "--full-pulses = 100000000: 100,000,000 full records"),
    "tradeoff --pulses": ("scanner_sim.cli", "scanner-sim tradeoff", ["tradeoff", "pool_panel", "--pulses", "1000000000"],
                          "--pulses = 1000000000: 14 runs keeping the points of 1,000,000,000 pulses and the records of 500"),
    "coverage --cell-m": ("scanner_sim.cli", "scanner-sim coverage", ["coverage", "--cell-m", "0.0001", "--workers", "0"],
                          "--cell-m = 0.0001: coverage over 42,000,000,000 cells of the 30 x 14 m seabed, 1 pass at once,"),
    "bench-rays --pulses": ("scanner_sim.cli", "scanner-sim bench-rays", ["bench-rays", "--pulses", "100000000"],
                            "--pulses = 100000000: a chunk of 100,000,000 pulses x 19 sub-rays"),
}


@pytest.mark.parametrize("case", list(MEMORY_CASES))
def test_counts_beyond_the_memory_are_refused_before_allocating_not_out_of_memory_naming_chunk_pulses(case, tmp_path):
    """``--shots 1e9`` (muls experiment, maxrange, precision), ``muls bench --pulses``, ``scanner-sim tradeoff
    --pulses 1e9`` (a static scene), ``coverage --cell-m 0.0001`` and ``bench-rays --pulses`` ended with exit 1 and
    "out of memory; use smaller chunks (survey.chunk_pulses)", even in muls. Root cause: each option was checked
    only as a number >= 1 or > 0, and what it sizes (one simulate call of every shot, every run's points, a
    coverage tally per cell, one chunk of rays) was allocated whole; the MemoryError then met run_guarded's generic
    advice, which names a scene key neither command was given."""
    module, prog, argv, what = MEMORY_CASES[case]
    proc = _run(module, *argv, cwd=tmp_path)
    lines = _lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith(f"{prog}: error: {what}"), lines[0]
    assert re.search(MEMORY + LIMIT, lines[0]), lines[0]


def test_multiscatter_plate_beyond_any_echo_is_refused_not_out_of_memory(tmp_path):
    """``muls multiscatter --range-m 1e6`` ended with exit 1 and the survey.chunk_pulses advice. Root cause: the
    run's histograms span the echo's time, 2 r / c_w, at 0.5 ns a bin (20 batches, several tallies), and no range
    was refused, though no light comes back from beyond 2 a r = 40 (absorption alone)."""
    proc = _run("muls.cli", "multiscatter", "--water", "pond", "--range-m", "1e6", "--no-plot", cwd=tmp_path)
    lines = _lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0] == ("muls multiscatter: error: --range-m = 1000000.0: no light comes back from so far in pond: "
                        "absorption alone leaves e^-440,000 of it (none beyond e^-40); at most 90.9 m in this water")


def test_window_size_beyond_what_vtk_can_render_is_refused_not_aborted(tmp_path):
    """``scanner-sim view --window-size 50000 50000`` aborted in C++ (std::bad_alloc, SIGABRT, no line of ours).
    Root cause: only a side below 16 px was refused; VTK allocated the 2.5e9-pixel framebuffer itself (about 100
    bytes a pixel with the screenshot), and a C++ exception ends the process. A side beyond 16384 px (what GPU
    drivers commonly render) or a picture beyond the memory is now refused before VTK starts."""
    las = tmp_path / "points.las"  # a few points: VTK's picture is all the memory the old code asked for
    n = 8
    fields = {name: np.ones((n,) if col.width is None else (n, col.width), col.dtype)
              for name, col in PointRecords.columns().items()}
    fields["xyz"] = np.column_stack([np.arange(n), np.arange(n) % 3, np.zeros(n)]).astype(float)
    io.write_las(las, PointRecords(**fields), offset_m=np.zeros(3))
    proc = _run("scanner_sim.cli", "view", str(las), "--screenshot", str(tmp_path / "v.png"), "--window-size",
                "50000", "50000", cwd=tmp_path)
    assert proc.returncode == 2 and _lines(proc.stderr) == [
        "scanner-sim view: error: --window-size = 50000 50000: at most 16384 px a side (the largest framebuffer OpenGL "
        "drivers commonly render)"], proc.stderr
    with pytest.raises(ValueError) as refused:  # a side VTK renders, a picture too large for the machine's memory
        point_cloud.check_window_size("--window-size", (16384, 16384), available_bytes=10**10)
    assert str(refused.value) == (
        "--window-size = 16384 16384: a 16,384 x 16,384 px picture would need about 26.8 GB of memory, more than the "
        "8.0 GB it may use (80% of the 10.0 GB available); at most 80,000,000 pixels (width x height) on this machine")


@pytest.mark.parametrize("argv, option, limit", [
    (["multiscatter", "--water", "pond", "--range-m", "5", "--packets", str(10**20), "--no-plot"], "--packets",
     "461,168,601,842,738,780"),
    (["validate-pass", "--packets", str(10**20)], "--packets", "461,168,601,842,738,780"),
    (["mobley1993", "--photons", str(10**20), "--no-plot"], "--photons", "92,233,720,368,547,756"),
])
def test_monte_carlo_counts_beyond_64_bits_are_refused_not_an_internal_error(argv, option, limit, capsys):
    """``--packets 10**20`` ended with exit 1 and "internal error: TypingError: ... Int value is too large". Root
    cause: the compiled kernels number packets in 64-bit integers (a batch's share as batch x packets), and the
    count went to numba unchecked."""
    code = muls_main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert err == (f"muls {argv[0]}: error: {option} = {10**20}: at most {limit} (the Monte Carlo numbers its packets "
                   "in 64 bits)")
