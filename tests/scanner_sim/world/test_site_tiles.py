"""Site-scale scenes (scanner_sim.world.site, scanner_sim.rays.tiles): a seabed kept as its heights and meshed in
windows of tiles as the pass goes gives the whole mesh's points, bit for bit."""

import numpy as np
import pytest

from scanner_sim.config import ConfigError, load_scene
from scanner_sim.rays import tiles
from scanner_sim.rays.caster import RayCaster
from scanner_sim.rays.tiles import TiledTarget
from scanner_sim.survey.pipeline import simulate_pass
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.world.scene import Scene, build_scene
from scanner_sim.world.site import TILED_ABOVE_TRIANGLES, SiteScene, tiled
from scanner_sim.world.terrain import HeightField

#: The lawnmower over rocks at a 25th of its pulses, in chunks of 2 s: 6,000 pulses reach 120 m of its track.
SLOW = {"scanner.pulse_rate_hz": 200.0, "survey.chunk_pulses": 400}
#: [m] How far on a window reaches in these tests (a 40 m seabed: a new window every few metres of the track).
AHEAD_M = 4.0


def assert_same_pass(a, b) -> None:
    """Two in-memory passes (simulate_pass results) are the same bit for bit: every point column, every dropout
    column and the coverage figures."""
    pa, pb = a.points.as_dict(), b.points.as_dict()
    assert pa.keys() == pb.keys()
    for name in pa:
        np.testing.assert_array_equal(pb[name], pa[name], err_msg=name)
    for name in ("pulse_index", "time_s", "origin", "direction", "cause"):
        np.testing.assert_array_equal(getattr(b.dropouts, name), getattr(a.dropouts, name), err_msg=name)
    assert b.summary["coverage"] == a.summary["coverage"]


@pytest.fixture(scope="module")
def lawnmower():
    config = load_scene("seabed_lawnmower").with_overrides(SLOW)
    return config, build_scene(config), build_scene(config, tile_m=2.0)


def test_tiling_rule_is_the_seabeds_triangle_count():
    """A seabed of exactly TILED_ABOVE_TRIANGLES triangles stays one mesh; one more column of cells tiles it."""
    ny = 1001
    nx = TILED_ABOVE_TRIANGLES // (2 * (ny - 1)) + 1  # 2 (nx - 1)(ny - 1) = the limit
    assert not tiled(HeightField(0.0, 0.0, 0.1, np.zeros((ny, nx))))
    assert tiled(HeightField(0.0, 0.0, 0.1, np.zeros((ny, nx + 1))))


def test_site_scale_seabed_is_accepted_and_a_larger_one_refused():
    """1 km x 200 m at 0.25 m (6.4 million triangles) validates; at 0.025 m (640 million) the key is named."""
    config = load_scene("seabed_lawnmower")
    assert config.with_overrides({"seabed.size_m": [1000, 200], "seabed.resolution_m": 0.25}).seabed.size_m[0] == 1000
    with pytest.raises(ConfigError, match="resolution_m"):
        config.with_overrides({"seabed.size_m": [1000, 200], "seabed.resolution_m": 0.025})


def test_window_faces_are_the_whole_scenes_faces(lawnmower):
    """Every face of a window, mapped to the whole scene's numbering, has the whole scene's corners (world, to the
    bit), normal, reflectance, label, object and surface: the rocks' faces as well as the seabed's."""
    _, whole, site = lawnmower
    t = site.tile_cells
    window = site.window(2 * t, 5 * t, t, 3 * t)
    same = site.site_faces(window, np.arange(window.n_faces))
    np.testing.assert_array_equal(window.vertices[window.faces], whole.vertices[whole.faces[same]])
    for name in ("face_normal", "face_reflectance", "face_label", "face_object", "face_surface"):
        np.testing.assert_array_equal(getattr(window, name), getattr(whole, name)[same], err_msg=name)
    np.testing.assert_array_equal(site.face_surface[same], whole.face_surface[same])
    assert window.n_faces - 2 * (3 * t) * (2 * t) == whole.n_faces - site.seabed_faces  # every rock's face is there


def test_site_has_the_whole_scenes_frame_and_objects(lawnmower):
    """The local origin and extent (which the float32 casts and the shadow-ray step depend on), the object list and
    the face count are the whole scene's."""
    _, whole, site = lawnmower
    np.testing.assert_array_equal(site.local_origin, whole.local_origin)
    assert site.local_extent_m == whole.local_extent_m
    assert site.n_faces == whole.n_faces
    assert [(o.object_id, o.name, o.kind, o.label) for o in site.objects] == [
        (o.object_id, o.name, o.kind, o.label) for o in whole.objects]


def test_first_hits_of_any_ray_are_the_whole_scenes(lawnmower):
    """Rays from above the seabed, in order along x, most of them steeply down, the rest in any direction (slant,
    level, up; many miss or leave the site): the tiled target's first hits (ray, face in the whole scene's
    numbering, distance) are the whole caster's, though each group of them is cast into a window of its own."""
    _, whole, site = lawnmower
    rng = np.random.default_rng(5)
    n = 4000
    origin = np.c_[np.sort(rng.uniform(-25, 25, n)), rng.uniform(-20, 20, n), rng.uniform(-38, -33, n)]
    direction = rng.standard_normal((n, 3))
    down = rng.random(n) < 0.75
    direction[down, 2] = -4.0 * np.abs(direction[down, 2]) - 2.0
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    origin = origin - whole.local_origin
    expected = RayCaster.for_scene(whole).first_hits(origin, direction)
    target = TiledTarget(site)
    got = target.first_hits(origin, direction)
    for e, g in zip(expected, got):
        np.testing.assert_array_equal(g, e)
    assert len(expected[0]) > n // 2 and n - len(expected[0]) > n // 20 and target.windows_built > 3


@pytest.mark.parametrize("fidelity", ["fast", "auto"])
def test_tiled_pass_gives_the_whole_scenes_points_and_dropouts(lawnmower, fidelity, monkeypatch):
    """6,000 pulses over the lawnmower's rocks and relief, in windows of 2 m tiles reaching 4 m on (dozens built):
    every point column (position, truth, class, object, surface, channel...) and every dropout equal the whole
    mesh's pass, at a level that casts every sub-ray (fast) and at the one whose seabed hits come from the proof grid
    (auto)."""
    config, whole, site = lawnmower
    monkeypatch.setattr(tiles, "WINDOW_AHEAD_M", AHEAD_M)
    options = PassOptions(max_pulses=6000, fidelity=fidelity, progress=False, render=False, write_scene=False)
    a, b = simulate_pass(config, options, scene=whole), simulate_pass(config, options, scene=site)
    assert len(a.points) > 5000
    assert_same_pass(a, b)
    assert set(np.unique(a.points.object_id)) == {0, 1}  # the seabed and its rocks met


def test_pass_over_a_site_builds_windows_as_it_goes(lawnmower, monkeypatch):
    """The pass's target is tiled for a SiteScene, keeps no more windows than it may, and builds them as it moves."""
    config, _, site = lawnmower
    monkeypatch.setattr(tiles, "WINDOW_AHEAD_M", AHEAD_M)
    options = PassOptions(max_pulses=3000, progress=False, render=False, write_scene=False)
    setup = PassSetup.build(config, options, site)
    assert isinstance(setup.target, TiledTarget) and isinstance(setup.scene, SiteScene)
    before = setup.target.windows_built
    for slots in setup.slot_chunks():
        setup.simulate_chunk(slots)
    assert setup.target.windows_built > before + 5
    assert len(setup.target._windows) <= tiles.KEPT_WINDOWS
    assert isinstance(PassSetup.build(config, options, build_scene(config)).scene, Scene)


def test_a_tile_size_that_is_not_positive_is_refused_in_one_line():
    from muls.infra.errors import ParameterError

    with pytest.raises(ParameterError, match=r"^tile_m = -4\.0: must be a tile's side in metres, > 0"):
        build_scene(load_scene("seabed_lawnmower"), tile_m=-4.0)


def test_a_chunks_coverage_tally_takes_memory_for_its_pulses_not_for_the_whole_grid():
    """Coverage counted each chunk's pulses with ``np.bincount(..., minlength=n_bins)``: two arrays as large as the
    whole plan grid made and added per chunk (25 MB each over a 1 km x 200 m site at 0.25 m cells), a cost that
    grew with the site, not with the chunk (site passes ran slower the larger the site: 83,000 pulses/s at 500 m,
    63,000 at 4 km). Now the counts are added where the pulses are; the same counts as bincount's."""
    import tracemalloc

    from scanner_sim.metrics.coverage import FAILURE_CAUSES, BinTally

    rng = np.random.default_rng(2)
    big = BinTally(10_000_000)
    reaching = rng.integers(-1, 10_000_000, 3000)
    outcome = rng.integers(-1, len(FAILURE_CAUSES), 3000)
    valid = rng.integers(-1, 10_000_000, 2000)
    tracemalloc.start()
    big.add(reaching, outcome, valid)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 1_000_000  # bytes: the chunk's few thousand pulses, not 80 MB of bins
    small = BinTally(50)
    r, v = reaching % 51 - 1, valid % 51 - 1
    small.add(r, outcome, v)
    small.add(r, outcome, v)
    np.testing.assert_array_equal(small.reaching, 2 * np.bincount(r[r >= 0], minlength=50))
    np.testing.assert_array_equal(small.valid, 2 * np.bincount(v[v >= 0], minlength=50))


def test_bench_site_reports_the_figures_its_targets_are_judged_on(monkeypatch):
    """``scanner-sim bench-site --json``'s keys, on a small stand-in (in this process, a minute of survey): the
    site's triangles, set-up, peak memory and pulses/s, the small scene's pulses/s, the memory by minutes of survey,
    and the rule by which pulses were left out; over the procedural seabeds and over generated rasters."""
    from scanner_sim.perf import sitebench

    monkeypatch.setattr(sitebench, "_in_fresh_process", lambda fn, *args: fn(*args))
    monkeypatch.setattr(sitebench, "SITE_SIZE_M", (80.0, 40.0))
    monkeypatch.setattr(sitebench, "SMALL_SIZE_M", (60.0, 40.0))
    monkeypatch.setattr(sitebench, "SMALL_SECONDS", 10.0)
    monkeypatch.setattr(sitebench, "RSS_MINUTES", (1,))
    result = sitebench.bench_site("fast", minutes=1)
    assert result["site"]["triangles"] == 2 * 320 * 160
    assert {"setup_s", "peak_rss_mb", "pulses_per_s"} <= result["site"].keys() and result["site"]["pulses"] > 30000
    assert result["small"]["pulses_per_s"] > 0 and list(result["rss_mb_by_minutes"]) == ["1"]
    assert result["rss_mb_by_minutes"]["1"] > 50 and "every other pulse" in result["subsampling"]
    raster = sitebench.bench_site("fast", minutes=1, seabed="raster")  # a GeoTIFF of 81 x 41 pixels, 1 m, at 0.25 m
    assert raster["seabed"] == "raster" and raster["site"]["triangles"] == 2 * 320 * 160
    assert raster["site"]["pulses"] > 30000 and raster["small"]["pulses_per_s"] > 0
