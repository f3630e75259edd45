"""One line and the right exit code for the faults found last round: names beyond the file system's limit, LAS, LAZ
and PLY files cut short, empty or binary campaign files, a set-up refusal inside a campaign, and Ctrl-C on a Dask
campaign. Each test names the failure it pins; the docstring says why it happened.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from scanner_sim.cli import main
from scanner_sim.config import ConfigError, MeshObject, load_scene
from scanner_sim.survey.pipeline import run_pass
from scanner_sim.survey.setup import PassOptions
from scanner_sim.world.mesh_file import load_mesh_file

REPO = Path(__file__).resolve().parents[2]


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env.pop("MULS_TRACEBACK", None)
    return env


def _cli(*args, cwd):
    """``scanner-sim ARGS`` in a subprocess: (exit code, stderr's non-empty lines)."""
    proc = subprocess.run([sys.executable, "-m", "scanner_sim.cli", *args], capture_output=True, text=True,
                          env=_env(), cwd=cwd, timeout=600)
    return proc.returncode, [line for line in proc.stderr.splitlines() if line.strip()]


# -- names beyond the file system's limit -------------------------------------------------------------------------
@pytest.mark.parametrize("argv, words", [
    (["run", "pool_panel", "--out", "a" * 300], ["argument --out", "300 bytes", "233"]),
    (["schema", "--out", "s" * 250 + ".json"], ["argument --out", "255 bytes", "241"]),
    (["validate", "v" * 300 + ".yaml"], ["file name too long", "255 bytes"]),
])
def test_an_output_or_scene_name_over_255_bytes_is_one_line_exit_2(argv, words, tmp_path):
    """Root cause: argparse's checks of --out stat the path, and the OS answers ENAMETOOLONG, an OSError that
    argparse lets through as a traceback; a scene path too long ended as exit 1, as if the machine had failed."""
    code, lines = _cli(*argv, cwd=tmp_path)
    assert code == 2 and len(lines) == 1, lines
    assert "Traceback" not in lines[0] and all(w in lines[0] for w in words), lines[0]


def test_a_sweep_value_giving_a_pass_folder_over_255_bytes_is_refused_before_any_pass(tmp_path, capsys):
    """Root cause: a pass's folder is named after its sweep values and was only made when its pass was written,
    after it ran: the campaign simulated the pass, then failed with "File name too long" and exit 1."""
    path = tmp_path / "long.yaml"
    path.write_text(f"format_version: 1\nscene: pool_panel\nsweep:\n  description: ['{'d' * 300}']\n"
                    "options:\n  max_pulses: 20\n  render: false\n")
    started = time.perf_counter()
    code = main(["campaign", str(path), "--workers", "0", "--quiet", "--out", str(tmp_path / "out")])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and "description=ddd" in err[0] and "255" in err[0], err
    assert not (tmp_path / "out").exists() and time.perf_counter() - started < 10


# -- files cut short ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def clouds(tmp_path_factory):
    """points.las and points.laz of one small pass (300 pulses)."""
    out = tmp_path_factory.mktemp("clouds") / "pass"
    run_pass(load_scene("pool_panel").with_overrides({"output.laz": True}), out,
             PassOptions(max_pulses=300, progress=False, render=False))
    return out


@pytest.mark.parametrize("name, keep, words", [
    ("points.las", 10_000, ["truncated", "header promises", "points"]),
    ("points.laz", 4_000, ["compressed points end early"]),
    ("points.las", 200, ["not a readable LAS/LAZ file"]),
])
def test_a_truncated_las_or_laz_is_refused_naming_it(name, keep, words, clouds, tmp_path):
    """Root cause: laspy reads an uncompressed LAS cut short as the points it holds (a file of 300 points cut at
    10 kB read as 133, and swath and view went on, exit 0), and a LAZ cut short raised lazrs's own LazrsError, an
    internal error (exit 1)."""
    cut = tmp_path / f"cut_{name}"
    cut.write_bytes((clouds / name).read_bytes()[:keep])
    assert cut.stat().st_size < (clouds / name).stat().st_size
    code, lines = _cli("swath", str(cut), cwd=tmp_path)
    assert code == 2 and len(lines) == 1, lines
    assert cut.name in lines[0] and all(w in lines[0] for w in words), lines[0]


def test_a_truncated_ascii_ply_mesh_is_refused_naming_the_object(tmp_path):
    """Root cause: trimesh reads an ASCII PLY as the lines it holds, whatever its header promises: a mesh of 100,000
    faces cut after the first loaded as one triangle, and the pass ran, exit 0."""
    path = tmp_path / "wreck.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 100000\nproperty list uchar int vertex_indices\nend_header\n"
                    "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    with pytest.raises(ConfigError) as exc:
        load_mesh_file(MeshObject.model_validate({"type": "mesh", "name": "wreck", "file": str(path)}), 2)
    text = str(exc.value)
    assert "\n" not in text and "objects[2]" in text and "wreck.ply" in text, text
    assert "truncated" in text and "100,000 faces" in text and "holds 1 " in text, text


# -- campaign files -----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("content, words", [
    (b"", ["empty"]),
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", ["binary data"]),
    ("sweep: café".encode("latin-1"), ["not UTF-8"]),
    (b"- 1\n- 2\n", ["not a mapping of campaign keys"]),
])
def test_an_empty_or_binary_campaign_file_is_named(content, words, tmp_path, capsys):
    """Root cause: load_campaign read the file with read_text and handed the value to the model: an empty file
    gave "scene: missing required key" and a binary one a codec error, neither naming the file."""
    path = tmp_path / "mine.yaml"
    path.write_bytes(content)
    code = main(["campaign", str(path), "--workers", "0", "--out", str(tmp_path / "out")])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and "mine.yaml" in err[0] and all(w in err[0] for w in words), err


# -- set-up refusals inside a campaign ----------------------------------------------------------------------------
def test_a_set_up_refusal_in_a_campaign_is_found_before_any_pass_runs(tmp_path, capsys):
    """Root cause: a campaign validated each combination's scene keys but not its pass set-up (a start after the
    track's end, the vehicle under the seabed, a pass too big), which ran in the pass's task: the passes before it
    ran and were written, and on Dask the refusal was retried and printed with Dask's stack three times."""
    path = tmp_path / "late.yaml"
    path.write_text("format_version: 1\nscene: cable_survey\nsweep:\n  survey.start_s: [0, 1000]\n"
                    "options:\n  max_pulses: 50\n  render: false\n")
    code = main(["campaign", str(path), "--workers", "0", "--quiet", "--out", str(tmp_path / "out")])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1, err
    assert "survey.start_s=1000" in err[0] and "survey.start_s = 1000" in err[0] and "end of the track" in err[0]
    assert not list((tmp_path / "out").glob("*/summary.json"))  # no pass ran


@pytest.mark.slow
def test_a_set_up_refusal_in_a_task_is_not_retried(tmp_path, monkeypatch):
    """Root cause: Dask retries any exception a task raises; a bad set-up (a ValueError) gives the same error on
    every try, so it ran three times and each worker logged its stack. The task now returns it."""
    from scanner_sim.runs import jobs
    from scanner_sim.runs.cluster import dask_client
    from scanner_sim.runs.tasks import PassJob

    monkeypatch.setattr(jobs, "check_jobs", lambda _: None, raising=False)  # as if a check were missed
    late = load_scene("cable_survey").with_overrides({"survey.start_s": 1000.0, "survey.max_pulses": 50})
    with dask_client(workers=1, dashboard=False) as client:
        client.run(lambda: __import__("logging").getLogger("distributed").setLevel("ERROR"))
        outcome, = jobs.run_jobs([PassJob("late", late, PassOptions(progress=False, render=False))], tmp_path,
                                 client, retries=2, progress=False)
        logs = [text for worker in client.get_worker_logs().values() for _, text in worker]
    assert outcome.status == "failed" and "survey.start_s = 1000" in outcome.error
    assert not [text for text in logs if "Compute Failed" in text], logs  # tried once, logged by no worker


# -- Ctrl-C on a Dask campaign ------------------------------------------------------------------------------------
@pytest.mark.slow
def test_ctrl_c_on_a_dask_campaign_is_one_line_exit_130_and_keeps_finished_passes(tmp_path):
    """Root cause: Ctrl-C reaches every process of the terminal's group: each Dask worker raised its own
    KeyboardInterrupt and the scheduler and nannies logged the cancelled tasks, 23 to 48 lines. The cluster's
    processes now ignore SIGINT (the command closes them) and Dask logs only critical errors."""
    campaign = tmp_path / "c.yaml"
    campaign.write_text("format_version: 1\nscene: cable_survey\nsweep:\n  seed: [1, 2, 3, 4, 5, 6]\n"
                        "options:\n  max_pulses: 4000\n  render: false\n")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "scanner_sim.cli", "campaign", str(campaign), "--workers", "2",
                             "--quiet", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=_env(), cwd=tmp_path, start_new_session=True)
    deadline = time.monotonic() + 600
    while not list(out.glob("*/summary.json")) and time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.2)
    finished = {p.parent.name: p.read_text() for p in out.glob("*/summary.json")}
    os.killpg(proc.pid, signal.SIGINT)  # as Ctrl-C in a terminal: the whole process group
    _, err = proc.communicate(timeout=120)
    lines = [line for line in err.splitlines() if line.strip()]
    assert proc.returncode == 130 and len(lines) == 1 and "interrupted (Ctrl-C)" in lines[0], err
    for name, text in finished.items():
        assert (out / name / "summary.json").read_text() == text and json.loads(text)["pulses"] == 4000


# -- the Python API -----------------------------------------------------------------------------------------------
def _api_calls():
    import muls
    import scanner_sim as sim

    config = sim.load_scene("pool_panel")
    options = sim.PassOptions(max_pulses=5, progress=False)
    return {
        "config": [lambda: sim.simulate_pass("pool_panel"), lambda: sim.run_pass({"name": "x"}, "out"),
                   lambda: sim.build_scene("pool_panel"), lambda: sim.PassSetup.build(None)],
        "options": [lambda: sim.simulate_pass(config, {"max_pulses": 5}), lambda: sim.run_pass(config, "out", "fast")],
        "scene": [lambda: sim.simulate_pass(config, options, scene="pool_panel")],
        "out_dir": [lambda: sim.run_pass(config, 5, options)],
        "PassOptions.max_pulses": [lambda: sim.PassOptions(max_pulses="5000")],
        "PassOptions.waveforms": [lambda: sim.PassOptions(waveforms="all")],
        "PassOptions.render_size": [lambda: sim.PassOptions(render_size=800)],
        "PassOptions.coverage": [lambda: sim.PassOptions(coverage=0.25)],
        "PassOptions.progress": [lambda: sim.PassOptions(progress="no")],
        "overrides": [lambda: config.with_overrides("survey.seed=3"), lambda: config.with_overrides({1: 2})],
        "water": [lambda: muls.instrument_preset("single_channel", "coastal_ocean")],
    }


@pytest.mark.parametrize("parameter", list(_api_calls()))
def test_the_python_api_answers_a_wrong_type_with_a_type_error_naming_the_parameter(parameter, tmp_path,
                                                                                     monkeypatch):
    """Root cause: the entry points used their arguments' attributes without checking their types, so a scene
    name where a SceneConfig belongs, a dict for PassOptions or a string for an option's number ended in an
    AttributeError (or a TypeError from deep inside) that named no parameter."""
    monkeypatch.chdir(tmp_path)
    for call in _api_calls()[parameter]:
        with pytest.raises(TypeError) as exc:
            call()
        assert str(exc.value).startswith(f"{parameter} must be "), str(exc.value)
    assert list(tmp_path.iterdir()) == []  # refused before anything was written
