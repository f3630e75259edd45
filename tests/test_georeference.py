"""Points take the truth of the echo the instrument ranged (muls' back-references), never another hit's or
another pulse's."""

import numpy as np
import pytest

from muls.peaks import Peaks
from muls.ranging import Ranging
from scanner_sim.config import parse_scene
from scanner_sim.rays.hits import Hits
from scanner_sim.survey.georeference import NO_OBJECT, NOISE_CLASS, LinesOfSight, georeference
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.world.scene import LABELS

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
                         time_s=np.array([0.0, 2e-4]), slot=np.array([10, 11]), leg=np.ones(2, np.uint16))
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
