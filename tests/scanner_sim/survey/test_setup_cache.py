"""What the set-up keeps between runs (scanner_sim/survey/setup_cache.py), the ranging-precision table and the built
scene: the same inputs read it back (a scene the very one a build gives), any changed input measures or builds it
again, and a damaged entry is measured or built again and replaced, never trusted."""

from __future__ import annotations

import dataclasses
import gc
import os
import shutil
import weakref
from types import SimpleNamespace

import numpy as np
import pytest

from scanner_sim import load_scene
from scanner_sim.rays.cast import CastScene
from scanner_sim.survey import setup_cache
from scanner_sim.survey.ranging_precision import RangingPrecision
from scanner_sim.survey.setup import PassOptions, PassSetup
from tests.conftest import ROOT


@pytest.fixture
def measured(tmp_path, monkeypatch):
    """The cache under ``tmp_path``; the measurement replaced by one that counts its calls and whose table depends on
    the physics' seed and the ranges (so a wrong entry read back would show)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    calls = []

    def measure(physics, instrument, ranges_m):
        calls.append((physics.seed, tuple(ranges_m)))
        shape = (3, 2, 2, len(ranges_m), 24)
        bias = np.random.default_rng(physics.seed).normal(0.0, 0.01, shape)
        return RangingPrecision(bias, np.abs(bias), np.full(shape, 20), np.geomspace(1.0, 1e6, 25), tuple(ranges_m))

    monkeypatch.setattr(setup_cache, "measure_ranging_precision", measure)
    return calls


def physics(seed: int = 7, record_mode: str = "ch0_peak"):
    model = SimpleNamespace(instrument="inst", water=("coastal", 0.3), multiple_scattering="table",
                            tables=np.arange(5.0), attenuation=None, scattering=None)
    return SimpleNamespace(model=model, seed=seed, record_mode=record_mode, deciding_only=True)


def same(a: RangingPrecision, b: RangingPrecision) -> bool:
    return (a.ranges_m == b.ranges_m and all(np.array_equal(getattr(a, f), getattr(b, f))
                                            for f in ("bias_m", "std_m", "count", "snr_edges")))


def test_the_same_inputs_read_the_table_back(measured):
    first = setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    again = setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    assert measured == [(7, (2.0, 3.5))] and same(first, again)


@pytest.mark.parametrize("changed", [dict(seed=8), dict(record_mode="full"), dict(ranges=(2.0, 3.6)),
                                     dict(tables=np.arange(5.0) + 1e-12)])
def test_a_changed_input_misses(measured, changed):
    setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    other = physics(changed.get("seed", 7), changed.get("record_mode", "ch0_peak"))
    if "tables" in changed:
        other.model.tables = changed["tables"]
    table = setup_cache.cached_ranging_precision(other, "inst", changed.get("ranges", (2.0, 3.5)))
    assert len(measured) == 2
    assert table.ranges_m == changed.get("ranges", (2.0, 3.5))


def test_a_damaged_entry_is_measured_again_and_replaced(measured):
    first = setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    (entry,) = setup_cache.tables_dir().rglob("ranging_*.npz")
    data = bytearray(entry.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 8] = bytes(8 * [0xFF])  # inside the stored arrays: only the zip's CRC can tell
    entry.write_bytes(bytes(data))
    again = setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    assert len(measured) == 2 and same(first, again)
    entry.write_bytes(b"")  # truncated to nothing
    setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    assert len(measured) == 3
    setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    assert len(measured) == 3  # replaced by a good entry


def test_an_unwritable_cache_measures_each_time(measured, tmp_path, monkeypatch):
    (tmp_path / "file").write_text("not a folder")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "file"))
    for _ in range(2):
        assert setup_cache.cached_ranging_precision(physics(), "inst", (2.0,)).ranges_m == (2.0,)
    assert len(measured) == 2


@pytest.fixture
def builds(tmp_path, monkeypatch):
    """The cache under ``tmp_path``; the scene build counted (the scenes it returns, in order)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    built = []

    def build(config):
        built.append(real_build(config))
        return built[-1]

    real_build = setup_cache.build_scene
    monkeypatch.setattr(setup_cache, "build_scene", build)
    return built


@pytest.fixture
def mine_field(tmp_path):
    """mine_field (procedural seabed with rocks, three mines, a mesh file) coarsened to build in a moment, read from a
    copy of the scene file and its mesh under ``tmp_path``."""
    (tmp_path / "assets").mkdir()
    shutil.copy(ROOT / "scenes" / "mine_field.yaml", tmp_path)
    shutil.copy(ROOT / "scenes" / "assets" / "mooring_block.obj", tmp_path / "assets")
    return load_scene(tmp_path / "mine_field.yaml").with_overrides({"seabed.resolution_m": 0.2})


def same_value(a, b) -> bool:
    """``a`` and ``b`` hold the same values to the bit: arrays by their bytes, shapes and types, objects attribute by
    attribute."""
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(map(same_value, a, b))
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same_value(a[k], b[k]) for k in a)
    if dataclasses.is_dataclass(a) or hasattr(a, "__dict__") and not callable(a):
        return type(a) is type(b) and same_value(vars(a), vars(b))
    return a == b


def test_a_scene_reads_back_the_very_scene_a_build_gives(builds, mine_field):
    first = setup_cache.stored_scene(mine_field)
    again = setup_cache.stored_scene(mine_field)
    assert len(builds) == 1 and again is not first
    assert same_value(vars(first), vars(again)) and again.n_faces == first.n_faces > 10_000
    assert [o.name for o in again.objects][-1] == "mooring_block"


def moved_sphere(config) -> dict:
    objects = [o.model_dump(exclude_unset=True) for o in config.objects]
    objects[0]["position_m"] = [-5.0, 0.9]
    return {"objects": objects}


@pytest.mark.parametrize("override", [lambda c: {"seabed.seed": 4}, lambda c: {"seabed.rocks.count": 39},
                                      moved_sphere, lambda c: {"crs": "EPSG:32630"}])
def test_a_changed_scene_section_builds_again(builds, mine_field, override):
    setup_cache.stored_scene(mine_field)
    setup_cache.stored_scene(mine_field.with_overrides(override(mine_field)))
    assert len(builds) == 2


def test_a_changed_track_reuses_a_procedural_seabed_but_not_a_raster_window(builds, mine_field):
    setup_cache.stored_scene(mine_field)
    setup_cache.stored_scene(mine_field.with_overrides({"platform.waypoints_m": [[-8, 0], [8, 0]]}))
    assert len(builds) == 1  # the procedural seabed does not follow the track
    site = load_scene("real_site")  # its raster spans x 614164 to 614236, y 4494756 to 4494812 [m]
    areas = [site.with_overrides({"platform.lawnmower.center_m": [614200.0 + dx, 4494790.0],
                                  "platform.lawnmower.size_m": [30, 20]}) for dx in (0.0, 5.0)]
    assert setup_cache.scene_key(areas[0]) != setup_cache.scene_key(areas[1])  # the raster window read follows the plan


def test_a_changed_mesh_file_builds_again(builds, mine_field, tmp_path):
    setup_cache.stored_scene(mine_field)
    mesh = tmp_path / "assets" / "mooring_block.obj"
    stat = mesh.stat()
    os.utime(mesh, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    setup_cache.stored_scene(mine_field)
    assert len(builds) == 2


def test_a_damaged_scene_is_built_again_and_replaced(builds, mine_field):
    setup_cache.stored_scene(mine_field)
    (entry,) = setup_cache.scenes_dir().rglob("scene_*.pickle")
    data = bytearray(entry.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 8] = bytes(8 * [0xFF])  # inside an array's bytes: the pickle would still load
    entry.write_bytes(bytes(data))
    again = setup_cache.stored_scene(mine_field)
    assert len(builds) == 2 and same_value(vars(builds[0]), vars(again))
    entry.write_bytes(entry.read_bytes()[:1000])  # truncated
    setup_cache.stored_scene(mine_field)
    assert len(builds) == 3
    assert same_value(vars(setup_cache.stored_scene(mine_field)), vars(builds[0]))
    assert len(builds) == 3  # replaced by a good entry


def test_an_unwritable_cache_builds_each_time(builds, mine_field, tmp_path, monkeypatch):
    (tmp_path / "file").write_text("not a folder")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "file"))
    for _ in range(2):
        setup_cache.stored_scene(mine_field)
    assert len(builds) == 2


def test_the_least_recently_used_scenes_go_beyond_the_budget(builds, mine_field, monkeypatch):
    setup_cache.stored_scene(mine_field)
    (first,) = setup_cache.scenes_dir().rglob("scene_*.pickle")
    monkeypatch.setattr(setup_cache, "SCENES_KEPT_BYTES", int(2.5 * first.stat().st_size))
    seeds = [mine_field.with_overrides({"seabed.seed": seed}) for seed in (4, 5)]
    setup_cache.stored_scene(seeds[0])
    os.utime(first, ns=(0, 0))  # the oldest use ...
    setup_cache.stored_scene(mine_field)  # ... until it is read again: the first of seed 4 is now the oldest
    setup_cache.stored_scene(seeds[1])
    assert len(list(setup_cache.scenes_dir().rglob("scene_*.pickle"))) == 2
    setup_cache.stored_scene(mine_field)
    setup_cache.stored_scene(seeds[1])
    assert len(builds) == 3  # both kept; seed 4's went
    setup_cache.stored_scene(seeds[0])
    assert len(builds) == 4


def test_the_budget_holds_the_scenes_of_every_source_state(builds, mine_field, monkeypatch):
    """Each edit of the code is a new source state, whose runs store their scenes anew: the budget counts the
    scenes of the older states too, so that editing does not pile up a scene per run."""
    setup_cache.stored_scene(mine_field)
    (first,) = setup_cache.scenes_dir().rglob("scene_*.pickle")
    monkeypatch.setattr(setup_cache, "SCENES_KEPT_BYTES", int(1.5 * first.stat().st_size))
    os.utime(first, ns=(0, 0))
    monkeypatch.setattr(setup_cache, "code_key", lambda: "an_edited_state")
    setup_cache.stored_scene(mine_field)
    assert len(builds) == 2
    assert [p.parent.name for p in setup_cache.scenes_dir().rglob("scene_*.pickle")] == ["an_edited_state"]


def test_passes_of_one_scene_in_a_row_share_its_object_and_its_bvh(builds, mine_field):
    """In one process the passes of one scene (a campaign over waters and altitudes) get one scene object, read or
    built once, and the ray stage builds one BVH over it; a pass of another scene replaces it."""
    first = setup_cache.cached_scene(mine_field)
    other_water = setup_cache.cached_scene(mine_field.with_overrides({"water": "turbid_harbor",
                                                                      "platform.altitude_m": 6.0}))
    assert other_water is first and len(builds) == 1
    assert CastScene.of(first).caster is CastScene.of(other_water).caster
    other_seabed = setup_cache.cached_scene(mine_field.with_overrides({"seabed.seed": 4}))
    assert other_seabed is not first and len(builds) == 2
    assert CastScene.of(other_seabed).caster is not CastScene.of(first).caster


def test_a_scene_s_bvh_goes_with_the_scene(builds, mine_field):
    """The BVH kept for a scene object (CastScene.of) is dropped once the scene is: a dataset's millionth scene does not
    hold the BVHs of the ones before."""
    setup_cache.stored_scene(mine_field)  # built (the fixture keeps what it builds) and stored
    scene = setup_cache.stored_scene(mine_field)  # read back: held here alone
    caster = weakref.ref(CastScene.of(scene).caster)
    assert caster() is not None
    del scene
    gc.collect()
    assert caster() is None


def test_a_pass_on_a_shared_bvh_gives_the_same_points_as_on_its_own(builds, mine_field):
    """Set-ups of one scene in a row share its BVH; their pulses give the same points to the bit as on a BVH built for
    the pass alone (CastScene.build)."""
    options = PassOptions(max_pulses=400, progress=False, render=False)
    shared = [PassSetup.build(mine_field, options) for _ in range(2)]
    assert shared[0].target.caster is shared[1].target.caster
    alone = dataclasses.replace(shared[1], target=CastScene.build(shared[1].target.scene))
    slots = next(iter(shared[0].slot_chunks()))
    points = [setup.simulate_chunk(slots).points for setup in (*shared, alone)]
    for other in points[1:]:
        assert all(np.array_equal(getattr(points[0], f.name), getattr(other, f.name), equal_nan=True)
                   for f in dataclasses.fields(points[0]))
