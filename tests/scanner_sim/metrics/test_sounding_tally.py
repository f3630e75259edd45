"""The S-44 order tally's compiled loop against numpy's definition of what it counts."""

import numpy as np
import pytest

from scanner_sim.metrics import s44


@pytest.mark.parametrize("predicted", [False, True])
def test_order_tally_counts_what_soundings_meeting_and_the_grids_index_count(predicted):
    """The tally's kernel against the numpy definition of a sounding meeting an order (:func:`s44.soundings_meeting`)
    and of its cell (``PlanGrid.index``), counted with ``np.bincount``: soundings on cell edges, outside the grids,
    without a truth (NaN), at every order's limit, with and without predicted uncertainties (some NaN)."""
    from scanner_sim.metrics.coverage import PlanGrid
    from scanner_sim.metrics.s44 import OrderTally, order_scales

    rng = np.random.default_rng(11)
    n = 20000
    scales = order_scales()
    grids = [PlanGrid.over((-3.0, 41.0), (2.0, 30.5), s.cell_m) for s in scales]
    xy = rng.uniform(-5.0, 45.0, (n, 2))
    xy[::7] = np.round(xy[::7] * 2) / 2  # on the 0.5 m cells' edges, and so on every order's
    depth = rng.uniform(0.5, 60.0, n)
    truth = np.c_[xy, -depth]
    truth[::53] = np.nan
    order = np.array([s.order for s in scales])[rng.integers(0, len(scales), n)]
    tvu = np.array([o.tvu_max_m(d) for o, d in zip(order, depth)])
    thu = np.array([o.thu_max_m(d) for o, d in zip(order, depth)])
    # errors spread over each order's limits, some exactly at one
    vertical = tvu * rng.choice([-1.0, 1.0], n) * np.where(rng.random(n) < 0.1, 1.0, rng.uniform(0, 1.3, n))
    angle = rng.uniform(0, 2 * np.pi, n)
    horizontal = thu * np.where(rng.random(n) < 0.1, 1.0, rng.uniform(0, 1.3, n))
    measured = truth + np.c_[horizontal * np.cos(angle), horizontal * np.sin(angle), vertical]
    tvu_m = thu_m = None
    if predicted:
        tvu_m, thu_m = tvu * rng.uniform(0.5, 1.2, n), thu * rng.uniform(0.5, 1.2, n)
        tvu_m[::5], thu_m[::3] = np.nan, np.nan
    tally = OrderTally(grids, scales)
    tally.add(truth, measured, tvu_m, thu_m)

    meets = s44.soundings_meeting(depth, measured[:, 2] - truth[:, 2],
                                  np.hypot(*(measured[:, :2] - truth[:, :2]).T), tvu_m, thu_m)
    assert 0.2 < meets.mean() < 0.8  # both outcomes well represented
    for k, grid in enumerate(grids):
        cell = grid.index(truth[:, :2])
        np.testing.assert_array_equal(tally.soundings[k], np.bincount(cell[cell >= 0], minlength=grid.size))
        counted = (cell >= 0) & meets[k]
        np.testing.assert_array_equal(tally.meeting[k], np.bincount(cell[counted], minlength=grid.size))
