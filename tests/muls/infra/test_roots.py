"""Brent's root finder (muls/infra/roots.py) returns SciPy's bits, so that the water's phase-function family, solved at
import, is the same without importing scipy.optimize."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq as scipy_brentq

from muls.infra.roots import brentq
from muls.water.phase_family import FF_LINE_N0, FF_LINE_SLOPE, FF_MU_SEARCH, fournier_forand_backscatter_ratio


def test_same_bits_as_scipy_on_random_brackets():
    rng = np.random.default_rng(1)
    compared = 0
    for _ in range(500):
        c = rng.normal(size=4)

        def f(x, c=c):
            return math.sin(c[0] * x) + c[1] * x**3 + c[2] * x + c[3]

        if np.sign(f(-5.0)) == np.sign(f(5.0)):
            continue
        xtol = 10 ** rng.uniform(-14, -2)
        assert brentq(f, -5.0, 5.0, xtol=xtol) == scipy_brentq(f, -5.0, 5.0, xtol=xtol)
        compared += 1
    assert compared > 100


@pytest.mark.parametrize("ratio", [0.002, 0.005, 0.01, 0.015, 0.0183, 0.0245])
def test_same_fournier_forand_member_as_scipy(ratio):
    def f(mu):
        return fournier_forand_backscatter_ratio(FF_LINE_N0 + FF_LINE_SLOPE * (mu - 3.0), mu) - ratio

    assert brentq(f, *FF_MU_SEARCH, xtol=1e-10) == scipy_brentq(f, *FF_MU_SEARCH, xtol=1e-10)


def test_root_of_a_known_function_and_a_bad_bracket():
    assert brentq(lambda x: x * x - 2.0, 0.0, 2.0) == pytest.approx(math.sqrt(2.0), abs=1e-11)
    with pytest.raises(ValueError, match="different signs"):
        brentq(lambda x: x * x + 1.0, -1.0, 1.0)
