"""A seabed from a bathymetry raster: GeoTIFF, BAG, NetCDF and ASCII grids through rasterio, their CRS, nodata,
vertical sign and window, the bilinear refinement, micro-relief and class rasters, and the bad rasters refused in
one line naming the key."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.transform import Affine, from_origin
from scipy.interpolate import RegularGridInterpolator

import scanner_sim
from scanner_sim.config import ConfigError, parse_scene
from scanner_sim.config.raster_seabed import RasterGrid
from scanner_sim.world.scene import build_scene

ROOT = Path(__file__).resolve().parents[3]
X0, Y0, CELL = 500_000.0, 5_600_000.0, 1.0  # UTM zone 31N: a real place in the North Sea


def bathymetry(ny=40, nx=60):
    """(ny, nx) seabed elevations [m], row 0 the northern row: 12 m deep with 0.8 m and 0.5 m undulations."""
    yy, xx = np.mgrid[0:ny, 0:nx]
    return -12.0 + 0.8 * np.sin(xx / 6.0) + 0.5 * np.cos(yy / 5.0)


def write_raster(path, values, driver="GTiff", crs="EPSG:32631", nodata=None, transform=None, **tags):
    ny, nx = values.shape
    transform = transform or from_origin(X0, Y0 + ny * CELL, CELL, CELL)
    with rasterio.open(path, "w", driver=driver, width=nx, height=ny, count=1, dtype="float32", crs=crs,
                       transform=transform, nodata=nodata) as ds:
        ds.write(values.astype("float32"), 1)
        if tags:
            ds.update_tags(1, **tags)
    return path


def scene(tmp_path, seabed, platform=None, **more):
    data = {"format_version": 1, "name": "raster_site", "water": "clean_ocean", "seabed": seabed,
            "platform": platform or {"mode": "waypoints", "altitude_m": 4.0,
                                     "waypoints_m": [[X0 + 10, Y0 + 20], [X0 + 50, Y0 + 20]]}, **more}
    return parse_scene(data, base_dir=tmp_path)


def pixel_surface(values, transform):
    """raster(x, y): bilinear between pixel centres, by scipy (a second method, not the loader's)."""
    ny, nx = values.shape
    x = transform.c + (np.arange(nx) + 0.5) * transform.a
    y = transform.f + (np.arange(ny) + 0.5) * transform.e
    return RegularGridInterpolator((y[::-1], x), values[::-1], bounds_error=False)


def test_utm_geotiff_becomes_a_scene_and_the_points_lie_on_it(tmp_path):
    """Acceptance: a GeoTIFF in UTM 31N by a few YAML keys; the pass's points, in the raster's CRS, lie on the
    raster's surface: median |z - raster(x, y)| far below the surface's relief (its standard deviation)."""
    values = bathymetry()
    write_raster(tmp_path / "site.tif", values)
    cfg = scene(tmp_path, {"raster": "site.tif"})
    result = scanner_sim.simulate_pass(cfg, scanner_sim.PassOptions(max_pulses=4000, progress=False))
    xyz = result.points.xyz
    assert len(xyz) > 1000
    assert (np.abs(xyz[:, 0] - X0 - 30) < 30).all() and (np.abs(xyz[:, 1] - Y0 - 20) < 20).all()
    raster_z = pixel_surface(values, from_origin(X0, Y0 + 40, CELL, CELL))(np.c_[xyz[:, 1], xyz[:, 0]])
    relief = values.std()
    error = np.nanmedian(np.abs(xyz[:, 2] - raster_z))
    assert relief > 0.4 and error < 0.05 * relief, (error, relief)
    assert result.summary["seabed"]["crs"] == "EPSG:32631"
    assert result.summary["seabed"]["synthetic_relief_rms_m"] == 0.0
    assert "coverage" in result.summary


def test_raster_crs_must_be_the_scene_crs(tmp_path):
    """With crs: 32631 the UTM 31N raster is the world frame; with crs: 32632 (the next zone, 6 degrees east) its
    coordinates would land hundreds of km away: refused in one line naming seabed.raster and both CRSs."""
    write_raster(tmp_path / "site.tif", bathymetry())
    assert build_scene(scene(tmp_path, {"raster": "site.tif"}, crs=32631)).crs.to_epsg() == 32631
    with pytest.raises(ConfigError, match=r"^seabed\.raster = 'site\.tif': its CRS \(WGS 84 / UTM zone 31N\) is not "
                       r"the scene's crs \(WGS 84 / UTM zone 32N\)"):
        build_scene(scene(tmp_path, {"raster": "site.tif"}, crs=32632))


def test_refined_heights_are_bilinear_between_pixel_centres(tmp_path):
    """The refined height field at its nodes equals scipy's bilinear interpolation of the pixel centres, and a node
    on a pixel centre takes the pixel's value; k = ceil(cell / resolution_m) = 3 nodes per cell."""
    values = bathymetry()
    write_raster(tmp_path / "site.tif", values)
    hf = build_scene(scene(tmp_path, {"raster": "site.tif", "resolution_m": 0.4})).heightfield
    assert hf.spacing_m == pytest.approx(1.0 / 3)
    ny, nx = hf.shape
    gx, gy = np.meshgrid(hf.x0_m + hf.spacing_m * np.arange(nx), hf.y0_m + hf.spacing_m * np.arange(ny))
    expected = pixel_surface(values, from_origin(X0, Y0 + 40, CELL, CELL))(np.c_[gy.ravel(), gx.ravel()])
    assert np.allclose(hf.heights_m.ravel(), expected, atol=1e-5)
    assert hf.x0_m == X0 + 0.5 and hf.height(X0 + 3.5, Y0 + 40 - 2.5) == pytest.approx(values[2, 3], abs=1e-5)


def test_only_a_window_around_the_track_is_read(tmp_path):
    """A track near the raster's west edge reads the columns within margin_m (plus one) of it, not the rest."""
    values = bathymetry(ny=40, nx=400)
    write_raster(tmp_path / "long.tif", values)
    cfg = scene(tmp_path, {"raster": "long.tif", "margin_m": 5.0})
    info = build_scene(cfg).seabed_info
    # waypoints x from X0 + 10 to X0 + 50: columns 5 to 55, one more each side for the bilinear stencil
    assert info["window"]["col_off"] == 4 and info["window"]["width"] == 52
    assert info["window"]["row_off"] == 14 and info["window"]["height"] == 12  # y 15 to 25 m: rows 15 to 25


def test_bag_with_depth_down_values_and_nodata_loads_with_the_right_sign_and_gaps(tmp_path):
    """Acceptance: a BAG written by rasterio's BAG driver holding depths (positive down) and nodata cells: with
    vertical: depth_down the seabed lies at -depth; the nodata pixels are gaps a vertical ray passes through; the
    vertical datum is read from the file's compound CRS. Left to auto, BAG reads as elevation (the format's rule)
    and the positive values are refused naming the key."""
    depth = -bathymetry()
    depth[10:14, 20:26] = 1e6  # BAG's nodata value
    write_raster(tmp_path / "survey.bag", depth, driver="BAG", nodata=1e6)
    cfg = scene(tmp_path, {"raster": "survey.bag", "vertical": "depth_down"})
    built = build_scene(cfg)
    hf = built.heightfield
    assert built.seabed_info["vertical"] == "depth_down" and built.seabed_info["driver"] == "BAG"
    x, y = X0 + 10.5, Y0 + 40 - 5.5  # the centre of pixel (row 5, col 10)
    assert hf.height(x, y) == pytest.approx(-depth[5, 10], abs=1e-4)
    gap_x, gap_y = X0 + 23.0, Y0 + 40 - 12.0  # inside the nodata block
    assert not hf.covers(gap_x, gap_y) and hf.covers(x, y)
    from scanner_sim.rays.caster import ray_caster

    caster = ray_caster((built.vertices - built.local_origin).astype(np.float32), built.faces)
    origins = np.array([[gap_x, gap_y, -2.0], [x, y, -2.0]]) - built.local_origin
    rays, _, dist = caster.first_hits(origins.astype(np.float32), np.tile([0.0, 0.0, -1.0], (2, 1)).astype(np.float32))
    assert list(rays) == [1] and dist[0] == pytest.approx(-2.0 + depth[5, 10], abs=1e-3)
    with pytest.raises(ConfigError, match=r"^seabed\.vertical = 'auto': .*all above 0.*depth_down"):
        build_scene(scene(tmp_path, {"raster": "survey.bag"}))


def test_nodata_cells_are_not_counted_as_seabed_in_the_coverage(tmp_path):
    """Nodata cells have no triangles: the plan cells over them are neither covered nor gaps, and the coverage
    reports their area as no seabed data (the 4 x 6 m block: 24 m2, within a cell of the grid's rounding)."""
    values = bathymetry()
    values[18:22, 27:33] = -9999.0
    write_raster(tmp_path / "holes.tif", values, nodata=-9999.0)
    cfg = scene(tmp_path, {"raster": "holes.tif"}, platform={
        "mode": "waypoints", "altitude_m": 4.0, "waypoints_m": [[X0 + 5, Y0 + 20], [X0 + 55, Y0 + 20]]})
    result = scanner_sim.simulate_pass(cfg, scanner_sim.PassOptions(max_pulses=6000, progress=False))
    coverage = result.summary["coverage"]
    assert 20.0 <= coverage["no_seabed_data_m2"] <= 30.0, coverage["no_seabed_data_m2"]


@pytest.mark.parametrize("driver, suffix", [("netCDF", "nc"), ("AAIGrid", "asc")])
def test_netcdf_and_ascii_grids_load(tmp_path, driver, suffix):
    """NetCDF (with a CF positive = down variable: depths) and an Arc/Info ASCII grid, copied from a GeoTIFF by
    GDAL, give the GeoTIFF's seabed."""
    from rasterio.shutil import copy

    values = bathymetry()
    sign = -1.0 if driver == "netCDF" else 1.0
    tags = {"positive": "down"} if driver == "netCDF" else {}
    write_raster(tmp_path / "src.tif", sign * values, **tags)
    copy(tmp_path / "src.tif", tmp_path / f"site.{suffix}", driver=driver)
    hf = build_scene(scene(tmp_path, {"raster": f"site.{suffix}"})).heightfield
    assert hf.height(X0 + 10.5, Y0 + 40 - 5.5) == pytest.approx(values[5, 10], abs=1e-4)


def test_micro_relief_is_seeded_and_reported_synthetic(tmp_path):
    """Micro-relief of 5 cm rms: the same seed gives the same seabed bit for bit, another seed another; its rms
    over the bilinear surface is the one asked; the outputs name it synthetic."""
    write_raster(tmp_path / "site.tif", bathymetry())
    plain = build_scene(scene(tmp_path, {"raster": "site.tif"})).heightfield.heights_m

    def relief(seed):
        return build_scene(scene(tmp_path, {"raster": "site.tif", "micro_relief": {"rms_m": 0.05, "seed": seed}}))

    a, b, c = relief(1), relief(1), relief(2)
    assert np.array_equal(a.heightfield.heights_m, b.heightfield.heights_m)
    assert not np.array_equal(a.heightfield.heights_m, c.heightfield.heights_m)
    assert np.std(a.heightfield.heights_m - plain) == pytest.approx(0.05, rel=1e-6)
    assert a.seabed_info["synthetic_relief_rms_m"] == 0.05 and a.seabed_info["synthetic_relief_seed"] == 1


def test_class_raster_gives_each_cell_its_material(tmp_path):
    """A class raster (west half code 1 = rock, east half code 2 = reflectance 0.3): the seabed faces take the
    material of the class under them."""
    write_raster(tmp_path / "site.tif", bathymetry())
    codes = np.where(np.arange(60)[None, :] < 30, 1, 2) * np.ones((40, 1))
    write_raster(tmp_path / "classes.tif", codes)
    built = build_scene(scene(tmp_path, {"raster": "site.tif", "classes": {
        "raster": "classes.tif", "materials": {1: {"material": "rock"}, 2: {"reflectance": 0.3}}}}))
    sb = built.objects[0]
    refl = built.face_reflectance[sb.face_start:sb.face_stop]
    centre_x = built.vertices[built.faces[sb.face_start:sb.face_stop]].mean(axis=1)[:, 0]
    assert np.all(refl[centre_x < X0 + 29.5] == 0.20) and np.all(refl[centre_x > X0 + 30.5] == 0.3)


def test_in_memory_grid_is_a_seabed(tmp_path):
    """The Python API takes a height grid with its affine transform in place of a file, through a whole pass
    (overrides and the provenance's fingerprint included): its points lie where the file's pass puts them."""
    values = bathymetry()
    grid = RasterGrid(values, from_origin(X0, Y0 + 40, CELL, CELL), "EPSG:32631")
    cfg = scene(tmp_path, {"raster": grid})
    hf = build_scene(cfg).heightfield
    assert hf.height(X0 + 10.5, Y0 + 40 - 5.5) == pytest.approx(values[5, 10])
    options = scanner_sim.PassOptions(max_pulses=500, progress=False)
    in_memory = scanner_sim.simulate_pass(cfg, options)
    write_raster(tmp_path / "site.tif", values)
    from_file = scanner_sim.simulate_pass(scene(tmp_path, {"raster": "site.tif"}), options)
    assert np.allclose(in_memory.points.xyz, from_file.points.xyz, atol=1e-5)


def test_the_rasters_bytes_are_in_the_pass_fingerprint(tmp_path):
    """Two rasters at one path with other values: the same scene, other inputs (the provenance's fingerprint
    differs), as for mesh files."""
    from scanner_sim.survey.provenance import inputs_fingerprint

    level = None
    prints = []
    for offset in (0.0, 0.5):
        write_raster(tmp_path / "site.tif", bathymetry() - offset)
        cfg = scene(tmp_path, {"raster": "site.tif"})
        prints.append(inputs_fingerprint(cfg, scanner_sim.PassOptions(), level or cfg.survey.level))
    assert prints[0] != prints[1]


BAD = {
    "no_crs": (dict(crs=None), "has no coordinate reference system"),
    "rotated": (dict(transform=Affine(1.0, 0.2, X0, 0.2, -1.0, Y0)), "rotated or sheared"),
    "one_cell": (dict(shape=(1, 1)), "a 1 x 1 grid"),
    "all_nodata": (dict(nodata=-12.0, fill=-12.0), "all 2,400 cells within margin_m of the survey's plan are nodata"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_raster_is_one_line_naming_the_key_exit_2(tmp_path, case):
    """A raster with no CRS, a rotated grid, a 1 x 1 grid or nothing but nodata: `scanner-sim validate --build`
    prints one line naming seabed.raster and exits 2."""
    options, message = BAD[case]
    values = np.full(options.pop("shape", (40, 60)), options.pop("fill", -12.0))
    write_raster(tmp_path / "bad.tif", values, **options)
    (tmp_path / "bad.yaml").write_text(
        "format_version: 1\nname: bad\nseabed: {raster: bad.tif, margin_m: 100}\nplatform: {mode: waypoints, altitude_m: 4,"
        f" waypoints_m: [[{X0 + 10}, {Y0 + 20}], [{X0 + 50}, {Y0 + 20}]]}}\n")
    run = subprocess.run([sys.executable, "-m", "scanner_sim.cli", "validate", str(tmp_path / "bad.yaml"), "--build"],
                         capture_output=True, text=True, cwd=ROOT, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin"})
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    prefix = "scanner-sim validate: error: seabed.raster = 'bad.tif': "
    assert len(lines) == 1 and lines[0].startswith(prefix) and message in lines[0], lines


def test_lawnmower_with_no_area_covers_the_rasters_valid_extent(tmp_path):
    """A lawnmower naming no area, heading east, over a raster whose 10 western columns and 5 southern rows are
    nodata: its lines run from the first to the last valid pixel centre in x (X0 + 10.5 to X0 + 59.5) and its
    first and last lines lie on the valid rows' extreme centres in y (Y0 + 5.5 to Y0 + 39.5), all of it over the
    seabed (no set-up warning of a track off it)."""
    import warnings

    from scanner_sim.config.errors import SetupWarning
    from scanner_sim.motion.track_checks import build_trajectory

    values = bathymetry()
    values[:, :10] = -9999.0
    values[35:, :] = -9999.0
    write_raster(tmp_path / "site.tif", values, nodata=-9999.0)
    cfg = scene(tmp_path, {"raster": "site.tif"}, platform={
        "mode": "lawnmower", "altitude_m": 4.0, "turn_length_m": 0.0,
        "lawnmower": {"heading_deg": 90.0, "line_spacing_m": 8.5}})
    with warnings.catch_warnings():
        warnings.simplefilter("error", SetupWarning)
        path = build_trajectory(cfg, build_scene(cfg))._xy
    assert path[:, 0].min() == pytest.approx(X0 + 10.5, abs=1e-5) and path[:, 0].max() == pytest.approx(X0 + 59.5, abs=1e-5)
    # 34 m across at 8.5 m spacing: 5 lines, centred on the valid rows' middle (Y0 + 22.5)
    assert path[:, 1].max() - path[:, 1].min() == pytest.approx(34.0, abs=1e-5)
    assert 0.5 * (path[:, 1].max() + path[:, 1].min()) == pytest.approx(Y0 + 22.5, abs=1e-5)


def test_south_up_raster_gives_the_same_seabed(tmp_path):
    """A grid stored south-up (rows running north, transform e > 0) is the same seabed as the north-up one: the
    height at every pixel centre is the same pixel's value."""
    values = bathymetry()
    write_raster(tmp_path / "north_up.tif", values)
    write_raster(tmp_path / "south_up.tif", values[::-1], transform=Affine(CELL, 0.0, X0, 0.0, CELL, Y0))
    a = build_scene(scene(tmp_path, {"raster": "north_up.tif"})).heightfield
    b = build_scene(scene(tmp_path, {"raster": "south_up.tif"})).heightfield
    assert (a.x0_m, a.y0_m, a.spacing_m) == (b.x0_m, b.y0_m, b.spacing_m)
    assert np.array_equal(a.heights_m, b.heights_m)


def test_coverage_map_draws_cells_without_seabed_data_apart(tmp_path):
    """coverage_map.png paints the cells with no seabed data in their own colour, and only where given."""
    import matplotlib.image as mpimg

    from scanner_sim.metrics.coverage import GAP_CAUSES
    from scanner_sim.render.coverage_map import plot_coverage_map
    from scanner_sim.render.plan_map import COVERAGE_COLOURS, NO_SEABED_COLOUR

    def colours(no_seabed):
        plot_coverage_map(tmp_path / "m.png", state, (0, 20, 0, 10), GAP_CAUSES, no_seabed=no_seabed)
        rgb = (mpimg.imread(tmp_path / "m.png")[..., :3] * 255).round().astype(int)
        return {tuple(c) for c in rgb.reshape(-1, 3)}

    def rgb_of(hex_colour):
        return tuple(int(hex_colour[i:i + 2], 16) for i in (1, 3, 5))

    state = np.full((40, 80), -1)
    mask = np.zeros(state.shape, bool)
    mask[10:20, 10:30] = True
    assert rgb_of(NO_SEABED_COLOUR) in colours(mask) and rgb_of(COVERAGE_COLOURS["covered"]) in colours(mask)
    assert rgb_of(NO_SEABED_COLOUR) not in colours(None)


def test_a_window_beyond_the_triangle_budget_is_refused_before_its_pixels_are_read(tmp_path, monkeypatch):
    """A 2,000 x 2,000 raster of 1 m cells read 1 km around the track: the window is columns 0 to 1,050 (x up to
    50 + 1,000 m, one more pixel) and rows 979 to 1,999 (y from 20 - 1,000 to 20 + 1,000 m): 1,051 x 1,021 pixels,
    refined 4 nodes a metre to 4,201 x 4,081 nodes, 2 x 4,200 x 4,080 = 34,272,000 triangles. Refused naming
    seabed.resolution_m before any pixel is read (rasterio's read is never called)."""
    import rasterio.io

    path = tmp_path / "big.tif"
    with rasterio.open(path, "w", driver="GTiff", width=2000, height=2000, count=1, dtype="float32",
                       crs="EPSG:32631", transform=from_origin(X0, Y0 + 2000, 1.0, 1.0), sparse_ok=True) as ds:
        ds.write(np.full((1, 10, 10), -12.0, "float32"), window=((0, 10), (0, 10)))
    cfg = scene(tmp_path, {"raster": "big.tif", "margin_m": 1000.0})
    reads = []
    original = rasterio.io.DatasetReader.read
    monkeypatch.setattr(rasterio.io.DatasetReader, "read",
                        lambda self, *a, **k: reads.append(k) or original(self, *a, **k))
    with pytest.raises(ConfigError, match=r"^seabed\.resolution_m = 0\.25: refines the raster's 1051 x 1021 window to "
                       r"34,272,000 triangles, more than the 32,000,000 allowed"):
        build_scene(cfg)
    assert reads == []


@pytest.mark.parametrize("driver, suffix", [("GTiff", "tif"), ("BAG", "bag")])
def test_vertical_datum_is_read_from_a_compound_crs(tmp_path, driver, suffix):
    """A raster in UTM 31N + NAP height (EPSG:32631+5709, the Dutch datum) names its vertical datum: the seabed block
    reports it, and the scene's crs 32631 is its horizontal frame."""
    from rasterio.crs import CRS

    write_raster(tmp_path / f"nap.{suffix}", bathymetry(), driver=driver, crs=CRS.from_user_input("EPSG:32631+5709"))
    info = build_scene(scene(tmp_path, {"raster": f"nap.{suffix}"}, crs=32631)).seabed_info
    assert info["vertical_datum"] == "Normaal Amsterdams Peil" and info["crs"] == "EPSG:32631"
