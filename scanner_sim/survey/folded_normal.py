"""The folded normal's quantile, the T with P(|Z| <= T) = p for Z normal of mean mu and standard deviation sigma: by
Newton's method (:func:`folded_normal_quantile`), and rounded as THU and TVU are reported, from a table of the same
Newton steps (:func:`rounded_folded_normal_quantile`).

Newton's steps take 16 evaluations of the normal's distribution function and density a point (two of each a step,
four steps), most of a chunk's uncertainty stage. But the steps are the same in units of sigma: with r = |mu| / sigma
the result is sigma g(r), one smooth function of r for a given p. The table holds g on a grid of r (its values the
steps' own), and a point's quantile is sigma times g interpolated there (four-point Lagrange). Rounded to the
millimetre, the two agree wherever the table's error cannot carry the value across a rounding boundary; the few
points that lie that close to one, or beyond the table, are solved by the steps themselves. So the reported figures
are those of the steps, bit for bit, at about a tenth of their cost.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.special import ndtr, ndtri

from muls.infra.runtime import kernel

#: Newton steps of :func:`folded_normal_quantile`: from within 0.43 sigma of the root, four steps reach it to
#: about 1e-6 sigma, far under the millimetre THU and TVU are reported to.
NEWTON_STEPS = 4
#: Grid step of the table of g(r) [sigma], r = |mu| / sigma, and the largest r it holds: four-point Lagrange
#: interpolation on it lies within 8.1e-10 sigma of the steps (the largest of 3 million r, near r = 0.12, where g
#: bends most; h^4 scaling: 1.3e-8 at twice the step).
TABLE_STEP = 1.0 / 128.0
TABLE_MAX_R = 64.0
#: [sigma] What :func:`rounded_folded_normal_quantile` allows the table's value to lie from the steps' (twelve times
#: the largest error found, and tests/scanner_sim/survey/test_folded_normal.py holds the table to a quarter of it).
TABLE_ERROR_BOUND = 1e-8


def folded_normal_quantile(mean, sigma, p: float) -> np.ndarray:
    """(n,) the T with P(|Z| <= T) = ``p`` for Z normal of ``mean`` (n,) and ``sigma`` (n,) [m], for p >= 0.9:
    Newton's method on F(T) = Phi((T - mean) / sigma) - Phi((-T - mean) / sigma) = p from T0 = |mean| + z sigma,
    z = Phi^-1((1 + p) / 2) (1.96 for 0.95), which lies at or above the root. F rises and is concave beyond |mean|,
    and its first step is at most (1 - p) / (2 phi(z)) sigma < z sigma long for p >= 0.9 (0.43 sigma at 0.95), so
    every iterate stays beyond |mean| and the steps converge quadratically onto the root (:data:`NEWTON_STEPS`).
    A sigma under 1 micrometre is taken as 1 micrometre."""
    if not 0.9 <= p < 1.0:
        raise ValueError(f"folded_normal_quantile: p = {p!r}; this solver holds for 0.9 <= p < 1")
    mean, sigma = np.abs(np.asarray(mean, np.float64)), np.maximum(np.asarray(sigma, np.float64), 1e-6)
    t = mean + ndtri(0.5 + 0.5 * p) * sigma
    for _ in range(NEWTON_STEPS):
        a, b = (t - mean) / sigma, (t + mean) / sigma
        f = ndtr(a) - ndtr(-b) - p
        slope = (np.exp(-0.5 * a * a) + np.exp(-0.5 * b * b)) / (sigma * math.sqrt(2.0 * math.pi))
        t = t - f / slope
    return t


def rounded_folded_normal_quantile(mean, sigma, p: float, decimals: int) -> np.ndarray:
    """(n,) ``np.round(folded_normal_quantile(mean, sigma, p), decimals)``, the same bits, from the table of
    :func:`quantile_table` (module doc); NaN where ``sigma`` (n,) is not finite. ``mean`` (n,) [m]."""
    mean, sigma = np.ascontiguousarray(mean, np.float64), np.ascontiguousarray(sigma, np.float64)
    out, exact = np.empty(mean.shape[0]), np.empty(mean.shape[0], np.bool_)
    _interpolated(mean, sigma, quantile_table(p), 1.0 / TABLE_STEP, TABLE_ERROR_BOUND, 10.0 ** decimals, out, exact)
    if exact.any():
        out[exact] = folded_normal_quantile(mean[exact], sigma[exact], p)
    return np.round(out, decimals)


@functools.lru_cache(maxsize=4)
def quantile_table(p: float) -> np.ndarray:
    """g(r) = :func:`folded_normal_quantile` (r, 1, p) at r = (k - 1) :data:`TABLE_STEP`, k = 0 ... up to two steps
    past :data:`TABLE_MAX_R` (g is even in r: the first entry is g(-step) = g(step))."""
    r = np.abs(np.arange(-1, round(TABLE_MAX_R / TABLE_STEP) + 3) * TABLE_STEP)
    return folded_normal_quantile(r, np.ones_like(r), p)


@kernel(nogil=True)
def _interpolated(mean, sigma, table, per_step, bound, scale, out, exact):
    """For each point, ``out`` = sigma g(|mean| / sigma) by four-point Lagrange on ``table`` (``per_step`` entries a
    unit of r), and ``exact`` True where that cannot be trusted to round as the steps' value does: out ``scale``
    (10^decimals) within ``bound`` sigma (and a rounding's worth) of a rounding boundary, r beyond the table, or
    sigma not finite (out NaN)."""
    last = table.shape[0] - 3
    for i in range(mean.shape[0]):
        s = sigma[i]
        if not np.isfinite(s):
            out[i], exact[i] = np.nan, False
            continue
        s = max(s, 1e-6)
        x = abs(mean[i]) / s * per_step
        if not x < last:  # beyond the table, or a NaN mean
            out[i], exact[i] = np.nan, True
            continue
        k = int(x)
        t = x - k
        y0, y1, y2, y3 = table[k], table[k + 1], table[k + 2], table[k + 3]  # g at r = (k - 1 ... k + 2) step
        g = (-t * (t - 1.0) * (t - 2.0) / 6.0 * y0 + (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0 * y1
             - (t + 1.0) * t * (t - 2.0) / 2.0 * y2 + (t + 1.0) * t * (t - 1.0) / 6.0 * y3)
        value = s * g
        scaled = value * scale
        margin = scale * (bound * s + 1e-12 * value) + 1e-9
        out[i] = value
        exact[i] = abs(scaled - math.floor(scaled) - 0.5) <= margin
