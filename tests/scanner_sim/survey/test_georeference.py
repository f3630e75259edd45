"""Points take the truth of the echo the instrument ranged (muls' back-references), never another hit's or
another pulse's."""

from pathlib import Path

import numpy as np
import pytest

from muls.ranging.peaks import Peaks
from muls.ranging.returns import Ranging
from scanner_sim.config import load_scene, parse_scene
from scanner_sim.rays.hits import Hits
from scanner_sim.survey.georeference import NO_OBJECT, NOISE_CLASS, LinesOfSight, georeference
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.world.objects import frustum
from scanner_sim.world.scene import LABELS, Part, Scene, build_scene

STEP_M = 1.0
UPPER_Z, LIDAR_Z = -5.0, -1.0
ON_SURFACE_M = 0.25  # a point this close to one surface (and 0.75 m from the other) ranged that surface


def _panel(name, centre, size, label, material="black_painted_aluminium"):
    return {"type": "panel", "name": name, "center_m": centre, "size_m": size, "normal": [0, 0, 1],
            "label": label, "material": material}


def _step_scene(pulses=4000, lower_material="carbonate_sand"):
    """A 1 m step under a static lidar: an upper panel over x < 0, 4 m below the lidar, and a lower one 1 m
    deeper under everything."""
    return parse_scene({
        "format_version": 1, "name": "step", "water": "pool",
        "objects": [_panel("upper", [-2.0, 0.0, UPPER_Z], [4.0, 4.0], "panel"),
                    _panel("lower", [0.0, 0.0, UPPER_Z - STEP_M], [8.0, 8.0], "debris", lower_material)],
        "platform": {"mode": "static", "position_m": [0.0, 0.0, LIDAR_Z]},
        "scanner": {"mode": "oscillating", "sector_deg": 16, "scan_rate_hz": 5},
        "survey": {"max_pulses": pulses, "fidelity": "balanced", "seed": 3},
    })


@pytest.mark.parametrize("lower_material", ["carbonate_sand", "black_painted_aluminium"])
def test_regression_step_edge_points_take_the_class_of_the_surface_they_ranged(lower_material):
    """Root cause: georeferencing guessed the hit behind each return ("the strongest hit of the pulse within
    half a pulse length", 1.1 m), so at a 1 m step the upper, nearer and stronger hit won, and points on the
    lower surface took the upper object's class and id (1,660 of 1,987 at a 1 m step). muls now says which
    echo dominates each return it ranged, and the point takes that echo's hit."""
    setup = PassSetup.build(_step_scene(lower_material=lower_material))
    points = setup.simulate_chunk(next(setup.slot_chunks())).points
    z = points.xyz[:, 2]
    upper = np.abs(z - UPPER_Z) < ON_SURFACE_M
    lower = np.abs(z - (UPPER_Z - STEP_M)) < ON_SURFACE_M
    ids = {o.name: o.object_id for o in setup.scene.objects}
    edge = np.abs(points.xyz[:, 0]) < 0.1
    assert np.count_nonzero(lower & edge) > 20 and np.count_nonzero(upper & edge) > 20  # the edge is sampled
    assert np.all(points.classification[upper] == LABELS["panel"])
    assert np.all(points.object_id[upper] == ids["upper"])
    assert np.all(points.classification[lower] == LABELS["debris"])
    assert np.all(points.object_id[lower] == ids["lower"])


def test_regression_false_alarms_carry_no_other_pulses_truth():
    """Root cause: a return that no hit of its pulse explained was matched to hit index 0 of the chunk,
    another pulse's hit, and a chunk with no hits at all crashed with an IndexError (reference fidelity,
    turbid water, the target off to the side). A return no echo explains is now noise: class 7, object -1,
    no incidence, and the truth along its own line of sight, which meets nothing here."""
    config = parse_scene({
        "format_version": 1, "name": "off_to_the_side", "water": "turbid_harbor",
        "objects": [_panel("far_off", [30.0, 0.0, -6.0], [2.0, 2.0], "panel")],
        "platform": {"mode": "static", "position_m": [0.0, 0.0, -1.0]},
        "scanner": {"mode": "static", "aim_deg": 0},
        "survey": {"max_pulses": 20000, "fidelity": "reference", "chunk_pulses": 5000},
    })
    setup = PassSetup.build(config, PassOptions())
    noise = []
    for slots in setup.slot_chunks():
        chunk = setup.simulate_chunk(slots)
        assert len(chunk.points) + len(chunk.dropouts) >= slots.size
        noise.append(chunk.points)
    points = noise[0].concatenate(noise)
    assert np.all(points.classification == NOISE_CLASS)
    assert np.all(points.object_id == NO_OBJECT)
    assert np.all(np.isnan(points.true_range_m)) and np.all(np.isnan(points.incidence_deg))


@pytest.mark.parametrize("chunk", [777, 4000])
def test_back_references_do_not_depend_on_the_chunking(chunk):
    """The echo a point is attributed to is a property of the pulse, whatever chunk it is simulated in."""
    whole = PassSetup.build(_step_scene(pulses=1500))
    split = PassSetup.build(_step_scene(pulses=1500), PassOptions(chunk_pulses=chunk))
    a = whole.simulate_chunk(np.concatenate(list(whole.slot_chunks()))).points
    b = a.concatenate([split.simulate_chunk(s).points for s in split.slot_chunks()])
    for name in ("classification", "object_id", "xyz", "true_range_m", "intensity"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_regression_a_second_return_is_judged_against_the_second_surface():
    """Root cause: true_range_m was the first truth surface along the point's line of sight, so a correct
    second return (the lower panel behind an edge) read as an error of the step's height (2 m here). The
    truth is now the surface of the echo the instrument ranged, along the same line."""
    upper_m, step_m = 10.0, 2.0  # far enough that the low-gain channel sees both echoes unclipped
    config = parse_scene({
        "format_version": 1, "name": "edge", "water": "pool",
        "objects": [_panel("upper", [-2.0, 0.0, LIDAR_Z - upper_m], [4.0, 4.0], "panel"),
                    _panel("lower", [0.0, 0.0, LIDAR_Z - upper_m - step_m], [8.0, 8.0], "debris")],
        "platform": {"mode": "static", "position_m": [0.0, 0.0, LIDAR_Z]},  # the beam straddles the edge
        "scanner": {"mode": "static", "aim_deg": 0},
        "survey": {"max_pulses": 300, "fidelity": "balanced", "seed": 5},
    })
    setup = PassSetup.build(config)
    points = setup.simulate_chunk(next(setup.slot_chunks())).points
    second = points.return_number == 2
    assert np.count_nonzero(second) > 250  # both surfaces ranged on (almost) every pulse
    assert np.all(points.classification[second] == LABELS["debris"])
    assert np.all(np.abs(points.true_range_m[second] - (upper_m + step_m)) < 0.02)
    assert np.median(np.abs(points.range_error_m[second])) < 0.1


def _hits(pulse_index, range_m, object_id):
    """Hits of a chunk of 2 pulses (one row per hit), every attribute set."""
    n = len(pulse_index)
    f = np.ones(n)
    return Hits(pulse_index=np.asarray(pulse_index, np.int64), subray_index=np.zeros(n, np.int32),
                range_m=np.asarray(range_m, float), point=np.zeros((n, 3)), normal=np.tile([0.0, 0.0, 1.0], (n, 1)),
                incidence_rad=0 * f, reflectance=0.1 * f, label=np.full(n, LABELS["panel"], np.int16),
                object_id=np.asarray(object_id, np.int32), surface_id=np.asarray(object_id, np.int32), receiver_weight=f,
                weight=f, echo_range_m=f,
                n_pulses=2, n_subrays=1)


@pytest.mark.parametrize("hits", [_hits([], [], []), _hits([1], [4.0], [3])], ids=["no hits", "another pulse's hit"])
def test_a_false_alarm_takes_no_hit_of_another_pulse(hits):
    """Pulse 0 has a return that no echo explains (echo_index -1); the chunk has no hit at all, or one hit
    of pulse 1. The point is noise with no object, no incidence and the truth of its own line of sight (none
    here), whatever the other pulses met."""
    returns = Peaks(pulse=np.array([0]), channel=np.array([3]), time_s=np.array([3e-8]), range_m=np.array([3.3]),
                    amplitude_lsb=np.array([9.0]), snr=np.array([5.5]), saturated=np.array([False]),
                    peak_power_w=np.array([1e-7]), echo_index=np.array([-1]))
    ranging = Ranging(returns, np.array([1], np.uint8), np.array([1], np.uint8), returns,
                      np.array([-1, 2], np.int8), np.zeros(2))
    sight = LinesOfSight(origin_m=np.zeros((2, 3)), direction=np.tile([0.0, 0.0, -1.0], (2, 1)),
                         true_range_m=np.full(2, np.nan), first_surface=np.full(2, -1), scan_angle_deg=np.zeros(2),
                         time_s=np.array([0.0, 2e-4]), slot=np.array([10, 11]), leg=np.ones(2, np.uint16),
                         platform_m=np.zeros((2, 3)), attitude_rad=np.zeros((2, 3)), true_origin_m=np.zeros((2, 3)),
                         true_direction=np.tile([0.0, 0.0, -1.0], (2, 1)), axis_range_m=np.full(2, np.nan))
    points = georeference(ranging, hits, sight)
    assert len(points) == 1 and points.pulse_index[0] == 10
    assert points.classification[0] == NOISE_CLASS and points.object_id[0] == NO_OBJECT
    assert np.isnan(points.true_range_m[0]) and np.isnan(points.incidence_deg[0])
    np.testing.assert_allclose(points.xyz[0], [0.0, 0.0, -3.3])


def test_truth_without_navigation_noise_is_what_a_cast_along_each_line_finds():
    """Without navigation noise the truth comes from the beam cast's axis sub-ray instead of a cast of its own:
    the same ranges and surfaces as casting along each estimated line (here across the step's edge)."""
    setup = PassSetup.build(_step_scene(pulses=3000), PassOptions(progress=False))
    assert not setup.trajectory.has_navigation_noise
    slots = next(setup.slot_chunks())
    sight = setup.cast_chunk(slots).sight
    ray, tri, dist = setup.target.caster.first_hits((sight.origin_m - setup.scene.local_origin).astype(np.float32),
                                             sight.direction.astype(np.float32))
    assert ray.size == slots.size  # every line meets a panel
    assert np.array_equal(sight.true_range_m[ray], dist.astype(float))
    assert np.array_equal(sight.first_surface[ray], setup.scene.face_surface[tri])
    assert len(np.unique(sight.first_surface)) == 2  # both panels seen


# -- a step inside one mesh -------------------------------------------------------------------------------------
MESH_STEP_M = 1.3  # a hatch rim's height
MESH_LOWER_Z = UPPER_Z - MESH_STEP_M


def _quads_obj(path, quads):
    """Write the quads (each 4 corners [m], wound so the normal faces up or toward -x) as an OBJ of 2 triangles
    each; returns the path as a string."""
    corners = [c for q in quads for c in q]
    faces = [(4 * i + 1, 4 * i + 2, 4 * i + 3) for i in range(len(quads))] + [
        (4 * i + 1, 4 * i + 3, 4 * i + 4) for i in range(len(quads))]
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in corners) + "".join(f"f {a} {b} {c}\n" for a, b, c in faces))
    return str(path)


def _mesh_step_scene(folder, objects, fidelity="balanced", pulses=1500, noise=False):
    """The 1.3 m step of an extruded profile (upper level over x < 0, a vertical riser at x = 0, the lower level
    over x > 0, all 8 m along y) under a static lidar scanning across the rim; ``objects``: how many mesh objects
    carry its 3 quads, 1 (one mesh) or 2 (upper level and riser, then the lower level)."""
    upper = [(-4, -4, UPPER_Z), (0, -4, UPPER_Z), (0, 4, UPPER_Z), (-4, 4, UPPER_Z)]
    riser = [(0, -4, UPPER_Z), (0, 4, UPPER_Z), (0, 4, MESH_LOWER_Z), (0, -4, MESH_LOWER_Z)]
    lower = [(0, -4, MESH_LOWER_Z), (4, -4, MESH_LOWER_Z), (4, 4, MESH_LOWER_Z), (0, 4, MESH_LOWER_Z)]
    groups = [[upper, riser, lower]] if objects == 1 else [[upper, riser], [lower]]
    platform = {"mode": "static", "position_m": [0.0, 0.0, LIDAR_Z]}
    if noise:
        platform["navigation_noise"] = {"position_sigma_m": 0.05, "depth_sigma_m": 0.02, "attitude_sigma_deg": 0.2,
                                        "seed": 4}
    return parse_scene({
        "format_version": 1, "name": "mesh_step", "water": "pool",
        "objects": [{"type": "mesh", "name": f"part{i}", "file": _quads_obj(folder / f"part{i}.obj", quads),
                     "translate_m": [0.0, 0.0, 0.0], "material": "carbonate_sand", "label": "panel"}
                    for i, quads in enumerate(groups)],
        "platform": platform,
        "scanner": {"mode": "oscillating", "sector_deg": 16, "scan_rate_hz": 5},
        "survey": {"max_pulses": pulses, "fidelity": fidelity, "seed": 3},
    })


def test_a_steps_levels_are_two_surfaces_of_one_mesh_and_a_cylinders_side_is_one(tmp_path):
    """The surfaces a return's truth is judged on: the step's upper level, riser and lower level are three (their
    normals 90 deg apart), a 32-section cylinder's side is one and its caps two more, the seabed's height field
    (however rough) one."""
    step = build_scene(_mesh_step_scene(tmp_path, objects=1))
    z = step.vertices[step.faces].mean(axis=1)[:, 2]
    levels = [step.face_surface[np.isclose(z, UPPER_Z)], step.face_surface[np.isclose(z, MESH_LOWER_Z)]]
    assert [np.unique(s).size for s in levels] == [1, 1] and levels[0][0] != levels[1][0]
    assert np.unique(step.face_surface).size == 3
    v, f = frustum(0.25, 0.25, 1.0, sections=32)
    cylinder = Scene([Part("mine", "cylinder_mine", v, f, LABELS["panel"], 0.1)])
    side = np.abs(cylinder.face_normal[:, 2]) < 1e-9
    assert np.unique(cylinder.face_surface[side]).size == 1 and np.unique(cylinder.face_surface).size == 3
    rough = build_scene(parse_scene({
        "format_version": 1, "name": "rough", "water": "pool",
        "seabed": {"size_m": [4, 4], "resolution_m": 0.05, "depth_m": 6, "relief": {"rms_m": 0.3, "wavelength_m": 2}},
        "platform": {"mode": "static", "position_m": [0.0, 0.0, LIDAR_Z]}, "survey": {"max_pulses": 1}}))
    assert np.unique(rough.face_surface).size == 1


@pytest.mark.parametrize("fidelity", ["fast", "balanced", "auto", "reference"])
def test_truth_on_one_mesh_step_is_the_surface_ranged(fidelity, tmp_path):
    """Root cause: the truth of a return was the first surface along its line of sight whenever that surface
    belonged to the object the return's echo came from. A step inside one mesh (a hatch rim, a deck edge) is one
    object: where the beam's axis passes the rim onto the lower level while the sub-rays still on the upper level
    make a return, that return was judged against the lower level, a range error of -1.3 m (11 to 18 of the
    about 760 upper-level points here, at every level), where the same geometry as two objects read a few cm.
    Each hit now carries its triangle's smooth surface (Scene.face_surface, faces joined across edges under
    60 deg), and a return is judged on the first surface along its line only when that is its own surface, else
    on its facet's plane.

    The expected truth is computed from the geometry built: each point near a level (by its height) lies on that
    level's plane, where its own line of sight (the scanner's beam at the pulse's pose) crosses it."""
    setup = PassSetup.build(_mesh_step_scene(tmp_path, objects=1, fidelity=fidelity), PassOptions(progress=False))
    points = setup.simulate_chunk(next(setup.slot_chunks())).points
    origin, direction = setup.scanner.beam_rays(setup.trajectory.poses(points.gps_time_s, estimated=True))
    z = points.xyz[:, 2]
    for level_z in (UPPER_Z, MESH_LOWER_Z):
        on = np.abs(z - level_z) < ON_SURFACE_M
        expected = (level_z - origin[on, 2]) / direction[on, 2]  # where the line crosses the level's plane
        np.testing.assert_allclose(points.true_range_m[on], expected, atol=1e-3)
    # The case arises: upper-level returns whose line meets the upper level's plane beyond the rim (x > 0), so
    # that the first surface along it is the lower level.
    upper = np.abs(z - UPPER_Z) < ON_SURFACE_M
    t_upper = (UPPER_Z - origin[upper, 2]) / direction[upper, 2]
    assert np.count_nonzero(origin[upper, 0] + t_upper * direction[upper, 0] > 0.0) >= 5


def test_a_step_as_one_mesh_or_two_objects_gives_the_same_errors(tmp_path):
    """A symmetry: how a geometry is split into objects says nothing about where its surfaces are, so the same
    six triangles as one mesh or as two objects give every point the same truth and error, with navigation noise
    (the truth cast along the estimated line) as without. Before each hit carried its surface, the one mesh's
    returns across the rim read 1.3 m off (52 of 2,000 points with this noise, where the two objects read none)."""
    results = []
    for objects in (1, 2):
        (tmp_path / str(objects)).mkdir()
        setup = PassSetup.build(_mesh_step_scene(tmp_path / str(objects), objects, pulses=2000, noise=True),
                                PassOptions(progress=False))
        assert setup.trajectory.has_navigation_noise
        results.append(setup.simulate_chunk(next(setup.slot_chunks())).points)
    one, two = results
    np.testing.assert_array_equal(one.xyz, two.xyz)  # the same returns, ranged alike
    np.testing.assert_allclose(one.true_range_m, two.true_range_m, atol=1e-5)
    np.testing.assert_allclose(one.range_error_m, two.range_error_m, atol=1e-5)
    for stat in (np.median, lambda e: np.percentile(e, 95)):
        assert stat(np.abs(one.range_error_m)) == pytest.approx(stat(np.abs(two.range_error_m)), abs=1e-5)


def test_shipped_step_edges_as_one_mesh_reads_as_its_five_panels():
    """scenes/failures/step_edges_one_mesh.yaml is step_edges' five panels in one mesh object. Before the truth was
    judged by surface, 29 of its 2,001 points took the first panel of the mesh along their line, up to 2 m off
    (202 to 276 of 20,000 at the four levels); every point now has the truth it has in step_edges."""
    failures = Path(__file__).resolve().parents[3] / "scenes" / "failures"
    points = []
    for name in ("step_edges", "step_edges_one_mesh"):
        setup = PassSetup.build(load_scene(failures / f"{name}.yaml"), PassOptions(progress=False))
        points.append(setup.simulate_chunk(np.concatenate(list(setup.slot_chunks()))).points)
    panels, mesh = points
    assert len(panels) > 1900 and np.array_equal(panels.xyz, mesh.xyz)
    np.testing.assert_array_equal(panels.true_range_m, mesh.true_range_m)
