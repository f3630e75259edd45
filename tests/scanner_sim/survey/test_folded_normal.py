"""The folded normal's quantile: Newton's steps against SciPy's distribution, and the table of those steps against
the steps themselves, bit for bit once rounded as THU and TVU are reported."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import foldnorm

from scanner_sim.survey.folded_normal import (
    TABLE_ERROR_BOUND,
    TABLE_MAX_R,
    _interpolated,
    folded_normal_quantile,
    quantile_table,
    rounded_folded_normal_quantile,
)
from scanner_sim.survey.folded_normal import TABLE_STEP as STEP

P = 0.95


def test_tvu_is_the_folded_normal_quantile():
    """TVU's quantile (Newton's steps on the normal CDF) against scipy's folded normal distribution."""
    mean = np.array([0.0, 0.01, 0.05, -0.3, 2.0])
    sigma = np.array([0.01, 0.01, 0.01, 0.2, 0.05])
    for p in (0.9, 0.95, 0.99):
        expected = foldnorm(np.abs(mean) / sigma).ppf(p) * sigma
        np.testing.assert_allclose(folded_normal_quantile(mean, sigma, p), expected, rtol=1e-7)
    assert folded_normal_quantile(np.zeros(1), np.ones(1), 0.95)[0] == pytest.approx(1.959964, abs=1e-6)


def _table_alone(mean, sigma, scale=1000.0):
    out, exact = np.empty(mean.size), np.empty(mean.size, np.bool_)
    _interpolated(mean, sigma, quantile_table(P), 1.0 / STEP, TABLE_ERROR_BOUND, scale, out, exact)
    return out, exact


def test_the_table_lies_within_a_quarter_of_its_bound_of_the_steps():
    """The interpolated g(r) against Newton's steps at 3 million r over the table, denser where g bends most
    (r < 1): the largest error stays under a quarter of the bound the rounding trusts."""
    rng = np.random.default_rng(3)
    r = np.concatenate([rng.uniform(0, TABLE_MAX_R - 2 * STEP, 2_000_000), rng.uniform(0, 1, 1_000_000)])
    out, _ = _table_alone(r, np.ones_like(r))
    assert np.abs(out - folded_normal_quantile(r, np.ones_like(r), P)).max() < TABLE_ERROR_BOUND / 4


def test_rounded_quantiles_are_the_steps_rounded_bit_for_bit():
    """Random means and sigmas over five decades, with NaN and infinite sigmas, NaN means, sigmas of 0 (taken as
    1 micrometre) and means far beyond the table: the same bits as the steps rounded to the millimetre."""
    rng = np.random.default_rng(5)
    n = 400_000
    mean = rng.normal(0, 1, n) * 10 ** rng.uniform(-3, 0.5, n)
    sigma = 10 ** rng.uniform(-4, 0.5, n)
    sigma[::97], sigma[::101], mean[::103], sigma[::107], mean[::109] = np.nan, np.inf, np.nan, 0.0, 1e3
    got = rounded_folded_normal_quantile(mean, sigma, P, 3)
    finite = np.isfinite(sigma)
    expected = np.full(n, np.nan)
    expected[finite] = np.round(folded_normal_quantile(mean[finite], sigma[finite], P), 3)
    assert np.array_equal(got, expected, equal_nan=True)


def test_values_on_a_rounding_boundary_are_solved_by_the_steps():
    """Quantiles placed on a half millimetre, where the table's small error decides the rounding: the table alone
    rounds some of them the other way, and the solved ones are the steps' to the bit."""
    rng = np.random.default_rng(7)
    sigma, r = rng.uniform(0.001, 0.2, 50_000), rng.uniform(0, 10, 50_000)
    g = folded_normal_quantile(r * sigma, sigma, P)
    sigma = sigma * ((np.round(g * 1000 - 0.5) + 0.5) / 1000) / g  # the quantile, proportional to sigma, on a tie
    mean = r * sigma
    expected = np.round(folded_normal_quantile(mean, sigma, P), 3)
    alone, exact = _table_alone(mean, sigma)
    assert exact.mean() > 0.99
    assert np.any(np.round(alone, 3) != expected)
    assert np.array_equal(rounded_folded_normal_quantile(mean, sigma, P, 3), expected)


def test_a_confidence_outside_the_solvers_range_is_refused():
    with pytest.raises(ValueError, match="p = 0.5"):
        rounded_folded_normal_quantile(np.zeros(1), np.ones(1), 0.5, 3)
