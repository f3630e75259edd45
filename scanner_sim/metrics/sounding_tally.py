"""The S-44 order tally's kernel: every sounding of a chunk judged against each order and counted in that order's
cell, in one pass over the soundings (:class:`scanner_sim.metrics.s44.OrderTally`).

Numpy would take each order's test and each order's cell index as a pass over the chunk's arrays, ten scatter-adds
besides; here they are one loop that releases the GIL, since it runs on the pass's own thread beside the chunks'
workers. Its judgement is :func:`scanner_sim.metrics.s44.soundings_meeting`'s and its cells are
:meth:`scanner_sim.metrics.coverage.PlanGrid.index`'s, operation for operation in float64 (tests compare the counts).
"""

from __future__ import annotations

import math

from muls.infra.runtime import kernel


@kernel(nogil=True)
def tally_soundings(truth, measured, tvu_m, thu_m, limits, origin_m, cell_m, shapes, offsets, soundings, meeting):
    """Count each sounding into ``soundings`` and, where it meets the order, ``meeting`` (both the orders' cells
    flattened one after the other, int32), for every order whose grid holds its true plan position.

    truth, measured (n, 3) float64 [m]: the sounding's true point (z up, the surface at 0; NaN: none, counted
    nowhere) and where the pass put it; tvu_m, thu_m (n,) float64 or (0,): its predicted 95 % uncertainties [m] (NaN:
    not predicted, its true errors decide); limits (orders, 4): each order's TVU a squared [m^2], TVU b, THU [m] and
    THU's depth fraction (S-44 Table 1); origin_m (2,) the grids' shared lower-left corner [m]; cell_m (orders,) [m];
    shapes (orders, 2) int64 (ny, nx); offsets (orders,) int64: each order's first cell in the flat counts.
    """
    for i in range(truth.shape[0]):
        tx, ty, tz = truth[i, 0], truth[i, 1], truth[i, 2]
        depth = -tz
        vertical = abs(measured[i, 2] - tz)
        horizontal = math.hypot(measured[i, 0] - tx, measured[i, 1] - ty)
        for k in range(limits.shape[0]):
            fx = math.floor((tx - origin_m[0]) / cell_m[k])
            fy = math.floor((ty - origin_m[1]) / cell_m[k])
            ny, nx = shapes[k, 0], shapes[k, 1]
            if not (fx >= 0 and fx < nx and fy >= 0 and fy < ny):  # also where NaN
                continue
            cell = offsets[k] + int(fy) * nx + int(fx)
            soundings[cell] += 1
            bd = limits[k, 1] * depth
            tvu = math.sqrt(limits[k, 0] + bd * bd)  # S-44 section 3.2.3: sqrt(a^2 + (b d)^2)
            thu = limits[k, 2] + limits[k, 3] * depth
            ok = vertical <= tvu and horizontal <= thu
            if tvu_m.shape[0]:
                ok = ok and (math.isnan(tvu_m[i]) or tvu_m[i] <= tvu)
            if thu_m.shape[0]:
                ok = ok and (math.isnan(thu_m[i]) or thu_m[i] <= thu)
            if ok:
                meeting[cell] += 1

