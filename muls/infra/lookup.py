"""Compiled lookups in tables: the cell of a sorted grid that holds a value, interpolation in it as numpy.interp
does, and linear interpolation on a geometric grid by its logarithm.

For numba kernels that look up a table once per call: numba's scalar ``np.interp`` sets up arrays at every call
(136 ns against 50 for :func:`bracket` and :func:`interp_at`, measured in the peak fit's loop).
"""

from __future__ import annotations

import math

from .runtime import kernel


@kernel(inline="always")
def bracket(x, xp):
    """The cell of ascending ``xp`` (n,) that holds ``x``, as :func:`numpy.interp` finds it: j with xp[j] <= x <
    xp[j + 1]; -1 below the grid (or NaN), n - 1 at or above its end."""
    n = xp.shape[0]
    if x >= xp[n - 1]:
        return n - 1
    if not x >= xp[0]:
        return -1
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@kernel(inline="always")
def interp_at(x, j, xp, fp):
    """``numpy.interp(x, xp, fp)`` with x in cell ``j`` (:func:`bracket`), in numpy's arithmetic."""
    n = xp.shape[0]
    if j == n - 1:
        return fp[n - 1]
    if j < 0:
        return fp[0] if x < xp[0] else x  # x is NaN: NaN, as numpy gives
    if xp[j] == x:
        return fp[j]
    return (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j]) * (x - xp[j]) + fp[j]


@kernel(inline="always")
def on_geometric_grid(x, ratio, table):
    """Linear interpolation of ``table`` at ``x`` on the geometric grid ``ratio`` (O(1): index from log x)."""
    if not x > ratio[0]:  # also x <= 0 and NaN: below the grid
        return table[0]
    return on_log_grid(math.log(x), math.log(ratio[0]), steps_per_log(ratio), table)


@kernel(inline="always")
def steps_per_log(ratio):
    """Grid steps per unit of natural log of the geometric grid ``ratio``."""
    return (ratio.shape[0] - 1) / (math.log(ratio[ratio.shape[0] - 1]) - math.log(ratio[0]))


@kernel(inline="always")
def on_log_grid(log_x, log_first, steps, table):
    """:func:`on_geometric_grid` given log x, the log of the grid's first ratio and its steps per unit of log
    (:func:`steps_per_log`): no transcendental function, for loops that move along the grid in log."""
    n = table.shape[0]
    pos = (log_x - log_first) * steps
    if not pos > 0.0:  # also NaN
        return table[0]
    if pos >= n - 1:
        return table[n - 1]
    i = int(pos)
    f = pos - i
    return table[i] + f * (table[i + 1] - table[i])
