"""The fidelity table's column cuts, by hand."""

import numpy as np
import pytest

from muls.infra.errors import ParameterError
from scanner_sim.rays.echoes import ECHO_BIN_M
from scanner_sim.survey.handoff import column_cuts


def test_per_pulse_cut_sits_at_the_energy_weighted_mean_range_of_the_hits():
    """Pulse 0: 0.3 of the beam stops at 5 m and 0.2 at 6 m (mean 5.4 m), 0.5 misses; pulse 1 meets nothing."""
    cuts, shares = column_cuts(np.array([0, 0]), np.array([5.0, 6.0]), np.array([0.3, 0.2]), 2, "pulse")
    np.testing.assert_allclose(cuts, [[5.4, np.inf], [np.inf, np.inf]])
    np.testing.assert_allclose(shares, [[0.5, 0.5], [0.0, 1.0]])


def test_per_subray_cuts_light_the_column_to_each_surface():
    """The same beam cut per sub-ray: 0.3 at 5 m and 0.2 at 6 m; two sub-rays within a bin share one cut."""
    half_bin = 0.4 * ECHO_BIN_M
    cuts, shares = column_cuts(np.array([0, 0, 0]), np.array([6.0, 5.0, 5.0 + half_bin]),
                               np.array([0.2, 0.15, 0.15]), 2, "subray")
    assert cuts.shape == (2, 3)
    np.testing.assert_allclose(cuts[0], [5.0 + 0.5 * half_bin, 6.0, np.inf])
    np.testing.assert_allclose(shares, [[0.3, 0.2, 0.5], [0.0, 0.0, 1.0]])
    assert np.all(np.isinf(cuts[1]))


def test_one_surface_gives_the_same_column_whichever_the_cut():
    rng = np.random.default_rng(1)
    pulse = np.repeat(np.arange(4), 7)
    weight = np.full(28, 1 / 7)
    depth = np.repeat(rng.uniform(2, 9, 4), 7)
    a = column_cuts(pulse, depth, weight, 4, "pulse")
    b = column_cuts(pulse, depth, weight, 4, "subray")
    np.testing.assert_allclose(a[0], b[0])
    np.testing.assert_allclose(a[1], b[1], atol=1e-12)


def test_an_unknown_cut_is_refused_naming_the_choices():
    with pytest.raises(ParameterError, match="column_cut = 'beam'.*'pulse', 'subray'"):
        column_cuts(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), 1, "beam")


def test_per_subray_cuts_do_not_need_the_hits_sorted_by_pulse():
    """Hits of three pulses interleaved (an adaptive pass reorders its rows): each pulse's cuts come out in
    range order with its own shares. Pulse 2: 0.1 at 7 m, 0.1 and 0.2 at 3 m (one cut), 0.6 misses; pulse 0
    nothing; pulse 1: 1.0 at 4 m."""
    cuts, shares = column_cuts(np.array([2, 1, 2, 2]), np.array([7.0, 4.0, 3.0, 3.0]),
                               np.array([0.1, 1.0, 0.1, 0.2]), 3, "subray")
    np.testing.assert_allclose(cuts, [[np.inf] * 3, [4.0, np.inf, np.inf], [3.0, 7.0, np.inf]])
    np.testing.assert_allclose(shares, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.3, 0.1, 0.6]], atol=1e-15)
