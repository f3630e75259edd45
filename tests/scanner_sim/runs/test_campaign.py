"""Campaigns on Dask (docs/campaigns.md): every pass, whole or cut in segments, is byte-identical to the serial
run_pass; a killed worker costs only its task; a re-run skips complete passes; the file is checked strictly.

The cluster is a real LocalCluster of 2 worker processes (1 thread each) on loopback, shared by the module.
"""

import json
import os
import threading
import time
from pathlib import Path
from signal import SIGKILL

import pytest
import yaml
from conftest import run_cli

from scanner_sim.cli import main
from scanner_sim.config import SCENES_DIR, ConfigError, load_scene
from scanner_sim.runs.campaign import load_campaign, parse_campaign
from scanner_sim.runs.cluster import dask_client
from scanner_sim.runs.jobs import TIMING_KEYS, run_pass_segmented
from scanner_sim.survey.pipeline import run_pass
from scanner_sim.survey.setup import PassOptions

EXAMPLE = SCENES_DIR / "campaigns" / "example_campaign.yaml"
#: The files whose bytes must match the serial pass's (summary.json is compared without its timings).
SAME_BYTES = ("points.las", "dropouts.npz", "coverage_grid.npz", "trajectory.csv", "scene.ply")


@pytest.fixture(scope="module")
def client():
    with dask_client(workers=2, dashboard=False) as c:
        # the workers import this very package (not another install of it)
        import scanner_sim

        assert set(c.run(lambda: __import__("scanner_sim").__file__).values()) == {scanner_sim.__file__}
        yield c


def untimed(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k not in TIMING_KEYS}


def assert_same_pass(folder: Path, reference: Path) -> None:
    assert sorted(p.name for p in folder.iterdir()) == sorted(p.name for p in reference.iterdir())
    for name in SAME_BYTES:
        if (reference / name).exists():
            assert (folder / name).read_bytes() == (reference / name).read_bytes(), (folder.name, name)
    assert untimed(json.loads((folder / "summary.json").read_text())) == \
        untimed(json.loads((reference / "summary.json").read_text()))


@pytest.fixture(scope="module")
def example_run(client, tmp_path_factory):
    """The shipped example campaign (2 waters x 2 altitudes, 6,000 pulses) through the CLI on the cluster."""
    out = tmp_path_factory.mktemp("campaign") / "example"
    code, printed = run_cli(["campaign", str(EXAMPLE), "--scheduler", client.scheduler.address, "--out", str(out),
                             "--quiet"])
    assert code == 0 and printed.strip() == str(out / "campaign.json")
    return out


def test_campaign_passes_are_byte_identical_to_serial_run_pass(example_run, tmp_path):
    campaign = load_campaign(EXAMPLE)
    assert len(campaign.jobs) == 4
    for job in campaign.jobs:
        run_pass(job.config, tmp_path / job.name, job.options)
        assert_same_pass(example_run / job.name, tmp_path / job.name)
    result = json.loads((example_run / "campaign.json").read_text())
    assert (result["ran"], result["skipped"], result["failed"]) == (4, 0, 0)
    assert [p["values"] for p in result["passes"]] == [
        {"water": w, "platform.altitude_m": a} for w in ("clean_ocean", "turbid_harbor") for a in (4, 8)]
    # the campaign's table: CSV, Parquet and JSON agree; the charts are drawn
    import pyarrow.parquet as pq

    lines = (example_run / "campaign.csv").read_text().splitlines()
    assert len(lines) == 5 and lines[0].startswith("water,platform.altitude_m,dir,status,")
    table = pq.read_table(example_run / "campaign.parquet").to_pylist()
    assert [r["coverage.covered_fraction"] for r in table] == \
        [p["summary"]["coverage"]["covered_fraction"] for p in result["passes"]]
    assert [r["points"] for r in table] == [p["summary"]["points"] for p in result["passes"]]
    assert result["charts"] == ["covered_fraction_vs_platform-altitude_m_by_water.png",
                                "points_per_pulse_vs_platform-altitude_m_by_water.png"]
    assert all((example_run / name).stat().st_size > 10_000 for name in result["charts"])
    turbid = {p["values"]["platform.altitude_m"]: p["summary"]["coverage"]["covered_fraction"]
              for p in result["passes"] if p["values"]["water"] == "turbid_harbor"}
    assert turbid[8] < turbid[4]


def test_one_pass_in_four_segments_is_byte_identical(client, tmp_path):
    config = load_scene("cable_survey")
    options = PassOptions(max_pulses=6000, chunk_pulses=1000, progress=False, render=False)
    run_pass(config, tmp_path / "serial", options)
    result = run_pass_segmented(config, tmp_path / "segments", options, segments=4, client=client)
    assert result.summary["pulses"] == 6000
    assert_same_pass(tmp_path / "segments", tmp_path / "serial")
    # without a client the same tasks run in this process; more segments than chunks leaves some empty
    run_pass_segmented(config, tmp_path / "here", options, segments=8)
    assert_same_pass(tmp_path / "here", tmp_path / "serial")


def test_chunk_size_does_not_change_the_bits(tmp_path):
    """What segments rely on: every random draw is keyed by the pulse slot, not by the chunk."""
    config = load_scene("cable_survey")
    for chunk in (20000, 700):
        run_pass(config, tmp_path / str(chunk), PassOptions(max_pulses=3000, chunk_pulses=chunk, progress=False,
                                                            render=False))
    for name in SAME_BYTES:
        assert (tmp_path / "700" / name).read_bytes() == (tmp_path / "20000" / name).read_bytes(), name


def test_a_worker_killed_mid_campaign_costs_only_its_task(client, example_run, tmp_path):
    out = tmp_path / "killed"
    campaign = load_campaign(EXAMPLE)
    errors = []

    def run():
        try:
            from scanner_sim.runs.campaign import run_campaign

            run_campaign(campaign, out, client, progress=False)
        except Exception as exc:  # reported below
            errors.append(exc)

    thread = threading.Thread(target=run)
    thread.start()
    deadline = time.monotonic() + 120
    while not list(out.glob("*/summary.json")) and time.monotonic() < deadline:
        time.sleep(0.05)
    busy = [worker for worker, keys in client.processing().items() if keys]
    assert busy, "every pass finished before a worker could be killed"
    victim = client.run(os.getpid, workers=busy[:1])[busy[0]]
    os.kill(victim, SIGKILL)  # a worker process dies in the middle of a pass
    thread.join(timeout=180)
    assert not thread.is_alive() and not errors, errors
    result = json.loads((out / "campaign.json").read_text())
    assert (result["ran"], result["failed"]) == (4, 0)
    for job in campaign.jobs:
        assert_same_pass(out / job.name, example_run / job.name)
    assert victim not in client.run(os.getpid).values()  # the nanny started a new worker process


def test_a_rerun_skips_complete_passes_and_redoes_the_rest(client, example_run, tmp_path):
    import shutil

    out = tmp_path / "again"
    shutil.copytree(example_run, out)
    campaign = load_campaign(EXAMPLE)
    first, second, third = (out / job.name for job in campaign.jobs[:3])
    (first / "summary.json").unlink()  # a pass cut short before its summary, the proof of completeness
    (second / "summary.json").write_text('{"scene": "cable_sur')  # a summary that does not parse
    # written by a pass of other inputs: the fourth pass's summary, its inputs fingerprint with it
    shutil.copyfile(out / campaign.jobs[3].name / "summary.json", third / "summary.json")
    kept = (out / campaign.jobs[3].name / "points.las").stat().st_mtime_ns
    from scanner_sim.runs.campaign import run_campaign

    result = run_campaign(campaign, out, client, progress=False)
    assert [p["status"] for p in result["passes"]] == ["ran", "ran", "ran", "skipped"]
    assert (out / campaign.jobs[3].name / "points.las").stat().st_mtime_ns == kept
    for job in campaign.jobs:
        assert_same_pass(out / job.name, example_run / job.name)


def test_coverage_on_the_cluster_equals_coverage_in_process(client, tmp_path):
    argv = ["coverage", "cable_survey", "--waters", "clean_ocean", "turbid_harbor", "--instruments", "mul2023",
            "--altitudes-m", "5", "--max-pulses", "3000", "--no-render", "--quiet"]
    assert run_cli(argv + ["--out", str(tmp_path / "dask"), "--scheduler", client.scheduler.address])[0] == 0
    assert run_cli(argv + ["--out", str(tmp_path / "here"), "--workers", "0"])[0] == 0
    dask, here = (json.loads((tmp_path / d / "coverage.json").read_text()) for d in ("dask", "here"))
    for record in dask["records"] + here["records"]:
        record.pop("wall_s")
    assert dask["records"] == here["records"] and len(dask["records"]) == 2
    for record in dask["records"]:
        assert_same_pass(tmp_path / "dask" / record["dir"], tmp_path / "here" / record["dir"])


def _campaign(**changes):
    data = {"scene": "cable_survey", "sweep": {"water": ["clean_ocean", "turbid_harbor"],
                                              "platform.altitude_m": [4, 8]},
            "options": {"max_pulses": 6000, "render": False}}
    for key, value in changes.items():
        *path, last = key.split("/")
        node = data
        for name in path:
            node = node[name]
        node[last] = value
    return data


def test_the_brief_form_expands_to_four_validated_passes():
    campaign = parse_campaign(_campaign())
    assert [j.config.platform.altitude_m for j in campaign.jobs] == [4.0, 8.0, 4.0, 8.0]
    assert [j.config.water.preset for j in campaign.jobs] == ["clean_ocean"] * 2 + ["turbid_harbor"] * 2
    assert {j.config.survey.max_pulses for j in campaign.jobs} == {6000}
    aliases = parse_campaign(_campaign(sweep={"instrument": ["single_channel"], "fidelity": ["fast"], "seed": [3]}))
    config = aliases.jobs[0].config
    assert (config.instrument.preset, config.survey.fidelity, config.survey.seed) == ("single_channel", "fast", 3)
    assert aliases.jobs[0].name == "instrument=single_channel__fidelity=fast__seed=3"


@pytest.mark.parametrize("changes, words", [
    ({"sweep/platform.altitude_m": [4, -8]}, ["platform.altitude_m = -8", "> 0"]),
    ({"sweep/platform.altitud_m": [4]}, ["altitud_m", "did you mean 'altitude_m'"]),
    ({"sweep/water": ["clean_ocean", "milk"]}, ["water", "milk"]),
    ({"sweep/seed": [1, 1]}, ["sweep.seed", "repeated"]),
    ({"sweep/seed": []}, ["sweep.seed", "non-empty list"]),
    ({"sweep": {"seed": [1], "survey.seed": [2]}}, ["survey.seed", "sweep it once"]),
    ({"options/max_pulses": 0}, ["options.max_pulses = 0", ">= 1"]),
    ({"options/segmnts": 2}, ["options.segmnts", "did you mean 'segments'"]),
    ({"options/render": "no"}, ["options.render", "true or false"]),
    ({"sweeps": {}}, ["sweeps", "did you mean 'sweep'"]),
    ({"scene": "cable_survy"}, ["cable_survy", "did you mean 'cable_survey'"]),
    ({"charts": [{"x": "altitude", "y": "covered_fraction"}]}, ["charts[0].x = 'altitude'", "sweep's axes"]),
    ({"charts": [{"x": "water", "y": "coverage"}]}, ["charts[0].y = 'coverage'", "covered_fraction"]),
])
def test_bad_campaigns_fail_at_once_in_one_line_naming_the_key(changes, words):
    with pytest.raises(ConfigError) as info:
        parse_campaign(_campaign(**changes))
    message = str(info.value)
    assert "\n" not in message and all(w in message for w in words), message


def test_campaign_command_errors_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(_campaign(**{"sweep/platform.altitude_m": [4, 0]})))
    dup = tmp_path / "dup.yaml"
    dup.write_text("scene: cable_survey\nsweep: {seed: [1]}\nsweep: {seed: [2]}\n")
    for path, words in ((bad, ["platform.altitude_m = 0"]), (dup, ["sweep", "duplicate key", "line 3"]),
                        (tmp_path / "none.yaml", ["not found"])):
        assert main(["campaign", str(path), "--out", str(tmp_path / "x"), "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and all(w in err for w in words), err
    assert not (tmp_path / "x").exists()


def test_the_docs_show_the_shipped_example_file():
    page = (Path(__file__).resolve().parents[3] / "docs" / "campaigns.md").read_text()
    block = page.split("```yaml\n", 1)[1].split("```", 1)[0]
    assert block == EXAMPLE.read_text()


def test_a_campaign_of_segmented_passes_in_this_process(tmp_path):
    from scanner_sim.runs.campaign import run_campaign

    campaign = parse_campaign({"scene": "cable_survey", "sweep": {"seed": [5]},
                               "options": {"max_pulses": 3000, "chunk_pulses": 1000, "segments": 2,
                                           "render": False}})
    (job,) = campaign.jobs
    assert (job.name, job.segments, job.config.survey.seed) == ("seed=5", 2, 5)
    result = run_campaign(campaign, tmp_path / "campaign", progress=False)
    assert result["ran"] == 1 and result["charts"] == ["covered_fraction_vs_seed.png"]
    run_pass(job.config, tmp_path / "serial", job.options)
    assert_same_pass(tmp_path / "campaign" / "seed=5", tmp_path / "serial")
