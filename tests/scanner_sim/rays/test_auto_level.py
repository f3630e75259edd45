"""The ``auto`` level: balanced's hits, the seabed's found on its height field where that is proven exact, and
each simple footprint's sub-ray echoes replaced by the two-point Gauss quadrature of their delays
(scanner_sim.rays.collapse), the rest kept."""

from pathlib import Path

import numpy as np
import pytest
from conftest import cold_compiled_kernels, string_formatting

from muls.presets import mul2023
from scanner_sim.config import load_scene
from scanner_sim.fidelity import FIDELITY_LEVELS
from scanner_sim.rays import auto as auto_level
from scanner_sim.rays.auto import cast_auto
from scanner_sim.rays.beams import beam_pattern
from scanner_sim.rays.cast import CastScene, cast_beams
from scanner_sim.rays.caster import RayCaster
from scanner_sim.rays.collapse import COLLAPSE_SPAN_M, simple_pulses, two_point_rule
from scanner_sim.rays.echoes import echo_energy
from scanner_sim.rays.hits import HIT_FIELDS, Hits
from scanner_sim.rays.seabed_grid import seabed_grid
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.world.objects import panel_mesh, tube
from scanner_sim.world.scene import LABELS, Part, Scene
from scanner_sim.world.terrain import HeightField

FAILURES = Path(__file__).resolve().parents[3] / "scenes" / "failures"
M = 7


def _hits(pulse, range_m, object_id, n_pulses):
    n = len(pulse)
    f = np.ones(n)
    sub = np.concatenate([np.arange(c) for c in np.bincount(pulse, minlength=n_pulses)]).astype(np.int32)
    return Hits(pulse_index=np.asarray(pulse, np.int64), subray_index=sub, range_m=np.asarray(range_m, float),
                point=np.zeros((n, 3)), normal=np.tile([0.0, 0.0, 1.0], (n, 1)), incidence_rad=0 * f,
                reflectance=0.1 * f, label=np.ones(n, np.int16), object_id=np.asarray(object_id, np.int32),
                surface_id=np.asarray(object_id, np.int32), receiver_weight=f, weight=f / M,
                echo_range_m=np.asarray(range_m, float), n_pulses=n_pulses, n_subrays=M)


def test_a_pulse_is_simple_only_when_all_its_sub_rays_meet_one_object_within_the_spread():
    """Four pulses of seven sub-rays: 0 all on object 1 within 1 cm (simple); 1 one sub-ray on object 2; 2 a range
    spread just over the limit; 3 one sub-ray missing."""
    flat = list(5.0 + np.linspace(0, 0.01, M))
    pulse = [0] * M + [1] * M + [2] * M + [3] * (M - 1)
    rng = flat + flat + list(5.0 + np.linspace(0, 1.01 * COLLAPSE_SPAN_M, M)) + flat[:-1]
    obj = [1] * M + [1] * (M - 1) + [2] + [1] * (2 * M - 1)
    np.testing.assert_array_equal(simple_pulses(_hits(pulse, rng, obj, 4)), [True, False, False, False])


def test_the_two_point_rule_keeps_energy_mean_variance_and_skewness():
    """The two nodes and shares reproduce the distribution's moments of order 0 to 3 (sums over the samples
    here), not the fourth: a Gauss rule of two points is exact to degree 3."""
    rng = np.random.default_rng(4)
    energy, delay = rng.random((6, 19)), 30.0 + 0.05 * rng.random((6, 19))
    energy[0, 1:] = 0.0  # one echo alone: both nodes on it
    nodes, share = two_point_rule(energy, delay)
    p = energy / energy.sum(axis=1, keepdims=True)
    mean = np.sum(p * delay, axis=1)
    scale = 0.05  # the delays' spread: compare the moments in its units
    for order in range(4):
        np.testing.assert_allclose(np.sum(share * ((nodes - mean[:, None]) / scale) ** order, axis=1),
                                   np.sum(p * ((delay - mean[:, None]) / scale) ** order, axis=1), rtol=1e-7,
                                   atol=1e-9)
    fourth = np.sum(p * (delay - mean[:, None]) ** 4, axis=1)[1:]
    assert np.all(np.abs(np.sum(share * (nodes - mean[:, None]) ** 4, axis=1)[1:] - fourth) > 1e-3 * fourth)
    np.testing.assert_allclose(nodes[0], delay[0, 0])


def _casts(scene, pulses):
    """(auto's hits, balanced's hits) of the scene's first pulses."""
    setup = PassSetup.build(load_scene(str(FAILURES / f"{scene}.yaml")), PassOptions(max_pulses=pulses),
                            level=FIDELITY_LEVELS["auto"])
    slots = np.concatenate(list(setup.slot_chunks()))
    rays = setup.scanner.world_rays(setup.trajectory.poses(slots / setup.scanner.pulse_rate_hz))
    geometry = setup.model.instrument.geometry
    return (cast_auto(setup.target, *rays, setup.pattern, geometry),
            cast_beams(setup.target, *rays, setup.pattern, geometry))


def _energy(hits):
    return echo_energy(hits.weight, hits.reflectance, np.cos(hits.incidence_rad), hits.receiver_weight)


@pytest.mark.parametrize("scene", ["clear_water", "step_edges"])
def test_auto_keeps_each_pulses_echo_energy_and_mean_delay_and_the_axis_hit(scene):
    """Per pulse, auto's echoes bring the same energy at the same energy-weighted mean echo range and variance as
    balanced's sub-ray echoes, the beam share that hit is the same, and the axis hit (the truth and coverage
    footprint read it) is the one cast. Square on to a plate every pulse is simple (three rows); across the step
    edges the pulses that straddle an edge keep balanced's rows unchanged."""
    auto, balanced = _casts(scene, 300)
    n = balanced.n_pulses

    def per_pulse(hits, values):
        return np.bincount(hits.pulse_index, weights=values, minlength=n)

    for hits in (auto, balanced):
        assert np.all(np.diff(hits.pulse_index) >= 0)
    ea, eb = per_pulse(auto, _energy(auto)), per_pulse(balanced, _energy(balanced))
    np.testing.assert_allclose(ea, eb, rtol=1e-9)
    lit = eb > 0
    mean_a = per_pulse(auto, _energy(auto) * auto.echo_range_m)[lit] / ea[lit]
    mean_b = per_pulse(balanced, _energy(balanced) * balanced.echo_range_m)[lit] / eb[lit]
    np.testing.assert_allclose(mean_a, mean_b, rtol=0, atol=1e-6)  # return legs are float32: 0.5 um at 9 m

    def variance(hits, mean, energy):
        full_mean = np.zeros(n)
        full_mean[lit] = mean
        return per_pulse(hits, _energy(hits) * (hits.echo_range_m - full_mean[hits.pulse_index]) ** 2)[lit] / energy

    np.testing.assert_allclose(variance(auto, mean_a, ea[lit]), variance(balanced, mean_b, eb[lit]), rtol=1e-2,
                               atol=1e-10)
    np.testing.assert_allclose(per_pulse(auto, auto.weight), per_pulse(balanced, balanced.weight), rtol=1e-9)
    axis_a, axis_b = auto.subray_index == 0, balanced.subray_index == 0
    np.testing.assert_array_equal(auto.pulse_index[axis_a], balanced.pulse_index[axis_b])
    np.testing.assert_array_equal(auto.range_m[axis_a], balanced.range_m[axis_b])
    rows = np.bincount(auto.pulse_index, minlength=n)
    full = np.bincount(balanced.pulse_index, minlength=n)
    if scene == "clear_water":
        assert np.all(rows == 3)
    else:
        three = rows == 3
        assert three.any() and not three.all()
        kept = ~three
        np.testing.assert_array_equal(rows[kept], full[kept])
        mine, theirs = np.isin(auto.pulse_index, np.flatnonzero(kept)), np.isin(balanced.pulse_index, np.flatnonzero(kept))
        np.testing.assert_array_equal(auto.range_m[mine], balanced.range_m[theirs])
        np.testing.assert_array_equal(auto.weight[mine], balanced.weight[theirs])


# -- analytic seabed hits: Embree is the oracle -------------------------------------------------------------------

GEOMETRY = mul2023().geometry


class CountingCaster:
    """A RayCaster that counts the rays Embree is asked about."""

    def __init__(self, caster):
        self._caster, self.rays, self.shadow_rays = caster, 0, 0

    def first_hits_raw(self, origins, directions):
        self.rays += len(origins)
        return self._caster.first_hits_raw(origins, directions)

    def occluded_raw(self, origins, directions, lengths):
        self.shadow_rays += int(np.count_nonzero(np.asarray(lengths) > 0))
        return self._caster.occluded_raw(origins, directions, lengths)

    def __getattr__(self, name):
        return getattr(self._caster, name)


def _field(ridges=False):
    x = np.arange(101) * 0.05
    gx, gy = np.meshgrid(x, x)
    heights = -20.0 + 0.15 * gx + 0.08 * np.sin(7.0 * gx) * np.cos(5.0 * gy) + 0.02 * np.sin(23.0 * gy)
    if ridges:  # ridges 25 cm high across x and y, their flanks up to about 4 steep
        for c in (1.6, 2.2, 2.8, 3.4):
            heights += 0.25 * (np.exp(-((gx - c) / 0.05) ** 2) + np.exp(-((gy - c - 0.3) / 0.05) ** 2))
    return HeightField(100.0, 200.0, 0.05, heights)


def _seabed_scene(objects=(), ridges=False):
    """A 5 m x 5 m sloped, rippled height field (5 cm nodes; slopes up to about 1), with ``objects`` (name, (v, f))."""
    hf = _field(ridges)
    v, f = hf.mesh()
    parts = [Part("seabed", "seabed", v, f, LABELS["seabed"], 0.2)]
    parts += [Part(name, "panel", ov, of, LABELS["panel"], 0.5) for name, (ov, of) in objects]
    return Scene(parts, heightfield=hf)


def _plates_and_cable_scene(seed, ridges=False):
    """:func:`_seabed_scene` with 60 small plates 20-40 cm over its middle (placed by ``seed``) and a cable lying on it."""
    rng = np.random.default_rng(seed)
    hf, plates = _field(ridges), []
    for i in range(60):
        x, y = 101.9 + 1.2 * rng.random(), 201.9 + 1.2 * rng.random()
        z = float(hf.height(x, y)) + 0.2 + 0.2 * rng.random()
        plates.append((f"plate{i}", panel_mesh([x, y, z], (0.04 + 0.1 * rng.random(), 0.03), (0, 0, 1), (0, 1, 0))))
    line = np.c_[np.linspace(100.2, 104.8, 90), np.full(90, 202.5), np.zeros(90)]
    line[:, 2] = hf.height(line[:, 0], line[:, 1]) + 0.03
    return _seabed_scene(plates + [("cable", tube(line, 0.04))], ridges=ridges)


def _pulses(n, seed, spread_deg=40.0):
    """n beams from 1-2 m over the field's middle, up to ``spread_deg`` off nadir; receiver 13 cm aside, parallel."""
    rng = np.random.default_rng(seed)
    origin = np.c_[101.7 + 1.6 * rng.random(n), 201.7 + 1.6 * rng.random(n), -18.0 + 0.3 * rng.random(n)]
    tilt, azimuth = np.radians(spread_deg) * np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
    direction = np.c_[np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), -np.cos(tilt)]
    shaft = np.tile([1.0, 0.0, 0.0], (n, 1))
    return origin, direction, shaft, origin + [0.0, GEOMETRY.offset_m, 0.0], direction


def _both(scene, pulses, shadow_rays=True):
    caster = CountingCaster(RayCaster.for_scene(scene))
    pattern = beam_pattern(19)
    grid = seabed_grid(scene, caster)
    proven = auto_level.cast_seabed_analytic(CastScene(scene, caster, grid), *pulses, pattern, GEOMETRY, shadow_rays)
    embree = cast_beams(CastScene(scene, caster._caster, grid), *pulses, pattern, GEOMETRY, shadow_rays,
                        prove_shadows=False)
    return proven, embree, caster


def _assert_same_hits(proven, embree):
    np.testing.assert_array_equal(proven.pulse_index, embree.pulse_index)
    np.testing.assert_array_equal(proven.subray_index, embree.subray_index)
    np.testing.assert_array_equal(proven.object_id, embree.object_id)
    # Float32 distances along the ray (Embree's and the ray-plane intersection): a few float32 steps at 3 m, which
    # move the share of the aperture that sees a hit by a few millionths where the hit lies at its field's edge.
    np.testing.assert_array_equal(proven.receiver_weight > 0, embree.receiver_weight > 0)
    np.testing.assert_allclose(proven.receiver_weight, embree.receiver_weight, rtol=0, atol=1e-5)
    np.testing.assert_allclose(proven.range_m, embree.range_m, rtol=0, atol=2e-5)
    np.testing.assert_allclose(proven.point, embree.point, rtol=0, atol=2e-5)
    # The same facet: a hit within float32 rounding of a shared edge may name either neighbour.
    other_facet = np.any(proven.normal != embree.normal, axis=1)
    assert other_facet.sum() <= max(2, 1e-4 * len(embree))


def test_analytic_seabed_hits_are_embrees_hits_with_far_fewer_rays():
    """On a sloped, rippled height field with nothing else, every sub-ray hit, its facet, range, point and receiver
    check equal Embree's for the same rays (to float32 precision), while Embree casts the axes and a few pulses'
    sub-rays and no shadow rays for the proven pulses."""
    scene = _seabed_scene()
    pulses = _pulses(3000, seed=1)
    proven, embree, caster = _both(scene, pulses)
    assert len(embree) > 0.99 * 3000 * 19  # a sub-ray or two may leave the field
    _assert_same_hits(proven, embree)
    assert caster.rays < 0.25 * 3000 * 19, caster.rays  # the axes plus the unproven pulses' sub-rays
    assert caster.shadow_rays < 0.25 * 3000 * 19, caster.shadow_rays


def test_analytic_hits_leave_blocked_and_shadowed_pulses_to_embree():
    """Small plates 20-40 cm over the seabed and a cable lying on it cut some footprints and some paths to the
    receiver: hits on them, hits the plates hide from the receiver and hits beside them all equal Embree's."""
    scene = _plates_and_cable_scene(seed=3)
    pulses = _pulses(4000, seed=2)
    proven, embree, caster = _both(scene, pulses)
    on_objects = embree.object_id > 0
    assert on_objects.sum() > 200  # the footprints the plates and the cable cut
    seen_by_cone = _seen_without_shadow_rays(scene, pulses)
    shadowed = (embree.receiver_weight == 0) & (seen_by_cone > 0)
    assert shadowed.sum() > 20  # hits an object hides from the receiver
    _assert_same_hits(proven, embree)
    assert caster.rays < 0.5 * 4000 * 19


def test_analytic_hits_leave_pulses_the_relief_can_hide_to_embree():
    """Steep ridges and beams up to 60 degrees off nadir: footprints the ridges hide in part, and paths to the
    receiver they cut, need the seabed's own occlusion; every hit and receiver check equals Embree's."""
    scene = _seabed_scene(ridges=True)
    pulses = _pulses(4000, seed=4, spread_deg=60.0)
    proven, embree, caster = _both(scene, pulses)
    shadowed = (embree.receiver_weight == 0) & (_seen_without_shadow_rays(scene, pulses) > 0)
    assert shadowed.sum() > 20  # hits a ridge hides from the receiver
    _assert_same_hits(proven, embree)
    assert caster.rays < 0.6 * 4000 * 19


def _seen_without_shadow_rays(scene, pulses):
    hits = cast_beams(CastScene.build(scene), *pulses, beam_pattern(19), GEOMETRY, shadow_rays=False)
    return hits.receiver_weight


def test_a_scene_without_a_height_field_is_cast_as_balanced_casts_it():
    scene = Scene([Part("plate", "panel", *panel_mesh([0, 0, -5.0], (4.0, 4.0), (0, 0, 1), (0, 1, 0)),
                        LABELS["panel"], 0.3)])
    n = 200
    origin = np.zeros((n, 3))
    direction = np.tile([0.0, 0.0, -1.0], (n, 1))
    pulses = (origin, direction, np.tile([1.0, 0, 0], (n, 1)), origin + [0, GEOMETRY.offset_m, 0], direction)
    assert seabed_grid(scene, RayCaster.for_scene(scene)) is None
    proven, embree, _ = _both(scene, pulses)
    for f in HIT_FIELDS:
        np.testing.assert_array_equal(getattr(proven, f.name), getattr(embree, f.name))


def test_auto_decides_and_counts_what_it_proves_on_a_height_field():
    """The counts the trade-off reports: on the plain rippled field most pulses are proven and collapsed, every
    axis meets the seabed, and the scene has its proof grid (no fall-back reason)."""
    scene = _seabed_scene()
    caster = RayCaster.for_scene(scene)
    d = auto_level.auto_decisions(CastScene(scene, caster, seabed_grid(scene, caster)), *_pulses(500, seed=5),
                                  beam_pattern(19), GEOMETRY)
    assert d["pulses"] == 500 and d["no_grid"] is None and d["no_hit"] == 0
    assert d["axis_on_seabed"] == 500 and 400 < d["proven"] <= 500 and 400 < d["simple"] <= 500


def _gapped_scene():
    """:func:`_plates_and_cable_scene` (seed 3) with a 1 m no-data band across the field (y 202-203 m, as a surveyed
    raster's gaps) and a plate 1 m under the seabed below the band, which the sub-rays through the gap meet."""
    scene = _plates_and_cable_scene(seed=3)
    hf = scene.heightfield
    valid = np.ones((100, 100), bool)
    valid[40:60, :] = False
    hf = HeightField(hf.x0_m, hf.y0_m, hf.spacing_m, hf.heights_m, valid=valid)
    parts = [Part("seabed", "seabed", *hf.mesh(), LABELS["seabed"], 0.2),
             Part("below", "panel", *panel_mesh([102.5, 202.5, -21.0], (5.0, 1.4), (0, 0, 1), (0, 1, 0)),
                  LABELS["panel"], 0.5)]
    for o in scene.objects[1:]:
        faces = scene.faces[o.face_start:o.face_stop]
        used = np.unique(faces)
        parts.append(Part(o.name, o.kind, scene.vertices[used], np.searchsorted(used, faces), o.label, o.reflectance))
    return Scene(parts, heightfield=hf)


def test_a_height_field_with_gaps_is_proven_where_it_holds_seabed():
    """A height field with no-data cells (a surveyed raster's, as real_site's) has its proof grid: a gap holds no
    seabed, so it bounds nothing, and a sub-ray that reaches one may go on to what lies below (a plate 1 m under
    the gap here), so its pulse is left to Embree. Every hit, facet and receiver check equals Embree's (a proof that
    took a gap for seabed would put hits on the missing seabed where Embree finds the plate), most pulses off the
    gap are proven, and the trade-off has no fall-back to report."""
    scene = _gapped_scene()
    pulses = _pulses(4000, seed=2)
    proven, embree, caster = _both(scene, pulses)
    below = scene.object_named("below").object_id
    assert (embree.object_id == below).sum() > 5000  # sub-rays through the gap
    _assert_same_hits(proven, embree)
    target = CastScene(scene, RayCaster.for_scene(scene), seabed_grid(scene, RayCaster.for_scene(scene)))
    d = auto_level.auto_decisions(target, *pulses, beam_pattern(19), GEOMETRY)
    assert d["no_grid"] is None and 0.4 * 4000 < d["proven"] < d["axis_on_seabed"] < 0.8 * 4000
    assert caster.rays < 0.7 * 4000 * 19


def test_a_beam_into_a_gap_with_nothing_below_is_proven_to_meet_nothing():
    """Over a no-data band with nothing under it, a pulse whose axis meets nothing is proven to meet nothing at all
    where no 1 m block the bundle passes over, down to the scene's lowest point, holds anything; Embree then casts
    none of its other sub-rays. Pulses whose footprint straddles the band's edge with the axis in the gap keep the
    sub-rays that land on the seabed (a proof that skipped the blocks would lose them): every hit equals Embree's."""
    hf = _field()
    valid = np.ones((100, 100), bool)
    valid[40:60, :] = False
    hf = HeightField(hf.x0_m, hf.y0_m, hf.spacing_m, hf.heights_m, valid=valid)
    scene = Scene([Part("seabed", "seabed", *hf.mesh(), LABELS["seabed"], 0.2)], heightfield=hf)
    pulses = _pulses(4000, seed=7)
    proven, embree, caster = _both(scene, pulses)
    rows = np.bincount(embree.pulse_index, minlength=4000)
    axis_missed = np.ones(4000, bool)
    axis_missed[embree.pulse_index[embree.subray_index == 0]] = False
    assert (axis_missed & (rows > 0)).sum() > 5  # footprints over the edge, axis in the gap, some sub-rays on seabed
    _assert_same_hits(proven, embree)
    target = CastScene(scene, RayCaster.for_scene(scene), seabed_grid(scene, RayCaster.for_scene(scene)))
    d = auto_level.auto_decisions(target, *pulses, beam_pattern(19), GEOMETRY)
    assert d["no_hit"] > 400 and d["proven_missed"] > 0.5 * d["no_hit"], d
    assert caster.rays == 4000 + 18 * (4000 - d["proven"] - d["proven_missed"])  # the axes, the unproven rest


def test_shadow_rays_past_gaps_are_proven_clear_as_embree_finds_them():
    """Every level's shadow rays over a height field with a no-data band, plates and a cable: those the grid
    proves clear left out, every hit and receiver check the same bits as with every shadow ray cast."""
    scene = _gapped_scene()
    pulses = _pulses(4000, seed=6)
    every, proving = CountingCaster(RayCaster.for_scene(scene)), CountingCaster(RayCaster.for_scene(scene))
    cast = cast_beams(CastScene(scene, every, seabed_grid(scene, every)), *pulses, beam_pattern(19), GEOMETRY,
                      prove_shadows=False)
    proven = cast_beams(CastScene(scene, proving, seabed_grid(scene, proving)), *pulses, beam_pattern(19), GEOMETRY)
    assert ((cast.receiver_weight == 0) & (_seen_without_shadow_rays(scene, pulses) > 0)).sum() > 20
    for f in HIT_FIELDS:
        np.testing.assert_array_equal(getattr(proven, f.name), getattr(cast, f.name), err_msg=f.name)
    assert proving.shadow_rays < 0.6 * every.shadow_rays, (proving.shadow_rays, every.shadow_rays)


def test_the_seabed_bounds_hold_every_triangle():
    """The coarse cells' gradient box holds each seabed triangle's dz/dx, dz/dy (from its vertices, not its
    normal), their top its highest vertex, and the object tops the plates' heights."""
    plate = panel_mesh([101.03, 201.03, -19.5], (0.02, 0.02), (0, 0, 1), (0, 1, 0))
    scene = _seabed_scene([("plate", plate)])
    caster = RayCaster.for_scene(scene)
    grid = seabed_grid(scene, caster)
    v = scene.vertices - scene.local_origin
    tri = v[scene.faces[:2 * 100 * 100]]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    gx = (e1[:, 2] * e2[:, 1] - e2[:, 2] * e1[:, 1]) / det
    gy = (e2[:, 2] * e1[:, 0] - e1[:, 2] * e2[:, 0]) / det
    centre = tri.mean(axis=1)
    size = grid.k * grid.spacing
    i = ((centre[:, 1] - grid.y0) // size).astype(int)
    j = ((centre[:, 0] - grid.x0) // size).astype(int)
    g = grid.gradient[i, j]
    assert np.all(g[:, 0] <= gx + 1e-6) and np.all(gx <= g[:, 1] + 1e-6)
    assert np.all(g[:, 2] <= gy + 1e-6) and np.all(gy <= g[:, 3] + 1e-6)
    assert np.all(tri[:, :, 2].max(axis=1) <= grid.seabed_top[i, j] + 1e-6)
    at = (np.asarray(plate[0])[:, :2] - scene.local_origin[:2] - [grid.x0, grid.y0]) // size
    for cj, ci in at.astype(int):
        assert grid.object_top[ci, cj] == pytest.approx(-19.5 - scene.local_origin[2], abs=1e-5)
    assert np.isinf(grid.object_top).sum() > 0.9 * grid.object_top.size


def test_auto_on_a_seabed_keeps_each_pulses_echo_energy_and_mean_delay():
    """cable_survey's first pulses: auto's echoes (analytic hits, collapsed) bring balanced's energy per pulse
    and its energy-weighted mean echo range to the float32 precision of the distances."""
    setup = PassSetup.build(load_scene("cable_survey"), PassOptions(max_pulses=3000), level=FIDELITY_LEVELS["auto"])
    slots = np.concatenate(list(setup.slot_chunks()))
    rays = setup.scanner.world_rays(setup.trajectory.poses(slots / setup.scanner.pulse_rate_hz))
    geometry = setup.model.instrument.geometry
    auto = cast_auto(setup.target, *rays, setup.pattern, geometry)
    balanced = cast_beams(setup.target, *rays, setup.pattern, geometry)
    n = balanced.n_pulses
    ea = np.bincount(auto.pulse_index, weights=_energy(auto), minlength=n)
    eb = np.bincount(balanced.pulse_index, weights=_energy(balanced), minlength=n)
    np.testing.assert_allclose(ea, eb, rtol=1e-6)
    lit = eb > 0
    mean_a = np.bincount(auto.pulse_index, weights=_energy(auto) * auto.echo_range_m, minlength=n)[lit] / ea[lit]
    mean_b = np.bincount(balanced.pulse_index, weights=_energy(balanced) * balanced.echo_range_m,
                         minlength=n)[lit] / eb[lit]
    np.testing.assert_allclose(mean_a, mean_b, rtol=0, atol=2e-5)
    assert np.bincount(auto.pulse_index, minlength=n).mean() < 4  # mostly three rows a pulse


@pytest.mark.parametrize("ridges", [False, True])
def test_shadow_rays_proven_clear_leave_every_hit_as_embree_finds_it(ridges):
    """Every level casts its shadow rays through cast_beams, which leaves out a pulse's rays where the seabed grid
    proves nothing can stand between its seabed hits and the receiver. With plates over the seabed, a cable on it
    and (``ridges``) relief that hides hits, the hits and receiver checks are those of every ray cast, to the bit,
    while far fewer shadow rays are cast; a proof that passed a blocked path would change a receiver check."""
    scene = _plates_and_cable_scene(seed=5, ridges=ridges)
    pulses = _pulses(4000, seed=6, spread_deg=60.0 if ridges else 40.0)
    every, proving = CountingCaster(RayCaster.for_scene(scene)), CountingCaster(RayCaster.for_scene(scene))
    cast = cast_beams(CastScene(scene, every, seabed_grid(scene, every)), *pulses, beam_pattern(19), GEOMETRY,
                      prove_shadows=False)
    proven = cast_beams(CastScene(scene, proving, seabed_grid(scene, proving)), *pulses, beam_pattern(19), GEOMETRY)
    shadowed = (cast.receiver_weight == 0) & (_seen_without_shadow_rays(scene, pulses) > 0)
    assert shadowed.sum() > 20  # hits hidden from the receiver: what the shadow rays are for
    for f in HIT_FIELDS:
        np.testing.assert_array_equal(getattr(proven, f.name), getattr(cast, f.name), err_msg=f.name)
    assert proving.shadow_rays < (0.6 if ridges else 0.4) * every.shadow_rays, (proving.shadow_rays, every.shadow_rays)


@pytest.mark.slow
def test_regression_the_auto_ray_kernels_compile_no_string_formatting(tmp_path):
    """A cold ``auto`` ray stage (proof, analytic hits, collapse) compiles no string formatting. Root cause:
    ``_proven_figures`` copied a pulse's face indices with an array assigned to a slice (``kept[a:b] = prim[a:b]``),
    so numba compiled its shape-mismatch error with the unicode, repr and str helpers that format it, seconds of an
    ``auto`` first run for a message no valid input raises."""
    names = cold_compiled_kernels(
        "import sys\n"
        f"sys.path[:0] = [{str(Path(__file__).parent)!r}, {str(Path(__file__).parents[2])!r}]\n"
        "from test_auto_level import GEOMETRY, _pulses, _seabed_scene\n"
        "from scanner_sim.rays.auto import cast_auto\n"
        "from scanner_sim.rays.beams import beam_pattern\n"
        "from scanner_sim.rays.cast import CastScene\n"
        "from scanner_sim.rays.caster import RayCaster\n"
        "from scanner_sim.rays.seabed_grid import seabed_grid\n"
        "scene, pulses = _seabed_scene(), _pulses(200, seed=1)\n"
        "caster = RayCaster.for_scene(scene)\n"
        "target = CastScene(scene, caster, seabed_grid(scene, caster))\n"
        "def run():\n"
        "    cast_auto(target, *pulses, beam_pattern(19), GEOMETRY)\n", tmp_path)
    assert any(name.endswith("._proven_figures") for name in names), names
    assert not string_formatting(names)
