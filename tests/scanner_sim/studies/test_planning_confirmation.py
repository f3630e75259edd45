"""Survey planning's confirmation (docs/planning.md, step 4): the area a confirmation pass flies under a pulse
budget, by hand. The confirmation passes themselves run in tests/scanner_sim/studies/test_planning.py."""

import pytest

from scanner_sim.studies.planning_confirmation import confirm_area
from scanner_sim.studies.planning_prediction import Candidate, survey_time_s
from scanner_sim.studies.planning_sampling import SiteArea


def test_a_large_site_is_confirmed_over_a_centred_sample_that_fits_the_pulse_budget():
    """72 x 52 m at 52/7 m spacing (8 lines), 2 m/s, 1,260 pulses/s: the whole plan is 314 s, 395,640 pulses. Under a
    100,000-pulse budget the lines are cut to 20 m (not shorter), still (8 x 20 + 7 x 7.43) / 2 x 1,260 = 133,560
    pulses; 6 lines fit ((6 x 20 + 5 x 7.43) / 2 x 1,260 = 99,000), so the sample is 20 x 37.1 m."""
    area = SiteArea((0.0, 0.0), (72.0, 52.0), 90.0)
    plan = Candidate(4.0, 2.0, 52 / 7, 7.0, 0.95, survey_time_s(area, 52 / 7, 2.0), 8 * 72.0, 8)
    assert plan.survey_time_s * 1260 == pytest.approx(395_640)
    assert confirm_area(area, plan, 1260.0, 400_000) == area
    sample = confirm_area(area, plan, 1260.0, 100_000)
    assert sample.size_m == pytest.approx((20.0, 5 * 52 / 7))
    assert survey_time_s(sample, plan.spacing_m, 2.0) * 1260 <= 100_000
