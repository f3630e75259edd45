"""An echo spread in time by multiple scattering, as the Monte Carlo's tables give it
(:mod:`muls.montecarlo.scattering_tables`): each echo becomes its share on the straight path and equal shares of the rest at the
tables' quantile delays, or one echo at their mean delay where they lie close, interpolated linearly in range over the rows the
Monte Carlo saw. Compiled kernels: each return's row is found once, and the node delays' mean and mean square are closed forms
per interval.
"""

from __future__ import annotations

import numpy as np

from ..infra.runtime import kernel
from ..montecarlo.scattering_tables import ScatteringTables

#: [s] An echo whose delays spread by less than this (their energy-weighted standard deviation) is one echo at their
#: mean delay: it widens the filtered 10 ns pulse's 5.8 ns rms width by under 1.5 % and lowers its peak by about 1 %.
SPREAD_MERGE_S = 1e-9
#: [s] Up to this spread (about the filtered pulse's rms width) neighbouring nodes are paired: equal shares spaced
#: under a pulse width add up to the spread's shape; wider spreads keep every node, or the sum of the shares shows
#: their lumps (four nodes put the peak of a plate's echo 30 m down in the pond 26 % above the Monte Carlo's).
SPREAD_FINE_S = 6e-9
#: An echo's share on the straight path below this is added to its scattered part instead of being an echo of its own.
DIRECT_SHARE_MIN = 1e-3


def spread_rows(tables: ScatteringTables) -> tuple:
    """(ranges (k,) [m], direct share (k,), node delays (k, q) [s], their moments (:func:`_spread_moments`)) of the
    rows of ``tables`` the Monte Carlo saw (:meth:`ScatteringTables.seen_spread`): what :func:`spread_echoes` takes."""
    ranges, direct, nodes = tables.seen_spread()
    return ranges, direct, nodes, _spread_moments(direct, nodes)


def spread_echoes(rows: tuple, delay, energy, range_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Echoes (m,) at ``delay`` [s], ``energy`` [J] and ``range_m`` [m] spread by the table ``rows``
    (:func:`spread_rows`): (index of the echo each comes from, delay [s], energy [J]), each echo's together in its
    order, its straight-path echo first. One echo at the mean delay under :data:`SPREAD_MERGE_S` of spread, the
    node pairs under :data:`SPREAD_FINE_S`, every node beyond."""
    ranges, direct, nodes, moments = rows
    lower, weight = _spread_brackets(np.ascontiguousarray(range_m, dtype=np.float64), ranges)
    count = _spread_counts(lower, weight, direct, nodes.shape[1], moments)
    offsets = np.zeros(count.shape[0] + 1, np.int64)
    np.cumsum(count, out=offsets[1:])
    return _spread_fill(lower, weight, np.ascontiguousarray(delay, np.float64), np.ascontiguousarray(energy, np.float64),
                        offsets, direct, nodes, moments)


@kernel(nogil=True)
def _spread_moments(direct, nodes):
    """Per seen row k and the interval to row k + 1 (rows (k,)): the row's mean node delay [s] and mean squared node
    delay [s^2], and the cross and squared terms of the interval's change, so that a linear interpolation's mean
    and mean square are :func:`_spread_row`'s closed forms (node delays are linear in range between rows)."""
    k, q = nodes.shape
    mean, square, cross, change2 = np.zeros(k), np.zeros(k), np.zeros(k), np.zeros(k)
    for i in range(k):
        j = min(i + 1, k - 1)
        for n in range(q):
            a, d = nodes[i, n], nodes[j, n] - nodes[i, n]
            mean[i] += a / q
            square[i] += a * a / q
            cross[i] += 2.0 * a * d / q
            change2[i] += d * d / q
    return mean, square, cross, change2


@kernel(nogil=True)
def _spread_brackets(range_m, ranges):
    """(lower row (n,), weight of the upper row (n,)) of each range [m] among ``ranges`` (ascending), held outside
    them as ``np.interp`` holds its ends."""
    k = ranges.shape[0]
    lower, weight = np.zeros(range_m.shape[0], np.int64), np.zeros(range_m.shape[0])
    for i in range(range_m.shape[0]):
        r = range_m[i]
        if k == 1 or r <= ranges[0]:
            continue
        if r >= ranges[k - 1]:
            lower[i], weight[i] = k - 2, 1.0
            continue
        lo, hi = 0, k - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if ranges[mid] <= r:
                lo = mid
            else:
                hi = mid
        lower[i], weight[i] = lo, (r - ranges[lo]) / (ranges[lo + 1] - ranges[lo])
    return lower, weight


@kernel(inline="always")
def _spread_row(lo, w, direct, moments):
    """(direct share, mean delay of the scattered light [s], its variance [s^2]) at row ``lo`` + ``w`` of the way to
    the next: the node delays' mean and mean square in closed form (:func:`_spread_moments`)."""
    mean, square, cross, change2 = moments
    hi = min(lo + 1, direct.shape[0] - 1)
    share = direct[lo] + w * (direct[hi] - direct[lo])
    node_mean = mean[lo] + w * (mean[hi] - mean[lo])
    mean_delay = (1.0 - share) * node_mean
    return share, mean_delay, (1.0 - share) * (square[lo] + w * (cross[lo] + w * change2[lo])) - mean_delay**2


@kernel(nogil=True)
def _spread_counts(lower, weight, direct, q, moments):
    """Echoes each return spreads into (n,): 1 under :data:`SPREAD_MERGE_S` of spread, else the node pairs (under
    :data:`SPREAD_FINE_S`) or the ``q`` nodes, plus the straight path's echo where its share is worth one."""
    count = np.empty(lower.shape[0], np.int64)
    for i in range(lower.shape[0]):
        share, _, variance = _spread_row(lower[i], weight[i], direct, moments)
        if variance <= SPREAD_MERGE_S**2:
            count[i] = 1
        else:
            count[i] = (q // 2 if variance <= SPREAD_FINE_S**2 else q) + (1 if share >= DIRECT_SHARE_MIN else 0)
    return count


@kernel(nogil=True)
def _spread_fill(lower, weight, delay, energy, offsets, direct, nodes, moments):
    """The spread echoes of every return, each return's together in its order (its straight-path echo first):
    (return index (m,), delay (m,) [s], energy (m,) [J]) at ``offsets`` (:func:`_spread_counts`' sums)."""
    q = nodes.shape[1]
    m = offsets[-1]
    index, out_delay, out_energy = np.empty(m, np.int64), np.empty(m), np.empty(m)
    for i in range(lower.shape[0]):
        lo, w = lower[i], weight[i]
        share, mean_delay, variance = _spread_row(lo, w, direct, moments)
        j = offsets[i]
        if variance <= SPREAD_MERGE_S**2:
            index[j], out_delay[j], out_energy[j] = i, delay[i] + mean_delay, energy[i]
            continue
        straight = share >= DIRECT_SHARE_MIN
        if straight:
            index[j], out_delay[j], out_energy[j] = i, delay[i], energy[i] * share
            j += 1
        paired = variance <= SPREAD_FINE_S**2
        parts = q // 2 if paired else q
        scattered = energy[i] * ((1.0 - share) if straight else 1.0) / parts
        hi = min(lo + 1, nodes.shape[0] - 1)
        for k in range(parts):
            if paired:
                a = nodes[lo, 2 * k] + w * (nodes[hi, 2 * k] - nodes[lo, 2 * k])
                b = nodes[lo, 2 * k + 1] + w * (nodes[hi, 2 * k + 1] - nodes[lo, 2 * k + 1])
                node = 0.5 * (a + b)
            else:
                node = nodes[lo, k] + w * (nodes[hi, k] - nodes[lo, k])
            index[j], out_delay[j], out_energy[j] = i, delay[i] + node, scattered
            j += 1
    return index, out_delay, out_energy
