"""The shipped real site: a public survey's BAG loads with its CRS, sign and nodata; the shipped scene names its
raster by a path relative to the scene file, carries crs and leaves the lawnmower's area to the raster, so that
swapping the raster and the crs is all it takes to survey another place."""

from pathlib import Path

import numpy as np
import pytest
import rasterio

import scanner_sim
from scanner_sim.config import SCENES_DIR, load_scene, parse_scene
from scanner_sim.world.scene import build_scene

SITE = SCENES_DIR / "assets" / "real_site"


def test_public_bag_sample_loads_with_its_sign_crs_and_gaps(tmp_path):
    """NOAA H12607's BAG (shipped unchanged, from hyo2-bag's samples): read as elevation (BAG's rule), its nodata
    cells are gaps, and every pixel centre's height is the pixel's value; its range is the one GDAL's own
    statistics in the file give (-16.776 to -0.823 m)."""
    cfg = parse_scene({"format_version": 1, "name": "bag", "crs": "EPSG:26918",
                       "seabed": {"raster": str(SITE / "H12607_extract.bag")},
                       "platform": {"mode": "waypoints", "depth_m": 0.5,
                                    "waypoints_m": [[614150.0, 4494784.0], [614220.0, 4494784.0]]}})
    built = build_scene(cfg)
    hf, info = built.heightfield, built.seabed_info
    assert info["driver"] == "BAG" and info["vertical"] == "elevation_up" and info["vertical_datum"] is None
    with rasterio.open(SITE / "H12607_extract.bag") as ds:
        band = ds.read(1, masked=True)
        rows, cols = np.nonzero(~band.mask)
        x, y = ds.transform @ (cols + 0.5, rows + 0.5)
    assert band.min() == pytest.approx(-16.776, abs=1e-3) and band.max() == pytest.approx(-0.823, abs=1e-3)
    inside = hf.covers(x, y)
    assert inside.mean() > 0.5
    assert np.allclose(hf.height(x[inside], y[inside]), band.data[rows, cols][inside], atol=1e-4)
    gap_rows, gap_cols = np.nonzero(band.mask)
    gx, gy = ds.transform @ (gap_cols + 0.5, gap_rows + 0.5)
    assert not hf.covers(gx, gy).any()


def test_shipped_real_site_names_its_raster_relative_and_carries_crs():
    text = (SCENES_DIR / "real_site.yaml").read_text()
    cfg = load_scene("real_site")
    assert cfg.crs == "EPSG:26918" and not Path(cfg.seabed.raster).is_absolute()
    assert cfg.seabed.resolved_raster == SITE / "H12607_deep.tif"
    assert cfg.platform.lawnmower.size_m is None and "    size_m:" not in text


def test_swapping_raster_and_crs_surveys_another_place(tmp_path):
    """The real site's scene with only seabed.raster and crs replaced (a generated UTM 31N GeoTIFF): it builds, its
    lawnmower covers the new raster, and the pass's points lie in the new place, on its seabed."""
    from rasterio.transform import from_origin

    x0, y0 = 431_000.0, 5_712_000.0
    yy, xx = np.mgrid[0:20, 0:30]
    z = (-14.0 + 0.5 * np.sin(xx / 4.0) + 0.3 * np.cos(yy / 3.0)).astype("float32")
    with rasterio.open(tmp_path / "north_sea.tif", "w", driver="GTiff", width=30, height=20, count=1,
                       dtype="float32", crs="EPSG:32631", transform=from_origin(x0, y0, 2.0, 2.0)) as ds:
        ds.write(z, 1)
    cfg = load_scene("real_site").with_overrides({"seabed.raster": str(tmp_path / "north_sea.tif"),
                                                 "crs": "EPSG:32631"})
    result = scanner_sim.simulate_pass(cfg, scanner_sim.PassOptions(max_pulses=3000, progress=False))
    xyz = result.points.xyz
    assert len(xyz) > 1000
    assert (xyz[:, 0] > x0).all() and (xyz[:, 0] < x0 + 60).all()
    assert (xyz[:, 1] < y0).all() and (xyz[:, 1] > y0 - 40).all()
    assert (np.abs(xyz[:, 2] + 14.0) < 1.0).all()
    assert result.summary["settings"]["crs"] == "EPSG:32631"
