"""Survey inputs that stopped with an internal error (exit 1, "please report it") or named a key the user never
wrote: a fixed-depth platform over a raster seabed, a dataset over a raster base, GeoJSON line plans that are not
FeatureCollections of lines, a CSV line plan with a value that is not a number. Each is either a survey that
runs, or one line naming the file or key and what is allowed, exit 2, nothing written."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rasterio
from conftest import ROOT
from rasterio.transform import from_origin

from scanner_sim.config import load_scene
from scanner_sim.metrics.planned_swath import planned_swath
from scanner_sim.motion.trajectory import trajectory_of
from scanner_sim.world.scene import build_scene

X0, Y0 = 500_000.0, 5_600_000.0  # UTM zone 31N
TRACK = f"[[{X0 + 10}, {Y0 + 20}], [{X0 + 50}, {Y0 + 20}]]"


def flat_raster(path: Path, z_m: float = -12.0, shape=(40, 60)):
    """A 1 m GeoTIFF in UTM 31N, flat at ``z_m`` (elevation, up), its south-west corner at (X0, Y0)."""
    ny, nx = shape
    with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=1, dtype="float32", crs="EPSG:32631",
                       transform=from_origin(X0, Y0 + ny, 1.0, 1.0)) as ds:
        ds.write(np.full(shape, z_m, "float32"), 1)


def cli(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "scanner_sim.cli", *args], capture_output=True, text=True, cwd=tmp_path,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})


def one_line(run: subprocess.CompletedProcess, command: str) -> str:
    assert run.returncode == 2, run.stderr
    lines = [line for line in run.stderr.strip().splitlines() if not line.startswith("first run:")]
    assert len(lines) == 1 and lines[0].startswith(f"scanner-sim {command}: error: "), lines
    return lines[0]


def test_fixed_depth_platform_over_a_raster_seabed_runs(tmp_path):
    """Root cause: the planned swath took the vehicle's height above the seabed as ``seabed.depth_m - depth_m``, and
    a raster seabed has no depth_m: AttributeError at the start of every pass at fixed depth over a raster (a
    survey as legitimate as one at altitude). Its height is now read off the raster under the track: over a flat
    raster 12 m deep, a vehicle 8 m deep flies 4 m above it and a 30 degree sector's swath is 4 tan 15 deg wide on
    either side; the whole pass runs (exit 0) and writes its coverage."""
    flat_raster(tmp_path / "site.tif")
    (tmp_path / "fixed.yaml").write_text(
        f"format_version: 1\nname: fixed\ncrs: EPSG:32631\nseabed: {{raster: site.tif}}\n"
        f"platform: {{mode: waypoints, depth_m: 8, speed_m_s: 1, waypoints_m: {TRACK}}}\n"
        "scanner: {mode: oscillating, sector_deg: 30}\n")
    cfg = load_scene(tmp_path / "fixed.yaml")
    swath = planned_swath(cfg, trajectory_of(cfg, build_scene(cfg)), 1000.0)
    assert swath.half_width_m == pytest.approx(4.0 * math.tan(math.radians(15.0)), rel=1e-6)
    run = cli(tmp_path, "run", "fixed.yaml", "--max-pulses", "300", "--out", "out", "--no-render", "--quiet")
    assert run.returncode == 0, run.stderr
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["coverage"]["reached_area_m2"] > 0


def _raster_dataset(tmp_path: Path, area: str) -> subprocess.CompletedProcess:
    flat_raster(tmp_path / "site.tif")
    (tmp_path / "base.yaml").write_text(
        f"format_version: 1\nname: base\ncrs: EPSG:32631\nseabed: {{raster: site.tif}}\n"
        f"platform: {{mode: waypoints, altitude_m: 4, waypoints_m: {TRACK}}}\n")
    (tmp_path / "spec.yaml").write_text(
        f"format_version: 1\nname: ds\nscene: base.yaml\nseed: 1\nscenes: 1\nmax_pulses: 100\n{area}"
        "objects:\n  - type: cylinder_mine\n    count: 2\n")
    return cli(tmp_path, "dataset", "spec.yaml", "--out", "ds")


def test_dataset_over_a_raster_base_without_object_area_is_one_line(tmp_path):
    """Root cause: objects were placed around ``seabed.center_m`` in ``seabed.size_m``, which a raster seabed has
    not (AttributeError center_m). A raster's extent is no area to fill with objects: without object_area_m the
    spec is refused in one line naming the key, and nothing is written."""
    line = one_line(_raster_dataset(tmp_path, ""), "dataset")
    assert "object_area_m: missing" in line and "raster seabed" in line
    assert not (tmp_path / "ds").exists()


def test_dataset_over_a_raster_base_with_mines_places_them_around_the_plan(tmp_path):
    """With object_area_m, the mines are placed in that rectangle centred on the survey's plan (the track's middle,
    (X0 + 30, Y0 + 20)), and the dataset runs (past the seabed seed and rock count a raster has not)."""
    run = _raster_dataset(tmp_path, "object_area_m: [20, 4]\n")
    assert run.returncode == 0, run.stderr
    scene = json.loads((tmp_path / "ds" / "manifest.json").read_text())["scenes"][0]
    xy = np.array([o["position_m"][:2] for o in scene["drawn"]["objects"]])
    assert len(xy) == 2 and scene["seabed_seed"] is None
    assert np.all(np.abs(xy - [X0 + 30, Y0 + 20]) <= [10, 2])


@pytest.mark.parametrize("case, document, message", [
    ("null_geometry", {"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": None}]},
     "a null geometry (feature 0)"),
    ("top_level_list", [{"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[3, 50], [3.1, 50]]}}],
     "the file holds a JSON list"),
    ("features_not_a_list", {"type": "FeatureCollection", "features": {"a": 1}}, "features are"),
    ("coordinates_null", {"type": "LineString", "coordinates": None}, "feature 0's coordinates are None"),
])
def test_geojson_line_plan_that_is_no_feature_collection_of_lines_is_one_line(tmp_path, case, document, message):
    """Root cause: the reader called ``.get`` on whatever the JSON held (a null geometry, a top-level list):
    AttributeError, exit 1. Now each names platform.line_plan and the file, says what a plan holds, exit 2,
    and the run writes nothing."""
    (tmp_path / "plan.geojson").write_text(json.dumps(document))
    (tmp_path / "s.yaml").write_text("format_version: 1\nname: lp\ncrs: EPSG:32631\n"
                                     "platform: {mode: waypoints, depth_m: 5, line_plan: plan.geojson}\n")
    line = one_line(cli(tmp_path, "run", "s.yaml", "--out", "out"), "run")
    assert "platform.line_plan = 'plan.geojson': " in line and message in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", ["nan", "inf", "", "12,5"])
def test_nan_in_a_csv_line_plan_names_the_file_line_and_column(tmp_path, value):
    """Root cause: the CSV reader took float('nan') as a number, so the NaN surfaced as
    ``platform.waypoints_m[1][0] = nan``, a key the user never wrote. Now the file, its line (the header is line 1)
    and the column are named."""
    (tmp_path / "plan.csv").write_text(f'line,x,y\n1,0,0\n1,"{value}",0\n1,5,0\n')
    (tmp_path / "s.yaml").write_text("format_version: 1\nname: lp\n"
                                     "platform: {mode: waypoints, depth_m: 5, line_plan: plan.csv}\n")
    line = one_line(cli(tmp_path, "validate", "s.yaml"), "validate")
    assert f"platform.line_plan = 'plan.csv': line 3, column 'x' = '{value}': must be a finite number" in line
    assert "waypoints_m" not in line
