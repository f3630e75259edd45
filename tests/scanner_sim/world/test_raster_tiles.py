"""A raster seabed tiled as a procedural one is (scanner_sim.world.site, scanner_sim.rays.tiles): its nodata gaps,
its class raster's materials and its surfaces split by the gaps are each window's as the whole scene has them, and
the pass over the tiles gives the whole mesh's points, bit for bit."""

import numpy as np
import pytest
from rasterio.transform import from_origin

from scanner_sim.rays import tiles
from scanner_sim.survey.pipeline import simulate_pass
from scanner_sim.survey.setup import PassOptions
from scanner_sim.world.scene import Scene, build_scene
from scanner_sim.world.site import TILED_ABOVE_TRIANGLES, SiteScene
from tests.scanner_sim.world.test_raster_seabed import CELL, X0, Y0, bathymetry, scene, write_raster
from tests.scanner_sim.world.test_site_tiles import assert_same_pass

#: [m] How far on a window reaches in these tests (a 60 m raster: a new window every few metres of the line).
AHEAD_M = 4.0
#: Nodata columns: a 2 m wide strip across the whole raster (north to south), which parts the seabed in two.
GAP_COLUMNS = slice(28, 30)


@pytest.fixture(scope="module")
def holed(tmp_path_factory):
    """A 60 x 40 m raster (1 m cells, UTM 31N) with a nodata strip across it and a nodata block, a class raster
    (code 1 west of x = 20 m, 2 east of it), a cylinder mine east of the strip, and the line across them; the
    scene whole and tiled in 2 m tiles."""
    tmp_path = tmp_path_factory.mktemp("holed")
    values = bathymetry()
    values[:, GAP_COLUMNS] = -9999.0
    values[5:9, 40:44] = -9999.0
    write_raster(tmp_path / "site.tif", values, nodata=-9999.0)
    codes = np.where(np.arange(60)[None, :] < 20, 1, 2) * np.ones((40, 1))
    write_raster(tmp_path / "classes.tif", codes)
    config = scene(tmp_path, {"raster": "site.tif", "classes": {
        "raster": "classes.tif", "materials": {1: {"material": "rock"}, 2: {"reflectance": 0.3}}}},
        objects=[{"type": "cylinder_mine", "name": "mine", "position_m": [X0 + 40, Y0 + 20], "radius_m": 0.27,
                  "length_m": 1.8, "heading_deg": 30}]).with_overrides({"scanner.pulse_rate_hz": 600.0,
                                                                          "survey.chunk_pulses": 400})
    return config, build_scene(config), build_scene(config, tile_m=2.0)


def test_holed_raster_scene_is_what_the_tests_need(holed):
    """The whole scene's seabed has its gaps (fewer faces than cells), two surfaces (parted by the strip), two
    reflectances (the class raster's), and the mine as surfaces after them: what the tiled checks below compare."""
    _, whole, site = holed
    sb = whole.objects[0]
    ny, nx = whole.heightfield.shape
    assert sb.face_stop < 2 * (nx - 1) * (ny - 1)
    assert set(np.unique(whole.face_surface[:sb.face_stop])) == {0, 1}
    assert set(np.unique(whole.face_reflectance[:sb.face_stop])) == {0.2, 0.3}
    assert whole.face_surface[sb.face_stop:].min() == 2
    assert isinstance(site, SiteScene) and site.n_faces == whole.n_faces and site.seabed_faces == sb.face_stop
    assert site.seabed_info == whole.seabed_info and site.seabed_info["crs"] == "EPSG:32631"
    assert site.crs == whole.crs


@pytest.mark.parametrize("corner", [(0, 0), (8, 4), (12, 2)])
def test_raster_window_faces_are_the_whole_scenes_faces(holed, corner):
    """Every face of a window (at the raster's corner, over the gap strip, over the block), mapped to the whole
    scene's numbering, has the whole scene's corners (world, to the bit), normal, reflectance, label, object and
    surface, and the window holds each whole-scene seabed face over its cells once: the gaps have none."""
    _, whole, site = holed
    t = site.tile_cells
    j0, i0 = corner[0] * t, corner[1] * t
    window = site.window(j0, j0 + 3 * t, i0, i0 + 2 * t)
    same = site.site_faces(window, np.arange(window.n_faces))
    np.testing.assert_array_equal(window.vertices[window.faces], whole.vertices[whole.faces[same]])
    for name in ("face_normal", "face_reflectance", "face_label", "face_object", "face_surface"):
        np.testing.assert_array_equal(getattr(window, name), getattr(whole, name)[same], err_msg=name)
    np.testing.assert_array_equal(site.face_surface[same], whole.face_surface[same])
    seabed = same[same < site.seabed_faces]
    corners = whole.vertices[whole.faces[:site.seabed_faces]]
    lo = whole.heightfield.x0_m + j0 * whole.heightfield.spacing_m, whole.heightfield.y0_m + i0 * whole.heightfield.spacing_m
    inside = ((corners[:, :, 0].min(axis=1) >= lo[0]) & (corners[:, :, 0].max(axis=1) <= lo[0] + 3 * t * 0.25)
              & (corners[:, :, 1].min(axis=1) >= lo[1]) & (corners[:, :, 1].max(axis=1) <= lo[1] + 2 * t * 0.25))
    np.testing.assert_array_equal(np.sort(seabed), np.flatnonzero(inside))


@pytest.mark.parametrize("fidelity", ["fast", "auto"])
def test_tiled_raster_pass_gives_the_whole_scenes_points_and_dropouts(holed, fidelity, monkeypatch):
    """6,000 pulses along the line over the class raster, the gap strip, the block and the mine, in windows of 2 m
    tiles reaching 4 m on (dozens built): every point column and every dropout equal the whole mesh's pass, and so
    do the coverage figures (the gaps counted as no seabed data alike)."""
    config, whole, site = holed
    monkeypatch.setattr(tiles, "WINDOW_AHEAD_M", AHEAD_M)
    options = PassOptions(max_pulses=6000, fidelity=fidelity, progress=False, render=False, write_scene=False)
    a, b = simulate_pass(config, options, scene=whole), simulate_pass(config, options, scene=site)
    assert len(a.points) > 3000
    assert_same_pass(a, b)
    assert b.summary["seabed"] == a.summary["seabed"]
    x = a.points.xyz[:, 0] - X0
    assert (x < 28).sum() > 1000 and (x > 30).sum() > 1000 and 1 in a.points.object_id  # both sides of the strip, mine
    assert len(a.dropouts.cause) > 100  # pulses through the gaps


def test_raster_window_beyond_two_million_triangles_is_tiled_not_refused(tmp_path):
    """A raster seabed was meshed whole, so a window refined past TILED_ABOVE_TRIANGLES (2,000,000) was refused
    naming seabed.resolution_m. A 400 x 200 m raster of 1 m cells at 0.25 m: nodes from the first pixel centre to
    the last, 399 x 4 + 1 = 1,597 by 199 x 4 + 1 = 797, 2 x 1,596 x 796 = 2,540,832 triangles less the nodata
    block's. It is now a SiteScene, tiled like a procedural seabed: faces counted by hand, the raster's report and
    CRS carried; at 1 m it stays one mesh unless tile_m asks for tiles."""
    yy, xx = np.mgrid[0:200, 0:400]
    values = -12.0 + 0.5 * np.sin(xx / 9.0) + 0.3 * np.cos(yy / 7.0)
    values[50:60, 100:120] = -9999.0  # rows 50..59 from the north (140..149 from the south), columns 100..119
    write_raster(tmp_path / "big.tif", values, nodata=-9999.0, transform=from_origin(X0, Y0 + 200, CELL, CELL))
    config = scene(tmp_path, {"raster": "big.tif"}, platform={
        "mode": "lawnmower", "altitude_m": 4.0, "lawnmower": {"line_spacing_m": 20.0}}, crs="EPSG:32631")
    built = build_scene(config)
    assert isinstance(built, SiteScene)
    # Node k (0.25 m steps from the first pixel centre) lies in pixel floor(k / 4 + 1/2): pixels 100..119 hold node
    # columns 398..477, so cells 397..477 (81) lack a node; pixels 140..149 hold node rows 558..597: cells 557..597
    # (41). A cell is seabed when its four nodes are.
    assert built.n_faces == 2 * (1596 * 796 - 81 * 41) and 2 * 1596 * 796 > TILED_ABOVE_TRIANGLES
    assert built.seabed_info["crs"] == "EPSG:32631" and built.seabed_info["valid_cell_fraction"] < 1.0
    assert built.crs is not None and built.crs.to_epsg() == 32631
    coarse = config.with_overrides({"seabed.resolution_m": 1.0})
    assert isinstance(build_scene(coarse), Scene)
    assert isinstance(build_scene(coarse, tile_m=8.0), SiteScene)
