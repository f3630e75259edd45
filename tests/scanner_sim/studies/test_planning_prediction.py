"""Survey planning's prediction (docs/planning.md, step 3): the compliant share predicted at a line spacing from a
sample line's across-track profile, the survey time and the ladder of spacings, by hand."""

import numpy as np
import pytest

from scanner_sim.studies.planning_prediction import line_count, predicted_share, spacing_ladder, survey_time_s
from scanner_sim.studies.planning_sampling import BIN_M, Profile, SiteArea


def flat_profile(width_m: float, reach_m: float) -> Profile:
    """A line whose soundings comply within width/2 of it and fail beyond, out to reach_m, one sounding a cell."""
    offsets = (np.arange(int(2 * reach_m / BIN_M)) + 0.5) * BIN_M - reach_m
    cells = np.full(offsets.size, 10)
    good = np.where(np.abs(offsets) < 0.5 * width_m, 10, 0)
    return Profile("w", 1.0, 1.0, offsets, cells, good, cells, {}, np.array([good] * 5), cells.copy())


def test_predicted_share_of_a_sharp_swath_is_its_width_over_the_spacing_without_overlap():
    """Lines that reach no further than their compliant swath W: at a spacing s >= W the compliant share is W / s;
    at s <= W every cell complies (each cell's soundings come from lines within W/2)."""
    p = flat_profile(width_m=4.0, reach_m=2.0)
    assert predicted_share(p, 8.0, 1.0) == pytest.approx(0.5)
    assert predicted_share(p, 5.0, 1.0) == pytest.approx(0.8)
    assert predicted_share(p, 4.0, 1.0) == pytest.approx(1.0)
    # 200 %: at s = W a cell lies within reach of one line only (except exactly between two); at s = W / 2 of two
    assert predicted_share(p, 4.0, 2.0) < 0.1
    assert predicted_share(p, 2.0, 2.0) == pytest.approx(1.0)


def test_a_far_reaching_poor_edge_spoils_cells_the_near_line_alone_would_make_comply():
    """The same 4 m swath, but the scan reaches 6 m out with failing soundings: at 4 m spacing every cell also gets
    the neighbours' failing soundings, so the share drops well below the 100 % of the sharp swath."""
    sharp, wide = flat_profile(4.0, 2.0), flat_profile(4.0, 6.0)
    assert predicted_share(sharp, 4.0, 1.0) == pytest.approx(1.0)
    assert predicted_share(wide, 4.0, 1.0) < 0.6


def test_survey_time_and_the_spacing_ladder_by_hand():
    """24 x 16 m at 8 m spacing: 3 lines of 24 m and 2 legs of 8 m across, 88 m at 2 m/s = 44 s. The ladder spans the
    width with one line fewer at each step: 16 / (n - 1)."""
    area = SiteArea((0.0, 0.0), (24.0, 16.0), 90.0)
    assert survey_time_s(area, 8.0, 2.0) == pytest.approx(44.0)
    ladder = spacing_ladder(16.0, 4.0)
    assert ladder.tolist() == pytest.approx([16 / 4, 16 / 3, 16 / 2, 16 / 1])
    assert [line_count(16.0, s) for s in ladder] == [5, 4, 3, 2]
