"""``scanner-sim plan`` (docs/planning.md): its files, the same bytes on 1 and 2 Dask workers, a re-run that skips the
complete passes, the written scene that `scanner-sim run` turns into the confirmation again, the page in Chromium,
and bad input refused in one line with nothing written. On the small procedural site of tests/test_planning.py,
given a CRS so that lines.geojson is written."""

import contextlib
import io as stdio
import json

import numpy as np
import pytest
import yaml
from conftest import page_pixels

from scanner_sim.cli import main
from scanner_sim.runs.jobs import TIMING_KEYS
from tests.scanner_sim.studies.test_planning import SMALL_SITE

ARGS = ["--order", "special", "--waters", "clean_ocean", "turbid_harbor", "--altitudes-m", "3", "5",
        "--speeds-m-s", "2", "--sample-lines", "2", "--sample-length-m", "10"]
#: Files of a pass whose bytes must not depend on where it ran (summary.json is compared without its timings).
SAME_BYTES = ("coverage_grid.npz", "dropouts.npz", "trajectory.csv", "points.las")


def run_cli(argv) -> tuple[int, str]:
    printed = stdio.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(argv)
    return code, printed.getvalue()


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    path = tmp_path_factory.mktemp("site") / "small_site.yaml"
    path.write_text(yaml.safe_dump({**SMALL_SITE, "crs": "EPSG:32631"}))
    return path


@pytest.fixture(scope="module")
def planned(site, tmp_path_factory):
    """The plan run on a local cluster of 2 workers and again in this process (0 workers: no Dask)."""
    outs = {}
    for workers in ("2", "0"):
        out = tmp_path_factory.mktemp(f"plan{workers}")
        code, printed = run_cli(["plan", str(site), *ARGS, "--workers", workers, "--out", str(out), "--json"])
        assert code == 0
        outs[workers] = (out, json.loads(printed))
    return outs


def untimed(path) -> dict:
    return {k: v for k, v in json.loads(path.read_text()).items() if k not in TIMING_KEYS}


@pytest.mark.slow
def test_sample_and_confirmation_passes_are_the_same_bytes_on_two_workers_and_in_process(planned):
    (out2, plan2), (out0, plan0) = planned["2"], planned["0"]
    passes = sorted(p.name for p in out2.iterdir() if p.is_dir())
    assert passes == sorted(p.name for p in out0.iterdir() if p.is_dir())
    assert any(n.startswith("confirm-") for n in passes) and sum(n.startswith("sample-") for n in passes) == 8
    for name in passes:
        for f in SAME_BYTES:
            if (out0 / name / f).exists():
                assert (out2 / name / f).read_bytes() == (out0 / name / f).read_bytes(), (name, f)
        assert untimed(out2 / name / "summary.json") == untimed(out0 / name / "summary.json")
    assert plan2 == plan0
    assert (out2 / "plan.json").read_bytes() == (out0 / "plan.json").read_bytes()


@pytest.mark.slow
def test_plan_files_and_a_rerun_that_skips_every_complete_pass(planned, site):
    out, plan = planned["0"]
    for name in ("plan.json", "plan.md", "plan_chart.png", "plan.html", "lines.geojson", "scene-clean_ocean.yaml"):
        assert (out / name).is_file(), name
    clean, turbid = plan["waters"]
    assert clean["achievable"] and clean["confirmation"]["compliant_share"] >= 0.95
    assert not turbid["achievable"] and turbid["limiting_cause"] and turbid["best_order"] in ("1a", "1b", "2")
    lines = json.loads((out / "lines.geojson").read_text())
    assert lines["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::32631"
    assert len(lines["features"]) == clean["chosen"]["lines"]
    ys = sorted({f["geometry"]["coordinates"][0][1] for f in lines["features"]})
    assert np.diff(ys) == pytest.approx(clean["chosen"]["spacing_m"])
    before = {p: p.stat().st_mtime_ns for p in out.glob("*/summary.json")}
    code, _ = run_cli(["plan", str(site), *ARGS, "--workers", "0", "--out", str(out), "--quiet"])
    assert code == 0
    assert {p: p.stat().st_mtime_ns for p in out.glob("*/summary.json")} == before  # nothing ran again


@pytest.mark.slow
def test_running_the_written_scene_reproduces_the_confirmation(planned, tmp_path):
    """`scanner-sim run` of scene-WATER.yaml flies the chosen plan's confirmation pass: the same coverage grid."""
    out, plan = planned["0"]
    code, _ = run_cli(["run", str(out / "scene-clean_ocean.yaml"), "--out", str(tmp_path), "--quiet"])
    assert code == 0
    confirmed = out / plan["waters"][0]["confirmation"]["pass"]
    assert (tmp_path / "coverage_grid.npz").read_bytes() == (confirmed / "coverage_grid.npz").read_bytes()


@pytest.mark.slow
def test_plan_page_opens_in_headless_chromium_with_its_chart(planned, tmp_path):
    """Chromium renders plan.html; the screenshot shows the chart's chosen-plan red star (#d7301f)."""
    out, _ = planned["0"]
    rgb = page_pixels(out / "plan.html", tmp_path / "plan.png", height=2000)
    assert (np.abs(rgb.astype(int) - (0xD7, 0x30, 0x1F)).sum(axis=1) < 6).sum() > 20
    assert "turbid_harbor" in (out / "plan.html").read_text()


@pytest.mark.parametrize("argv, words", [
    (["--order", "specail"], "order = 'specail': no such IHO S-44 order; must be one of exclusive, special"),
    (["--order", "special", "--waters", "turbid_harbor", "--altitudes-m", "3", "10"],
     "altitudes_m: 10 m in water turbid_harbor: no pulse reaches the seabed"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(site, tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    code = main(["plan", str(site), *argv, "--workers", "0", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_site_without_a_seabed_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["plan", "pool_panel", "--order", "special", "--out", str(out)]) == 2
    assert "no seabed section" in capsys.readouterr().err and not out.exists()
