"""The uncertainty's check against the truth (scanner_sim/survey/tpu_calibration.py): its compiled judging against
the definitions taken over arrays in numpy, on a real chunk with every case a point can fall in."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scanner_sim.config import load_scene
from scanner_sim.config.materials import NOISE_CLASS
from scanner_sim.survey.chunk import cast_chunk, finish_chunk
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.survey.tpu_calibration import SAME_SURFACE_M, checked_errors
from scanner_sim.survey.uncertainty import TpuModel, coverage_levels


@pytest.fixture(scope="module")
def chunk_with_every_case():
    """A cable_survey chunk (with navigation noise) whose points are made to hold noise, true beams meeting nothing,
    other surfaces, a predicted variance of NaN and one under a micrometre."""
    setup = PassSetup.build(load_scene("cable_survey"), PassOptions(fidelity="fast", max_pulses=2000))
    slots = next(setup.slot_chunks())
    cast = cast_chunk(setup, slots)
    points = finish_chunk(setup, cast).points
    sight = cast.sight
    axis_range = sight.axis_range_m.copy()
    axis_range[::37] = np.nan
    sight = sight._replace(axis_range_m=axis_range)
    classification, true_range = points.classification.copy(), points.true_range_m.copy()
    classification[::41] = NOISE_CLASS
    true_range[::43] += np.float32(2 * SAME_SURFACE_M)
    points = dataclasses.replace(points, classification=classification, true_range_m=true_range)
    mean, var = TpuModel.predict(setup.tpu, points, sight, None)
    var[::47, 2], var[::53, 2], var[::59, :2], mean[::59, :2] = np.nan, 1e-14, 0.0, 0.0
    return setup, points, sight, mean, var


def test_judged_points_and_their_coverage_levels_are_numpys_to_the_bit(chunk_with_every_case):
    """Which points are judged and why the others are not, their true errors and coverage levels: the kernel's
    figures against the same definitions over arrays (the normal CDF SciPy's)."""
    setup, points, sight, mean, var = chunk_with_every_case
    got = checked_errors(points, sight, mean, var, setup.scene)

    row = np.searchsorted(sight.slot, points.pulse_index)
    true_range = sight.axis_range_m[row]
    noise = points.classification == NOISE_CLASS
    met = np.isfinite(true_range)
    same = met & (np.abs(true_range - points.true_range_m) <= SAME_SURFACE_M)
    judged = np.nonzero(~noise & same)[0]
    error = points.xyz[judged] - (sight.true_origin_m[row[judged]]
                                  + true_range[judged, None] * sight.true_direction[row[judged]])
    horizontal = np.hypot(error[:, 0], error[:, 1])
    level_z, level_h = coverage_levels(mean[judged], var[judged], error[:, 2], horizontal)

    assert got.skipped == {"noise": int(noise.sum()), "true_beam_meets_nothing": int((~noise & ~met).sum()),
                           "other_surface": int((~noise & met & ~same).sum())}
    assert min(got.skipped.values()) > 10 and judged.size > 1000
    for name, expected in (("vertical_m", error[:, 2]), ("horizontal_m", horizontal), ("level_vertical", level_z),
                           ("level_horizontal", level_h), ("tvu_m", points.tvu_m[judged])):
        assert np.array_equal(getattr(got, name), expected, equal_nan=True), name
    assert np.isnan(got.level_vertical).sum() == np.isnan(var[judged, 2]).sum() > 0
