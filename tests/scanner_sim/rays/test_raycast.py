"""Ray casting: closed-form planes, receiver shadowing, far-from-origin scenes, backends."""

import math
import sys

import numpy as np
import pytest

from muls.presets import mul2023
from scanner_sim.rays.beams import beam_pattern
from scanner_sim.rays.cast import CastScene, cast_beams
from scanner_sim.rays.caster import ray_caster
from scanner_sim.world.objects import frustum, panel_mesh
from scanner_sim.world.scene import LABELS, Part, Scene

GEOMETRY = mul2023().geometry
FLOAT32_RANGE_TOL_M = 2e-6  # float32 spacing near 10 m is 1e-6 m


def _cast(scene, *rays, **kw):
    return cast_beams(CastScene.build(scene), *rays, **kw)


def _plate(distance_m, tilt_rad, origin):
    """A 6 m plate whose centre is distance_m below ``origin``, normal tilted by tilt_rad about x."""
    n = (0.0, -math.sin(tilt_rad), math.cos(tilt_rad))
    v, f = panel_mesh(np.asarray(origin) + [0, 0, -distance_m], (6, 6), n, (1, 0, 0))
    return Part("plate", "panel", v, f, LABELS["panel"], 0.1)


def _nadir_pulse(origin, offset=GEOMETRY.offset_m):
    o = np.asarray(origin, float)[None, :]
    down = np.array([[0.0, 0.0, -1.0]])
    return o, down, np.array([[1.0, 0, 0]]), o + [offset, 0, 0], down


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (512345.678, 6123456.789, -35.0)])
@pytest.mark.parametrize("distance_m,tilt_deg", [(2.5, 0.0), (4.0, 30.0), (7.3, 60.0)])
def test_range_point_and_incidence_on_a_tilted_plane(origin, distance_m, tilt_deg):
    """Centre sub-ray of a nadir beam: range = D exactly, point = origin - D z, incidence = tilt, at the
    origin and in UTM-sized coordinates alike (the scene is shifted to a local origin before Embree)."""
    tilt = math.radians(tilt_deg)
    scene = Scene([_plate(distance_m, tilt, origin)])
    hits = _cast(scene, *_nadir_pulse(origin), beam_pattern(1), GEOMETRY)
    assert len(hits) == 1
    assert abs(hits.range_m[0] - distance_m) < FLOAT32_RANGE_TOL_M
    np.testing.assert_allclose(hits.point[0], np.asarray(origin) + [0, 0, -distance_m], atol=FLOAT32_RANGE_TOL_M)
    assert hits.incidence_rad[0] == pytest.approx(tilt, abs=1e-6)
    assert np.dot(hits.normal[0], [0, 0, -1]) < 0  # faces the incoming ray
    assert hits.label[0] == LABELS["panel"] and hits.reflectance[0] == 0.1


@pytest.mark.parametrize("tilt_deg", [0.0, 45.0])
def test_all_subrays_range_exactly_on_a_plane(tilt_deg):
    """Every sub-ray of a 91-ray beam: range equals the closed-form ray-plane distance."""
    tilt = math.radians(tilt_deg)
    origin = np.array([0.0, 0.0, 0.0])
    scene = Scene([_plate(5.0, tilt, origin)])
    hits = _cast(scene, *_nadir_pulse(origin), beam_pattern(91), GEOMETRY)
    assert len(hits) == 91
    n = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    # Recompute sub-ray origins/directions and the exact plane distance.
    from scanner_sim.rays.beams import subrays

    o, d = subrays(origin[None], np.array([[0, 0, -1.0]]), np.array([[1.0, 0, 0]]), beam_pattern(91),
                   0.5 * GEOMETRY.beam_diameter_m, 0.5 * GEOMETRY.beam_divergence_full_rad)
    exact = (np.dot(origin + [0, 0, -5.0], n) - o @ n) / (d @ n)
    np.testing.assert_allclose(hits.range_m, exact[hits.subray_index], atol=FLOAT32_RANGE_TOL_M)
    np.testing.assert_allclose(hits.incidence_rad, np.arccos(np.abs(d @ n))[hits.subray_index], atol=2e-6)


def test_far_scene_ranges_as_accurately_as_at_origin():
    """Many pulses scanning across a tilted plane: UTM-sized coordinates give the same ranges."""
    results = []
    for origin in ((0.0, 0.0, 0.0), (687654.321, 5432109.876, -60.0)):
        scene = Scene([_plate(4.0, math.radians(20), origin)])
        theta = np.linspace(-0.5, 0.5, 50)
        n = len(theta)
        bo = np.tile(origin, (n, 1))
        bd = np.c_[np.zeros(n), np.sin(theta), -np.cos(theta)]
        shaft = np.tile([1.0, 0, 0], (n, 1))
        hits = _cast(scene, bo, bd, shaft, bo + [GEOMETRY.offset_m, 0, 0], bd, beam_pattern(7), GEOMETRY)
        results.append(hits)
    a, b = results
    assert len(a) == len(b) == 350
    np.testing.assert_allclose(a.range_m, b.range_m, atol=FLOAT32_RANGE_TOL_M)
    assert np.array_equal(a.receiver_weight, b.receiver_weight)


def test_box_between_receiver_and_lit_point_zeroes_receiver_weight():
    """The beam still lights the seabed plate, but a box on the hit-to-aperture line hides it from the
    receiver: receiver weight 0 with the box, 1 without."""
    origin = np.zeros(3)
    plate = _plate(4.0, 0.0, origin)
    # Shadow ray from the hit (0, 0, -4) to the aperture (0.13, 0, 0); the box sits on it at z = -2,
    # x in [0.045, 0.085], clear of the beam (radius 0.009 m at 2 m).
    bv, bf = frustum(0.02, 0.02, 0.1, sections=16)
    box = Part("box", "mesh", bv + [0.065, 0.0, -2.05], bf, LABELS["debris"], 0.2)
    pulse = _nadir_pulse(origin)
    clear = _cast(Scene([plate]), *pulse, beam_pattern(1), GEOMETRY)
    blocked = _cast(Scene([plate, box]), *pulse, beam_pattern(1), GEOMETRY)
    assert clear.receiver_weight.tolist() == [1.0]
    assert len(blocked) == 1 and blocked.label[0] == LABELS["panel"]
    assert blocked.range_m[0] == pytest.approx(4.0, abs=FLOAT32_RANGE_TOL_M)
    assert blocked.receiver_weight.tolist() == [0.0]
    # Without shadow rays (fidelity 'fast') only the cone counts.
    fast = _cast(Scene([plate, box]), *pulse, beam_pattern(1), GEOMETRY, shadow_rays=False)
    assert fast.receiver_weight.tolist() == [1.0]


def test_blind_zone_hit_is_outside_the_fov_cone():
    origin = np.zeros(3)
    hits = _cast(Scene([_plate(1.0, 0.0, origin)]), *_nadir_pulse(origin), beam_pattern(19), GEOMETRY)
    assert len(hits) == 19 and hits.receiver_weight.sum() == 0.0
    assert hits.hit_fraction()[0] == pytest.approx(1.0)


def test_misses_have_no_rows_and_scan_order_is_kept():
    origin = np.zeros(3)
    scene = Scene([_plate(3.0, 0.0, origin)])
    theta = np.array([0.0, 1.4, -0.2, 1.5, 0.1])  # pulses 1 and 3 miss the 6 m plate
    n = len(theta)
    bo = np.zeros((n, 3))
    bd = np.c_[np.zeros(n), np.sin(theta), -np.cos(theta)]
    shaft = np.tile([1.0, 0, 0], (n, 1))
    hits = _cast(scene, bo, bd, shaft, bo + [0.13, 0, 0], bd, beam_pattern(7), GEOMETRY)
    assert sorted(set(hits.pulse_index.tolist())) == [0, 2, 4]
    assert np.all(np.diff(hits.pulse_index * 7 + hits.subray_index) > 0)
    assert np.allclose(hits.hit_fraction(), [1, 0, 1, 0, 1])


def test_numpy_backend_agrees_with_embree():
    rng = np.random.default_rng(0)
    bv, bf = frustum(0.5, 0.2, 0.4, sections=12)
    v = bv + [0.0, 0.0, -3.0]
    o = np.c_[rng.uniform(-0.6, 0.6, (200, 2)), np.zeros(200)].astype(np.float32)
    d = np.tile(np.float32([0, 0, -1]), (200, 1))
    a = ray_caster(v, bf, backend="embree").first_hits(o, d)
    b = ray_caster(v, bf, backend="numpy").first_hits(o, d)
    assert np.array_equal(a[0], b[0])
    np.testing.assert_allclose(a[2], b[2], atol=1e-5)


def test_explicit_embree_backend_is_loud_when_missing(monkeypatch):
    monkeypatch.setitem(sys.modules, "embreex", None)
    monkeypatch.setitem(sys.modules, "embreex.rtcore_scene", None)
    bv, bf = frustum(0.5, 0.2, 0.4)
    with pytest.raises(ImportError, match="embreex"):
        ray_caster(bv, bf, backend="embree")
    with pytest.warns(RuntimeWarning, match="embreex"):
        assert ray_caster(bv, bf, backend="auto").backend == "numpy"


def test_unknown_backend_lists_choices():
    with pytest.raises(ValueError, match="'auto', 'embree', 'numpy'"):
        ray_caster(np.zeros((3, 3)), np.array([[0, 1, 2]]), backend="optix")


def test_bvh_is_built_when_the_caster_is_made_not_by_the_first_chunks():
    """Root cause: embreex commits its scene (builds the BVH) inside the first query, with no lock, so the first
    chunks of a pass, running side by side on two threads, could both start building the same scene, and the
    build was timed as part of the pass (0.1 s of a cable_survey pass). The caster now builds it on creation."""
    bv, bf = frustum(0.5, 0.2, 0.4)
    caster = ray_caster(bv, bf, backend="embree")
    assert caster.committed
