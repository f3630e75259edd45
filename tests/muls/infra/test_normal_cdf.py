"""The compiled normal distribution function against SciPy's ``ndtr``, bit for bit."""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy.special import ndtr

from muls.infra.normal_cdf import normal_cdf


@numba.njit
def _over(x):
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        out[i] = normal_cdf(x[i])
    return out


def test_normal_cdf_is_scipys_ndtr_to_the_bit():
    """Normal, uniform and near-edge arguments: each branch of Cephes' erf and erfc (|x| / sqrt 2 under 1, in
    [1, 8), from 8, past the underflow), both signs, zeros, NaN and infinities."""
    rng = np.random.default_rng(11)
    edges = np.array([1.0, 8.0, 26.6, 37.5, 38.0]) * math.sqrt(2.0)
    x = np.concatenate([rng.normal(0, 3, 1_000_000), rng.uniform(-40, 40, 1_000_000), rng.uniform(-1.5, 1.5, 500_000),
                        np.concatenate([edges, -edges, np.nextafter(edges, 0), -np.nextafter(edges, 0)]),
                        [0.0, -0.0, np.nan, np.inf, -np.inf, 1e-300, -1e-300]])
    got, expected = _over(x), ndtr(x)
    assert np.array_equal(got, expected, equal_nan=True)
