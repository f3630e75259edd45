"""One chunk through the flow (scanner_sim/survey/chunk.py): its pulses split into points and dropouts, the dropouts
recorded along the beam navigation estimates, and the truth along a noiseless line of sight taken from the cast
itself as an independent cast along the beam finds it."""

import numpy as np
import pytest

from scanner_sim.config import load_scene
from scanner_sim.records.point_records import DROPOUT_CAUSES
from scanner_sim.survey.chunk import cast_chunk, finish_chunk
from scanner_sim.survey.setup import PassOptions, PassSetup

NOISELESS = {f"platform.navigation_noise.{k}": 0.0
             for k in ("position_sigma_m", "depth_sigma_m", "attitude_sigma_deg", "heading_sigma_deg")}


@pytest.fixture(scope="module")
def turbid():
    """cable_survey in turbid water, with navigation noise: many pulses give no point."""
    setup = PassSetup.build(load_scene("cable_survey"), PassOptions(water="turbid_harbor", max_pulses=3000))
    slots = next(setup.slot_chunks())
    return setup, slots, finish_chunk(setup, cast_chunk(setup, slots))


def test_every_pulse_of_a_chunk_gives_points_or_a_dropout_never_both(turbid):
    _, slots, chunk = turbid
    ranged, lost = set(chunk.points.pulse_index.tolist()), set(chunk.dropouts.pulse_index.tolist())
    assert len(ranged) > 100 and len(lost) > 100
    assert not ranged & lost
    assert ranged | lost == set(slots.tolist())
    assert len(lost) == len(chunk.dropouts)  # one record per lost pulse


def test_a_dropout_is_recorded_along_the_beam_navigation_estimates(turbid):
    """The record holds the pulse's time and the beam a surveyor would look along: the scanner's beam from the
    estimated pose at that time, which with navigation noise is not the true beam."""
    setup, _, chunk = turbid
    drop = chunk.dropouts
    times = drop.pulse_index / setup.scanner.pulse_rate_hz
    np.testing.assert_array_equal(drop.time_s, times)
    origin, direction = setup.scanner.beam_rays(setup.trajectory.poses(times, estimated=True))
    np.testing.assert_allclose(drop.origin, origin, rtol=0, atol=1e-9)
    np.testing.assert_allclose(drop.direction, direction, rtol=0, atol=1e-7)
    true_origin, _ = setup.scanner.beam_rays(setup.trajectory.poses(times))
    assert np.median(np.linalg.norm(drop.origin - true_origin, axis=1)) > 1e-3
    assert set(np.unique(drop.cause)) <= set(range(len(DROPOUT_CAUSES)))


def test_without_navigation_noise_the_truth_along_the_beam_is_what_a_cast_along_the_beam_meets():
    """Without navigation noise the chunk reuses the axis sub-ray's hit as the truth along each line of sight instead
    of casting again; a cast of its own along each beam (the caster's first hits) must find the same ranges."""
    config = load_scene("cable_survey").with_overrides(NOISELESS)
    setup = PassSetup.build(config, PassOptions(max_pulses=2000))
    assert not setup.trajectory.has_navigation_noise
    sight = cast_chunk(setup, next(setup.slot_chunks())).sight
    scene = setup.scene
    ray, tri, dist = setup.target.caster.first_hits((sight.origin_m - scene.local_origin).astype(np.float32),
                                                     sight.direction.astype(np.float32))
    cast = np.full(len(sight.slot), np.nan)
    cast[ray] = dist
    seen = np.isfinite(sight.true_range_m)
    assert seen.mean() > 0.9
    np.testing.assert_allclose(sight.true_range_m[seen], cast[seen], rtol=0, atol=2e-4)
    surface = np.full(len(sight.slot), -1)
    surface[ray] = scene.face_surface[tri]
    np.testing.assert_array_equal(sight.first_surface[seen], surface[seen])
