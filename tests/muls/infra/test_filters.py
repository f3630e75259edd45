"""muls.infra.filters.first_order_filter against scipy's lfilter (a second engine) and a closed form."""

import math

import numpy as np
from scipy.signal import lfilter

from muls.infra.filters import first_order_filter


def test_first_order_filter_matches_lfilter_bit_for_bit():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(4000, 6))
    r, b0, b1 = math.exp(-0.05), 0.3, -1.7
    assert np.array_equal(first_order_filter(x, r, b0, b1), lfilter([b0, b1], [1.0, -r], x, axis=0))
    assert np.array_equal(first_order_filter(x[:, 0], r), lfilter([1.0], [1.0, -r], x[:, 0]))


def test_first_order_filter_of_a_step_is_a_geometric_sum():
    r = 0.9
    y = first_order_filter(np.ones(50), r)
    n = np.arange(50)
    assert np.allclose(y, (1.0 - r ** (n + 1)) / (1.0 - r), rtol=1e-13)
