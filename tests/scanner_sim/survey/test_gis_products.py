"""GIS products of a pass over a scene with a ``crs``, read back by GDAL's own tools (``gdalinfo``, ``ogrinfo``)
and laspy as a GIS would: the coverage rasters carry the CRS and the survey's extent, the gaps are polygons with
their cause, the tracks lie in map coordinates, the LAS file's CRS record gives the CRS back."""

import json
import shutil
import subprocess

import numpy as np
import pytest
from conftest import UTM_CENTRE, utm_scene_data

from scanner_sim.config import parse_scene
from scanner_sim.io import read_coverage_grid_npz, read_las, read_trajectory_csv
from scanner_sim.metrics.coverage import GAP_CAUSES
from scanner_sim.survey.gis_products import gis_files
from scanner_sim.survey.pipeline import run_pass, simulate_pass
from scanner_sim.survey.setup import PassOptions, PassPlan

OPTIONS = PassOptions(max_pulses=3000, fidelity="fast", progress=False, render=False, write_scene=False)

needs_gdal = pytest.mark.skipif(shutil.which("gdalinfo") is None or shutil.which("ogrinfo") is None,
                                reason="GDAL's command-line tools (Debian's gdal-bin) are not installed")


def turbid_utm_scene(**keys):
    """The UTM scene in turbid harbour water, where some cells the beam reaches give no valid point (gaps)."""
    data = utm_scene_data(32631)
    data["water"] = "turbid_harbor"
    data.update(keys)
    return parse_scene(data)


@pytest.fixture(scope="module")
def utm_pass(tmp_path_factory):
    out = tmp_path_factory.mktemp("utm_pass")
    result = run_pass(turbid_utm_scene(), out, OPTIONS)
    return out, result.summary


def _gdalinfo(path) -> dict:
    return json.loads(subprocess.run(["gdalinfo", "-json", str(path)], check=True, capture_output=True,
                                     text=True).stdout)


def _epsg(wkt: str) -> int | None:
    from pyproj import CRS

    return CRS.from_wkt(wkt).to_epsg()


def test_the_pass_writes_the_gis_products_its_plan_lists(utm_pass):
    out, _ = utm_pass
    plan = PassPlan.of(turbid_utm_scene(), OPTIONS).files
    assert {"coverage.tif", "density.tif", "s44_orders.tif", "gaps.geojson", "trajectory.geojson",
            "lines.geojson"} <= set(plan)
    assert sorted(p.name for p in out.iterdir()) == sorted(plan)  # nothing more, nothing less, no temporary file


def test_a_scene_without_crs_plans_no_gis_product():
    config = parse_scene(utm_scene_data(None))
    assert not set(gis_files(True)) & set(PassPlan.of(config, OPTIONS).files)


@needs_gdal
def test_gdalinfo_shows_the_coverage_raster_crs_and_the_survey_extent(utm_pass):
    """The extent is that of the cells the pass reached, found here from coverage_grid.npz (row 0 south)."""
    out, _ = utm_pass
    grid = read_coverage_grid_npz(out / "coverage_grid.npz")
    rows, cols = np.nonzero(grid["state"] != -2)
    cell = float(grid["cell_m"])
    x0, y0 = grid["origin_m"]
    expected = (x0 + cols.min() * cell, y0 + rows.min() * cell, x0 + (cols.max() + 1) * cell,
                y0 + (rows.max() + 1) * cell)
    for name in ("coverage.tif", "density.tif", "s44_orders.tif"):
        info = _gdalinfo(out / name)
        assert info["driverShortName"] == "GTiff" and info["metadata"]["IMAGE_STRUCTURE"]["LAYOUT"] == "COG"
        assert _epsg(info["coordinateSystem"]["wkt"]) == 32631
        corners = info["cornerCoordinates"]
        assert (*corners["lowerLeft"], *corners["upperRight"]) == pytest.approx(expected, abs=1e-6)
        assert info["size"] == [int(cols.max() - cols.min() + 1), int(rows.max() - rows.min() + 1)]
    # in UTM zone 31N near 3 deg E, 51.45 deg N, where the scene was placed
    lon, lat = np.array(info["wgs84Extent"]["coordinates"][0]).mean(axis=0)
    assert lon == pytest.approx(3.0, abs=0.01) and lat == pytest.approx(51.45, abs=0.01)
    assert abs(np.mean(expected[::2]) - UTM_CENTRE[0]) < 12 and abs(np.mean(expected[1::2]) - UTM_CENTRE[1]) < 8


def test_the_rasters_add_up_to_the_summary_coverage_figures(utm_pass):
    """coverage.tif counts the covered area and each cause's gap area of the summary; density.tif integrates to
    the valid points in reach (both figures counted by the coverage tally, not from the files)."""
    import rasterio

    out, summary = utm_pass
    figures = summary["coverage"]
    with rasterio.open(out / "coverage.tif") as ds:
        state, cell_area = ds.read(1), abs(ds.transform.a * ds.transform.e)
        assert ds.nodata == -2
    assert np.count_nonzero(state == -1) * cell_area == pytest.approx(figures["covered_area_m2"])
    assert np.count_nonzero(state != -2) * cell_area == pytest.approx(figures["reached_area_m2"])
    for code, cause in enumerate(GAP_CAUSES):
        assert np.count_nonzero(state == code) * cell_area == pytest.approx(figures["gaps_m2"][cause])
    with rasterio.open(out / "density.tif") as ds:
        density = ds.read(1)
        # every reached cell's centre, looked up by its map coordinates, has its coverage_grid.npz state and count
        grid = read_coverage_grid_npz(out / "coverage_grid.npz")
        rows, cols = np.nonzero(grid["state"] != -2)
        cell = float(grid["cell_m"])
        x, y = grid["origin_m"][0] + (cols + 0.5) * cell, grid["origin_m"][1] + (rows + 0.5) * cell
        tif_rows, tif_cols = rasterio.transform.rowcol(ds.transform, x, y)
    assert np.array_equal(state[tif_rows, tif_cols], grid["state"][rows, cols])
    assert np.allclose(density[tif_rows, tif_cols], grid["valid"][rows, cols] / cell ** 2)
    assert np.nansum(density.astype(float)) * cell_area == pytest.approx(figures["valid_points_in_reach"], rel=1e-6)
    assert np.array_equal(np.isnan(density), state == -2)


def test_the_s44_raster_holds_each_cells_strictest_order_and_adds_up_to_the_summary(utm_pass):
    """s44_orders.tif, looked up by map coordinates, is coverage_grid.npz's strictest order of each reached cell;
    the orders are nested (each looser limit contains the stricter one), so the cells of the planned swath coded
    0..k are the summary's compliant area of order k, which the coverage tally counts per order on its own."""
    import rasterio

    out, summary = utm_pass
    grid = read_coverage_grid_npz(out / "coverage_grid.npz")
    rows, cols = np.nonzero(grid["state"] != -2)
    cell = float(grid["cell_m"])
    with rasterio.open(out / "s44_orders.tif") as ds:
        orders = ds.read(1)
        assert ds.nodata == -2 and ds.tags(1)["codes"].startswith("-1=none, 0=exclusive")
        x, y = grid["origin_m"][0] + (cols + 0.5) * cell, grid["origin_m"][1] + (rows + 0.5) * cell
        tif_rows, tif_cols = rasterio.transform.rowcol(ds.transform, x, y)
    code = orders[tif_rows, tif_cols]
    assert np.array_equal(code, grid["s44_order"][rows, cols])
    assert np.count_nonzero(orders != -2) == rows.size
    figures = summary["coverage"]
    assert figures["orders_area"] == "planned_swath"
    in_swath = grid["planned"][rows, cols]
    for k, name in enumerate(grid["s44_order_names"]):
        compliant = np.count_nonzero((code >= 0) & (code <= k) & in_swath) * cell ** 2
        assert compliant == pytest.approx(figures["orders"][str(name)]["compliant_area_m2"])
    assert (code >= 0).any(), "the test pass should comply with some order somewhere"


@needs_gdal
def test_ogrinfo_lists_the_gap_polygons_with_a_cause_field(utm_pass):
    out, summary = utm_pass
    holes = summary["coverage"]["holes"]
    assert holes["count"] >= 2  # the turbid water leaves gaps to map
    text = subprocess.run(["ogrinfo", "-al", "-so", str(out / "gaps.geojson")], check=True, capture_output=True,
                          text=True).stdout
    assert f"Feature Count: {holes['count']}" in text and "Geometry: Polygon" in text
    assert "cause: String" in text and "area_m2: Real" in text
    assert 'ID["EPSG",32631]' in text
    full = subprocess.run(["ogrinfo", "-al", str(out / "gaps.geojson")], check=True, capture_output=True,
                          text=True).stdout
    causes = {line.split("=", 1)[1].strip() for line in full.splitlines() if line.strip().startswith("cause (String)")}
    assert causes and causes <= set(GAP_CAUSES)


def test_each_gap_polygon_is_its_cells_with_their_cause(utm_pass):
    """A polygon's own area (shapely) is its cells' area; the areas add up to the summary's holes; a one-cell gap
    takes its cell's cause from coverage_grid.npz (the cause that failed most of the cell's pulses)."""
    from shapely.geometry import shape

    out, summary = utm_pass
    features = json.loads((out / "gaps.geojson").read_text())["features"]
    grid = read_coverage_grid_npz(out / "coverage_grid.npz")
    cell = float(grid["cell_m"])
    assert sum(f["properties"]["area_m2"] for f in features) == pytest.approx(summary["coverage"]["holes"]["total_m2"])
    single = 0
    for feature in features:
        polygon, props = shape(feature["geometry"]), feature["properties"]
        assert polygon.is_valid and polygon.area == pytest.approx(props["cells"] * cell ** 2)
        assert props["area_m2"] == pytest.approx(polygon.area) and props["cause"] in GAP_CAUSES
        if props["cells"] == 1:
            col, row = np.floor((np.array(polygon.centroid.coords[0]) - grid["origin_m"]) / cell).astype(int)
            assert GAP_CAUSES[grid["state"][row, col]] == props["cause"]
            single += 1
    assert single >= 1


def test_the_las_file_carries_the_crs_and_map_coordinates_to_the_millimetre(utm_pass):
    """laspy's parse_crs gives EPSG:32631 back; the header's offsets lie by the data and its scale is 1 mm; the
    points read back are the pass's own (simulated again in memory, the same seed) to half a millimetre."""
    import laspy

    out, _ = utm_pass
    with laspy.open(out / "points.las") as las:
        header = las.header
    assert header.parse_crs().to_epsg() == 32631
    assert np.allclose(header.scales, 0.001)
    cloud = read_las(out / "points.las")
    xyz = cloud.xyz
    assert np.all(np.abs(xyz.mean(axis=0)[:2] - header.offsets[:2]) < 50)
    assert np.all(np.abs(xyz[:, :2].mean(axis=0) - UTM_CENTRE) < 12)  # in map coordinates, not a local frame
    memory = simulate_pass(turbid_utm_scene(), OPTIONS).points
    assert len(memory) == len(cloud)
    assert np.abs(xyz - memory.xyz).max() <= 0.0005 + 1e-9


def test_the_planned_lines_are_the_lawnmower_in_map_coordinates(utm_pass):
    """3 lines 4 m apart over 12 m x 8 m, heading east (by hand): the first along y = N + 4, stepping south."""
    out, _ = utm_pass
    collection = json.loads((out / "lines.geojson").read_text())
    assert collection["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::32631"
    e, n = UTM_CENTRE
    ends = [(e - 6, n + 4), (e + 6, n + 4), (e + 6, n), (e - 6, n), (e - 6, n - 4), (e + 6, n - 4)]
    features = collection["features"]
    assert [f["properties"]["leg"] for f in features] == [1, 2, 3, 4, 5]
    for k, feature in enumerate(features):
        assert feature["geometry"]["type"] == "LineString"
        assert np.allclose(feature["geometry"]["coordinates"], [ends[k], ends[k + 1]], rtol=0, atol=1e-6)
    assert [f["properties"]["heading_deg"] for f in features] == pytest.approx([90, 180, 270, 180, 90])


def test_the_trajectory_geojson_is_the_trajectory_csv_by_leg(utm_pass):
    out, _ = utm_pass
    table = read_trajectory_csv(out / "trajectory.csv")
    features = json.loads((out / "trajectory.geojson").read_text())["features"]
    coords = np.concatenate([np.array(f["geometry"]["coordinates"]) for f in features])
    position = np.c_[table["x_m"], table["y_m"], table["z_m"]]
    assert coords.shape == position.shape and np.abs(coords - position).max() <= 0.0005 + 1e-9
    legs = [f["properties"] for f in features]
    assert [leg["leg"] for leg in legs] == list(range(1, len(legs) + 1))
    assert legs[0]["start_s"] == table["time_s"][0] and legs[-1]["stop_s"] == pytest.approx(table["time_s"][-1])


def test_split_legs_clouds_carry_the_crs(tmp_path):
    import laspy

    config = turbid_utm_scene(output={"las": True, "laz": False, "split_legs": True})
    run_pass(config, tmp_path, PassOptions(max_pulses=300, fidelity="fast", progress=False, render=False,
                                           write_scene=False))
    clouds = sorted(tmp_path.glob("leg*_points.las"))
    assert clouds
    for path in clouds:
        with laspy.open(path) as las:
            assert las.header.parse_crs().to_epsg() == 32631


class _Tally:
    """The parts of a coverage tally the gap polygons read: a plan grid, its cell tally and min_points 1."""

    def __init__(self, grid, cells):
        from scanner_sim.metrics.coverage import CoverageSettings

        self.grid, self.cells, self.settings = grid, cells, CoverageSettings()

    def cell_states(self):
        return self.cells.states(1).reshape(self.grid.shape)


def test_a_gap_takes_the_cause_of_most_of_its_pulses_and_its_cells_edges():
    """By hand on a 3 x 4 grid of 2 m cells at (100, 200): row 0's cells 0, 1, 2 form one gap, cell 0 failed by 9
    no_hit pulses, cells 1 and 2 by 4 below_threshold pulses each. Most cells say below_threshold, most pulses
    no_hit (9 of 17): the gap's cause is no_hit. Cell (row 1, col 3) touches it only by a corner, so it is a
    second gap (4-connected), below_threshold."""
    from shapely.geometry import box, shape

    from scanner_sim.metrics.coverage import BinTally, PlanGrid
    from scanner_sim.survey.gis_products import gap_features

    grid = PlanGrid((100.0, 200.0), 2.0, (3, 4))
    no_hit, below = GAP_CAUSES.index("no_hit"), GAP_CAUSES.index("below_threshold")
    failing = {0: (9, no_hit), 1: (4, below), 2: (4, below), 7: (4, below)}  # flat cell = row * 4 + col
    reaching = np.concatenate([np.full(failing.get(c, (1,))[0], c) for c in range(12)])
    outcome = np.array([failing[c][1] if c in failing else -1 for c in reaching])
    cells = BinTally(grid.size)
    cells.add(reaching, outcome, reaching[outcome == -1])
    features = gap_features(_Tally(grid, cells))
    assert len(features) == 2
    first, second = (f["properties"] for f in features)
    assert first["cause"] == "no_hit" and first["cause_share"] == pytest.approx(9 / 17) and first["cells"] == 3
    assert first["failed_pulses"] == first["reaching_pulses"] == 17 and first["area_m2"] == 12.0
    assert shape(features[0]["geometry"]).equals(box(100, 200, 106, 202))  # row 0 is the southern row
    assert second["cause"] == "below_threshold" and shape(features[1]["geometry"]).equals(box(106, 202, 108, 204))


def test_cached_scene_of_another_crs_is_not_reused():
    """A campaign's process kept one built scene keyed by the seabed and objects only, so a pass of the same seabed
    under another CRS reused a scene whose ``crs`` was the first pass's, and wrote its products in that CRS."""
    from scanner_sim.survey.setup_cache import cached_scene

    first = cached_scene(parse_scene(utm_scene_data(32631)))
    second = cached_scene(parse_scene(utm_scene_data(25831)))  # ETRS89 / UTM zone 31N
    assert first.crs.to_epsg() == 32631 and second.crs.to_epsg() == 25831


def test_a_compound_crs_reaches_the_las_file_with_its_vertical_datum(tmp_path):
    import laspy

    config = turbid_utm_scene(crs="EPSG:32631+3855")  # UTM zone 31N + EGM2008 height
    run_pass(config, tmp_path, PassOptions(max_pulses=300, fidelity="fast", progress=False, render=False,
                                           write_scene=False))
    with laspy.open(tmp_path / "points.las") as las:
        crs = las.header.parse_crs()
    assert crs.is_compound and [part.to_epsg() for part in crs.sub_crs_list] == [32631, 3855]
    member = json.loads((tmp_path / "gaps.geojson").read_text())["crs"]["properties"]["name"]
    assert member.startswith("COMPD_CS[")


def test_a_static_platform_is_one_station_point():
    from scanner_sim.survey.gis_products import line_features, track_features

    (station,) = line_features(np.array([[500_010.0, 5_700_020.0]]))
    assert station["geometry"] == {"type": "Point", "coordinates": [500_010.0, 5_700_020.0]}
    table = {"time_s": np.arange(4) * 0.1, "leg": np.ones(4, np.uint16),
             "position_m": np.tile([500_010.0, 5_700_020.0, -12.5], (4, 1))}
    (track,) = track_features(table)
    assert track["geometry"] == {"type": "Point", "coordinates": [500_010.0, 5_700_020.0, -12.5]}
    assert track["properties"] == {"leg": 1, "start_s": 0.0, "stop_s": pytest.approx(0.3), "length_m": 0.0}


def test_a_campaign_runs_again_a_pass_that_lacks_a_gis_product(tmp_path):
    """The products are in the pass's plan, which a campaign's completeness check reads: a pass folder without its
    gaps.geojson is run again, one with every product is skipped."""
    import yaml

    from scanner_sim.runs.campaign import load_campaign, run_campaign

    (tmp_path / "utm.yaml").write_text(yaml.safe_dump(utm_scene_data(32631)))
    (tmp_path / "campaign.yaml").write_text(yaml.safe_dump(
        {"scene": "utm.yaml", "sweep": {"seed": [1]}, "options": {"max_pulses": 300, "render": False}}))
    out = tmp_path / "out"

    def statuses():
        result = run_campaign(load_campaign(tmp_path / "campaign.yaml"), out, progress=False)
        return [p["status"] for p in result["passes"]]

    assert statuses() == ["ran"]
    (folder,) = [p for p in out.iterdir() if p.is_dir()]
    assert (folder / "gaps.geojson").is_file() and (folder / "coverage.tif").is_file()
    assert statuses() == ["skipped"]
    (folder / "gaps.geojson").unlink()
    assert statuses() == ["ran"] and (folder / "gaps.geojson").is_file()
