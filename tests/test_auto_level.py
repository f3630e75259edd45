"""The ``auto`` level: one echo where the beam's probe finds one surface seen alike, the full pattern elsewhere."""

from pathlib import Path

import numpy as np

from scanner_sim.auto_level import PROBE_SUBRAYS, SIMPLE_SPREAD_M, cast_auto, simple_pulses
from scanner_sim.config import load_scene
from scanner_sim.fidelity import FIDELITY_LEVELS
from scanner_sim.raycast import Hits, cast_beams
from scanner_sim.survey import PassOptions, PassSetup
from scanner_sim.tradeoff import with_level

FAILURES = Path(__file__).resolve().parent.parent / "scenes" / "failures"


def _probe(pulse, range_m, object_id, seen):
    n = len(pulse)
    f = np.ones(n)
    return Hits(pulse_index=np.asarray(pulse, np.int64), subray_index=np.tile(np.arange(PROBE_SUBRAYS), n)[:n].astype(np.int32),
                range_m=np.asarray(range_m, float), point=np.zeros((n, 3)), normal=np.tile([0.0, 0.0, 1.0], (n, 1)),
                incidence_rad=0 * f, reflectance=0.1 * f, label=np.ones(n, np.int16),
                object_id=np.asarray(object_id, np.int32), receiver_weight=np.asarray(seen, float),
                weight=f / PROBE_SUBRAYS, rx_distance_m=f, n_pulses=5, n_subrays=PROBE_SUBRAYS)


def test_a_pulse_is_simple_only_when_its_whole_probe_meets_one_surface_seen_alike():
    """Five pulses of seven probe sub-rays: 0 all on object 1 within 1 cm (simple); 1 one sub-ray on object 2;
    2 one sub-ray unseen by the receiver; 3 a range spread just over the limit; 4 one sub-ray missing."""
    m = PROBE_SUBRAYS
    flat = list(5.0 + np.linspace(0, 0.01, m))
    pulse = [0] * m + [1] * m + [2] * m + [3] * m + [4] * (m - 1)
    rng = flat + flat + flat + list(5.0 + np.linspace(0, 1.01 * SIMPLE_SPREAD_M, m)) + flat[:-1]
    obj = [1] * m + [1] * (m - 1) + [2] + [1] * (3 * m - 1)
    seen = [1] * (2 * m) + [1] * (m - 1) + [0] + [1] * (2 * m - 1)
    np.testing.assert_array_equal(simple_pulses(_probe(pulse, rng, obj, seen)), [True, False, False, False, False])


def _auto_hits(scene, pulses=50):
    """(auto's hits, balanced's hits) of the scene's first pulses."""
    setup = with_level(PassSetup.build(load_scene(str(FAILURES / f"{scene}.yaml")), PassOptions(max_pulses=pulses)),
                       FIDELITY_LEVELS["auto"])
    slots = np.concatenate(list(setup.slot_chunks()))
    rays = setup.scanner.world_rays(setup.trajectory.poses(slots / setup.scanner.pulse_rate_hz))
    geometry = setup.model.instrument.geometry
    return (cast_auto(setup.caster, setup.scene, *rays, setup.pattern, geometry),
            cast_beams(setup.caster, setup.scene, *rays, setup.pattern, geometry))


def test_a_flat_plate_square_on_gets_one_echo_per_pulse_and_an_edge_the_full_pattern():
    """Square on to a plate in clear water every pulse is simple: one row, the axis, with the whole beam. Across
    the step edges the pulses that straddle an edge keep balanced's 19 sub-rays."""
    flat, _ = _auto_hits("clear_water")
    assert len(flat) == flat.n_pulses and np.all(flat.subray_index == 0)
    np.testing.assert_allclose(flat.hit_fraction(), 1.0)
    steps, balanced = _auto_hits("step_edges", 400)
    rows = np.bincount(steps.pulse_index, minlength=steps.n_pulses)
    full = np.bincount(balanced.pulse_index, minlength=steps.n_pulses)
    one = rows == 1
    assert one.any() and not one.all()  # both kinds of pulse occur
    np.testing.assert_array_equal(rows[~one], full[~one])  # the others are cast as balanced casts them
    assert np.all(np.diff(steps.pulse_index) >= 0)  # scan order
    def axis(hits):
        return np.bincount(hits.pulse_index[hits.subray_index == 0], minlength=hits.n_pulses)

    np.testing.assert_array_equal(axis(steps), axis(balanced))  # the beam axis's hit is kept wherever it hits
