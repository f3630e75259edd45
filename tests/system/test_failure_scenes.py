"""The failure scenes of docs/fidelity.md (``scenes/failures/``): each loads, builds and has its rows in the page's
failure table; the wreck, quay-wall and moored-mine scenes have the geometry their headers claim, checked by
casting the first pulses' beam axes into the built scene against dimensions computed by hand."""

import importlib.util
import math
import re
from pathlib import Path

import numpy as np
import pytest

from scanner_sim.config import load_scene
from scanner_sim.fidelity import FIDELITY_LEVELS
from scanner_sim.studies.tradeoff import FAILURE_ROW
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.world.scene import build_scene

ROOT = Path(__file__).resolve().parents[2]
FAILURES = ROOT / "scenes" / "failures"
SCENES = sorted(p.stem for p in FAILURES.glob("*.yaml"))


def _failure_table() -> list[list[str]]:
    """The cells of docs/fidelity.md's failure-scene table, one list per row (header and rule left out)."""
    text = (ROOT / "docs" / "fidelity.md").read_text()
    section = text.split("### Failure scenes", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| ")]
    return [[c.strip() for c in line.strip("|").split("|")] for line in rows[1:]]


@pytest.mark.parametrize("name", SCENES)
def test_failure_scene_loads_and_builds(name):
    path = FAILURES / f"{name}.yaml"
    assert path.read_text().startswith("# Failure scene of docs/fidelity.md: ")
    cfg = load_scene(path)
    assert cfg.name == name
    cfg.water_model()
    cfg.instrument_model()
    assert build_scene(cfg).n_faces > 0


def test_every_failure_scene_has_its_rows_in_the_failure_table():
    """Each scene of scenes/failures/ has one row per level and the reference at 217 sub-rays in the table, with
    as many cells as ``scanner-sim tradeoff --failure-rows`` prints, and the table names no other scene."""
    rows = _failure_table()
    levels = [*FIDELITY_LEVELS, "reference at 217"]
    assert {r[0] for r in rows} == set(SCENES)
    for name in SCENES:
        assert [r[1] for r in rows if r[0] == name] == levels
    assert {len(r) for r in rows} == {2 + len(FAILURE_ROW)}


def _axis_hits(name: str, pulses: int = 3000):
    """The first hits of the beam axes of the scene's first ``pulses`` pulses: (object names (k,), distance (k,) [m],
    world hit points (k, 3) [m], the face normals (k, 3), the beam directions (k, 3)) of the axes that hit."""
    setup = PassSetup.build(load_scene(FAILURES / f"{name}.yaml"), PassOptions(max_pulses=pulses),
                            level=FIDELITY_LEVELS["fast"])
    slots = np.concatenate(list(setup.slot_chunks()))
    origin, direction, *_ = setup.scanner.world_rays(setup.trajectory.poses(slots / setup.scanner.pulse_rate_hz))
    scene = setup.target.scene
    ray, tri, dist = setup.target.caster.first_hits(origin - scene.local_origin, direction)
    dist = dist.astype(float)
    names = np.array([o.name for o in scene.objects])[scene.face_object[tri]]
    return names, dist, origin[ray] + dist[:, None] * direction[ray], scene.face_normal[tri], direction[ray]


def test_the_wreck_hull_is_what_its_generator_writes(tmp_path):
    """The shipped OBJ is the generator's output; the hull is closed, every face's normal points out of the steel
    (positive volume), and its volume is the flared prism's less the hold's, by hand."""
    import trimesh

    spec = importlib.util.spec_from_file_location("wreck_cavity", ROOT / "scenes" / "assets" / "wreck_cavity.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    gen.write_obj(tmp_path / "wreck.obj")
    shipped = ROOT / "scenes" / "assets" / "wreck_cavity.obj"
    assert (tmp_path / "wreck.obj").read_text() == shipped.read_text()
    assert shipped.stat().st_size < 10_000
    mesh = trimesh.load(shipped, force="mesh")
    assert mesh.is_watertight and mesh.is_winding_consistent
    prism = gen.LENGTH_M * (gen.DECK_HALF_WIDTH_M + gen.BOTTOM_HALF_WIDTH_M) * gen.DECK_HEIGHT_M
    hold = (2 * gen.HATCH_HALF_SIZE_M) ** 2 * gen.HOLD_DEPTH_M
    assert mesh.volume == pytest.approx(prism - hold, rel=1e-9)


def test_wreck_cavity_puts_deck_hold_floor_and_seabed_under_the_beam():
    """One mesh object with step edges inside it: the lidar 2.5 m above the deck (z -17.8) at x = 1.5 m sees the
    deck, the hold's floor 1.3 m below it through the hatch (|x|, |y| < 0.6 m) and the seabed (z -20) beyond the
    deck edge (x > 2.25 m), all three under the beam of the first 3,000 pulses. The axis that crosses the near
    rim (x = 0.6 m at 2.5 m down, 19.8 deg) meets the floor 4.04 m away, the deck 2.66 m: a 1.38 m step."""
    names, dist, point, normal, _ = _axis_hits("wreck_cavity")
    deck = (names == "wreck") & np.isclose(point[:, 2], -17.8, atol=1e-4)
    floor = (names == "wreck") & np.isclose(point[:, 2], -19.1, atol=1e-4)
    seabed = names == "seabed"
    assert deck.sum() > 500 and floor.sum() > 100 and seabed.sum() > 100
    assert dist[deck].min() == pytest.approx(2.5, abs=1e-3)
    assert np.all(np.abs(point[floor, :2]) < 0.6 + 1e-4) and np.all(normal[floor, 2] > 0.999)
    assert dist[floor].min() == pytest.approx(3.8 / math.cos(math.atan(0.9 / 2.5)), abs=0.01)
    assert np.all(np.isclose(point[seabed, 2], -20.0, atol=1e-4)) and np.all(point[seabed, 0] > 2.25)
    # The rest are the hold's walls: the far one (x = -0.6, facing the lidar) only.
    walls = ~(deck | floor | seabed)
    assert np.allclose(point[walls, 0], -0.6, atol=1e-4) and np.all(normal[walls, 0] > 0.999)


def test_the_wreck_deck_overhangs_the_seabed():
    """Under the flared side, between the bottom's half-width (1.2 m) and the deck's (2.25 m), a ray going up from
    the seabed meets the hull's side 1.05 m up at x = 1.7 m (2.2 m x 0.5 / 1.05), and a ray coming down meets the
    deck, not the seabed."""
    from scanner_sim.rays.caster import RayCaster

    scene = build_scene(load_scene(FAILURES / "wreck_cavity.yaml"))
    caster = RayCaster.for_scene(scene)
    origins = np.array([[1.7, 3.0, -19.99], [1.7, 3.0, -10.0]]) - scene.local_origin
    ray, tri, dist = caster.first_hits(origins, np.array([[0.0, 0, 1], [0, 0, -1]]))
    assert list(ray) == [0, 1] and list(scene.face_object[tri]) == [1, 1]
    assert dist[0] == pytest.approx(2.2 * 0.5 / 1.05 - 0.01, abs=1e-4)  # from 1 cm above the seabed
    assert dist[1] == pytest.approx(7.8, abs=1e-4)
    assert scene.face_normal[tri[0], 2] < 0 < scene.face_normal[tri[0], 0]  # the side faces out and down


def test_quay_wall_sweeps_from_the_seabed_onto_the_wall():
    """The lidar 4 m above the mud and 2.5 m from the wall (x = 2.5): the axis meets the mud out to the corner,
    atan(2.5 / 4) = 32.0 deg off nadir, at up to that incidence, and the wall beyond it from 58.0 deg of incidence
    (just above the corner, 4.72 m away) to near normal (horizontal, 2.5 m)."""
    names, dist, point, normal, direction = _axis_hits("quay_wall")
    incidence = np.degrees(np.arccos(np.abs(np.sum(normal * direction, axis=1))))
    wall, mud = names == "quay_wall", names == "seabed"
    assert wall.sum() + mud.sum() == len(names) and wall.sum() > 300 and mud.sum() > 300
    assert np.allclose(point[wall, 0], 2.5, atol=1e-4) and np.allclose(point[mud, 2], -10.0, atol=1e-4)
    assert np.all(normal[wall] @ [-1.0, 0, 0] > 0.999)
    corner = math.degrees(math.atan(2.5 / 4.0))
    assert incidence[mud].max() == pytest.approx(corner, abs=0.5)
    assert incidence[wall].max() == pytest.approx(90 - corner, abs=0.5)
    assert incidence[wall].min() < 1.0 and dist[wall].min() == pytest.approx(2.5, abs=0.01)
    assert dist[wall].max() == pytest.approx(math.hypot(2.5, 4.0), abs=0.05)


def test_moored_mine_top_lies_at_the_blind_zone_edge():
    """The mine's top is 1.6-1.8 m from the lidar (1.70 m: sphere centre 2.0 m above the mud 4.1 m down, radius
    0.4 m), its flanks out to about 2.1 m; beside it the mud at 4.1 m / cos(angle off nadir)."""
    names, dist, point, normal, direction = _axis_hits("moored_mine_turbid")
    mine, mud = names == "moored_mine", names == "seabed"
    assert mine.sum() > 300 and mud.sum() > 300 and mine.sum() + mud.sum() == len(names)
    assert 1.6 <= dist[mine].min() <= 1.8
    assert dist[mine].min() == pytest.approx(1.70, abs=0.01)
    assert np.allclose(np.linalg.norm(point[mine] - [0, 0, -13.0], axis=1), 0.4, atol=0.01)  # the icosphere's facets
    assert np.allclose(dist[mud], 4.1 / -direction[mud, 2], atol=1e-3)


def test_failure_rows_print_every_level_and_leave_the_references_self_comparison_out():
    """The rows `scanner-sim tradeoff --failure-rows` prints: one per level and the converged reference, the
    reference's comparisons with itself a dash, auto's speed with its ratio to balanced's."""
    from scanner_sim.studies.tradeoff import failure_table_rows

    metrics = {"vs_truth": {k: 0.5 for s, k, _ in FAILURE_ROW if s == "vs_truth"},
               "vs_reference": {k: 0.25 for s, k, _ in FAILURE_ROW if s == "vs_reference"}}
    result = {"scene": "x", "levels": {"fast": {**metrics, "pulses_per_s": 3000.0},
                                       "balanced": {**metrics, "pulses_per_s": 2000.0},
                                       "auto": {**metrics, "pulses_per_s": 2500.0},
                                       "reference": {**metrics, "pulses_per_s": 500.0}},
              "reference_convergence": {**metrics, "pulses_per_s": 100.0, "subrays": 217}}
    rows = [[c.strip() for c in r.strip("|").split("|")] for r in failure_table_rows(result).splitlines()]
    assert [r[1] for r in rows] == ["fast", "balanced", "auto", "reference", "reference at 217"]
    assert rows[2][2] == "2,500 (×1.25)" and rows[0][2] == "3,000"
    assert rows[3][8:] == ["–"] * 6 and rows[4][8:] == ["0.2500"] * 4 + ["+0.2500", "0.25000"]
    assert re.fullmatch(r"0\.500", rows[3][3])
