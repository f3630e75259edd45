"""Sizes a command cannot hold, or would spend hours on, are refused or bounded before any work: campaign
combinations, dataset scenes (drawn as they run, resumable), uncertainty ensembles, local workers, mesh triangles."""

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from conftest import ROOT as REPO

from scanner_sim.cli import main
from scanner_sim.config import SCENES_DIR, ConfigError

#: The address space of each subprocess [bytes]: a refusal needs far less; expanding 2 x 10**15 combinations more.
CAP_BYTES = 6 * 2**30


def _run(*argv: str, cwd: Path) -> subprocess.CompletedProcess:
    """``scanner-sim ARGV`` in a subprocess of this tree, its address space capped at :data:`CAP_BYTES`."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    env.pop("MULS_TRACEBACK", None)
    return subprocess.run([sys.executable, "-m", "scanner_sim.cli", *argv], capture_output=True, text=True, env=env,
                          cwd=cwd, timeout=300,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (CAP_BYTES, CAP_BYTES)))


def _lines(stderr: str) -> list[str]:
    """stderr without warnings (pool_panel's gate) and the first-run notice."""
    return [line for line in stderr.strip().splitlines() if ": warning: " not in line and not line.startswith("first run:")]


def _sweep(*lengths: int) -> dict:
    """A sweep of axes with ``lengths`` values each (seeds, altitudes, pulse rates, ...)."""
    keys = ["survey.seed", "platform.position_m", "scanner.pulse_rate_hz", "instrument.gate_delay_ns",
            "survey.max_pulses", "scanner.scan_rate_hz"]
    return {key: list(range(1, n + 1)) if key != "platform.position_m" else [[0, 0, -1 - i / n] for i in range(n)]
            for key, n in zip(keys, lengths)}


def test_campaign_of_a_million_combinations_is_refused_before_expanding(tmp_path):
    """A sweep of 10**6 combinations ran for minutes (every combination's scene was built and checked first), and one
    of 2 x 10**15 ended out of memory expanding the product. Root cause: the combinations were listed before anything
    counted them. The product of the axes' lengths is now counted when the file is read, and more than 10,000
    passes (a day of 10 s passes on a 2-core machine) is refused in one line, exit 2, nothing written."""
    from scanner_sim.runs.campaign import parse_campaign

    started = time.perf_counter()
    with pytest.raises(ConfigError, match=r"^sweep: 100 x 100 x 100 values give 1,000,000 combinations, more than the "
                                          r"10,000 passes a campaign runs"):
        parse_campaign({"scene": "pool_panel", "sweep": _sweep(100, 100, 100)})
    assert time.perf_counter() - started < 5.0
    path = tmp_path / "huge.yaml"
    path.write_text(yaml.safe_dump({"format_version": 1, "scene": "pool_panel",
                                    "sweep": _sweep(1000, 1000, 1000, 2, 1000, 1000)}, sort_keys=False))
    proc = _run("campaign", str(path), "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert _lines(proc.stderr) == ["scanner-sim campaign: error: sweep: 1,000 x 1,000 x 1,000 x 2 x 1,000 x 1,000 values "
                                   "give 2,000,000,000,000,000 combinations, more than the 10,000 passes a campaign "
                                   "runs; sweep fewer values, or split the sweep into campaigns"]
    assert not (tmp_path / "out").exists()


def test_uncertainty_with_ten_million_seeds_is_refused(capsys):
    """``scanner-sim uncertainty --seeds 10000000`` started ten million passes (years). Root cause: --seeds took any
    count. More than 10,000 passes (the spread of their shares then known to 0.7 %) is refused before the scene is
    read."""
    started = time.perf_counter()
    assert main(["uncertainty", "pool_panel", "--seeds", "10000000"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.strip() == ("scanner-sim uncertainty: error: --seeds = 10000000: at most 10,000 passes; "
                                         "their spread is then known to 0.7 % and more passes add hours, not precision")
    assert time.perf_counter() - started < 5.0


def test_local_cluster_for_two_passes_starts_no_more_workers_than_passes_or_cores():
    """``campaign --workers 12`` for 2 passes started 12 worker processes (15 with the cluster's own; 3.26 GB) on a
    2-core machine. Root cause: --workers was taken as given. The local cluster now has at most one worker per pass
    and per core: a worker more would idle, or share a core and add only its memory."""
    from scanner_sim.runs.cluster import capped_workers, default_workers, maybe_client

    cores = default_workers()
    assert capped_workers(12, 2) == min(2, cores)
    assert capped_workers(12, 1) == 1
    assert capped_workers(12) == min(12, cores)
    with maybe_client(workers=12, passes=2, dashboard=False) as client:
        assert len(client.scheduler_info()["workers"]) == min(2, cores)


def test_mesh_file_of_a_billion_triangles_is_refused_from_its_header(tmp_path):
    """A 3-million-triangle STL was still loading after 60 s at 3.3 GB. Root cause: the file was loaded whole before
    anything judged its size. A binary STL's header gives its triangle count (the file is 84 + 50 n bytes): a billion
    triangles (a sparse 50 GB file here) would need about 1 TB to load at 1 kB a triangle, and is refused in one line
    naming the object and the file, at once, in bounded memory."""
    stl = tmp_path / "scan.stl"
    with open(stl, "wb") as fh:
        fh.write(b"\0" * 80 + (10**9).to_bytes(4, "little"))
        fh.truncate(84 + 50 * 10**9)
    scene = yaml.safe_load((SCENES_DIR / "pool_panel.yaml").read_text())
    scene["objects"].append({"type": "mesh", "name": "wreck", "file": str(stl), "translate_m": [0, 0, -8]})
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    started = time.perf_counter()
    proc = _run("validate", "--build", str(path), cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    (line,) = _lines(proc.stderr)
    assert f"objects[1].file = {str(stl)!r} (object 'wreck'): 1,000,000,000 triangles would need about 1,000.0 GB of " \
           "memory to load" in line
    assert time.perf_counter() - started < 60.0


def _spec(tmp_path: Path, scenes: int) -> Path:
    spec = yaml.safe_load((SCENES_DIR / "datasets" / "example.yaml").read_text())
    path = tmp_path / "million.yaml"
    path.write_text(yaml.safe_dump(spec | {"name": "million", "scenes": scenes, "max_pulses": 200}, sort_keys=False))
    return path


def test_dataset_of_a_million_scenes_draws_lazily():
    """``scanner-sim dataset`` of 10**6 scenes drew and built every scene before the first ran (617 MB and no output
    after 55 s). Root cause: the spec's scenes were all drawn (about 10 ms each) and their set-ups checked (a scene
    build each) up front. Scenes are now drawn when asked for; reading the spec draws the first 32."""
    from scanner_sim.runs.dataset import parse_dataset

    spec = yaml.safe_load((SCENES_DIR / "datasets" / "example.yaml").read_text())
    started = time.perf_counter()
    dataset = parse_dataset(spec | {"scenes": 10**6})
    assert time.perf_counter() - started < 5.0
    assert len(dataset.scenes) == 10**6
    last = dataset.scenes[-1]
    assert last.index == 999_999 and last.name == "scene_999999"
    # a scene is what it is whatever the number of scenes: the same as in a dataset of the first 40
    small = parse_dataset(spec | {"scenes": 40})
    assert dataset.scenes[35].drawn == small.scenes[35].drawn and dataset.scenes[35].seed == small.scenes[35].seed


def _start(spec: Path, out: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    return subprocess.Popen([sys.executable, "-m", "scanner_sim.cli", "dataset", str(spec), "--out", str(out),
                             "--workers", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _wait_for(path: Path, proc: subprocess.Popen, timeout_s: float = 600.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"{path} not written"
        time.sleep(0.2)


@pytest.mark.slow
def test_dataset_of_a_million_scenes_interrupted_after_the_first_keeps_it_and_resumes(tmp_path):
    """A dataset of 10**6 scenes writes its first scene as soon as it has run; Ctrl-C then ends it (exit 130) keeping
    that scene, and the next run into the folder skips the scenes kept (their files untouched) and goes on with the
    next.

    The resumed run is interrupted once it has written a scene the first run had not: the first run, polled every
    0.2 s, may complete a second scene of 200 pulses before its Ctrl-C lands, and the resumed run, waited for on that
    scene, was then interrupted during Python's start-up, before the command could answer (exit -2 instead of 130)."""
    spec, out = _spec(tmp_path, 10**6), tmp_path / "out"
    first = out / "scenes" / "scene_000000"
    proc = _start(spec, out)
    _wait_for(first / "summary.json", proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert json.loads((out / "spec.json").read_text())["spec"]["scenes"] == 10**6
    assert not (out / "manifest.json").exists()
    kept = {p.name: p.stat().st_mtime_ns for p in first.iterdir()}
    done = sum(1 for _ in (out / "scenes").glob("scene_*/summary.json"))
    assert (out / "scenes" / f"scene_{done - 1:06d}" / "summary.json").exists()  # the scenes kept: 0 .. done - 1
    proc = _start(spec, out)
    _wait_for(out / "scenes" / f"scene_{done:06d}" / "summary.json", proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert {p.name: p.stat().st_mtime_ns for p in first.iterdir()} == kept
