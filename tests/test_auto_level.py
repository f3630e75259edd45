"""The ``auto`` level: balanced's cast, each simple footprint's sub-ray echoes replaced by the two-point Gauss
quadrature of their delays, the rest kept."""

from pathlib import Path

import numpy as np
import pytest

from scanner_sim.auto_level import SIMPLE_SPREAD_M, cast_auto, simple_pulses, two_point_rule
from scanner_sim.config import load_scene
from scanner_sim.fidelity import FIDELITY_LEVELS
from scanner_sim.raycast import Hits, cast_beams
from scanner_sim.survey import PassOptions, PassSetup, hit_echo_range_m
from scanner_sim.tradeoff import with_level

FAILURES = Path(__file__).resolve().parent.parent / "scenes" / "failures"
M = 7


def _hits(pulse, range_m, object_id, n_pulses):
    n = len(pulse)
    f = np.ones(n)
    sub = np.concatenate([np.arange(c) for c in np.bincount(pulse, minlength=n_pulses)]).astype(np.int32)
    return Hits(pulse_index=np.asarray(pulse, np.int64), subray_index=sub, range_m=np.asarray(range_m, float),
                point=np.zeros((n, 3)), normal=np.tile([0.0, 0.0, 1.0], (n, 1)), incidence_rad=0 * f,
                reflectance=0.1 * f, label=np.ones(n, np.int16), object_id=np.asarray(object_id, np.int32),
                receiver_weight=f, weight=f / M, rx_distance_m=np.asarray(range_m, np.float32), n_pulses=n_pulses,
                n_subrays=M)


def test_a_pulse_is_simple_only_when_all_its_sub_rays_meet_one_object_within_the_spread():
    """Four pulses of seven sub-rays: 0 all on object 1 within 1 cm (simple); 1 one sub-ray on object 2; 2 a range
    spread just over the limit; 3 one sub-ray missing."""
    flat = list(5.0 + np.linspace(0, 0.01, M))
    pulse = [0] * M + [1] * M + [2] * M + [3] * (M - 1)
    rng = flat + flat + list(5.0 + np.linspace(0, 1.01 * SIMPLE_SPREAD_M, M)) + flat[:-1]
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
    setup = with_level(PassSetup.build(load_scene(str(FAILURES / f"{scene}.yaml")), PassOptions(max_pulses=pulses)),
                       FIDELITY_LEVELS["auto"])
    slots = np.concatenate(list(setup.slot_chunks()))
    rays = setup.scanner.world_rays(setup.trajectory.poses(slots / setup.scanner.pulse_rate_hz))
    geometry = setup.model.instrument.geometry
    return (cast_auto(setup.caster, setup.scene, *rays, setup.pattern, geometry),
            cast_beams(setup.caster, setup.scene, *rays, setup.pattern, geometry))


def _energy(hits):
    return hits.weight * hits.reflectance * np.cos(hits.incidence_rad) * hits.receiver_weight


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
    mean_a = per_pulse(auto, _energy(auto) * hit_echo_range_m(auto))[lit] / ea[lit]
    mean_b = per_pulse(balanced, _energy(balanced) * hit_echo_range_m(balanced))[lit] / eb[lit]
    np.testing.assert_allclose(mean_a, mean_b, rtol=0, atol=1e-6)  # return legs are float32: 0.5 um at 9 m

    def variance(hits, mean, energy):
        full_mean = np.zeros(n)
        full_mean[lit] = mean
        return per_pulse(hits, _energy(hits) * (hit_echo_range_m(hits) - full_mean[hits.pulse_index]) ** 2)[lit] / energy

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
