"""The far channel's gate as a pass sets it (scanner_sim/survey/gate.py): the operator's rule where the scene gives
no gate, a warning where the scene's gate shuts out the survey's echoes."""

import warnings

import numpy as np
import pytest

from scanner_sim.config import load_scene
from scanner_sim.config.errors import SetupWarning
from scanner_sim.studies.coverage_study import StudyPlan, run_study
from scanner_sim.survey.gate import GATE_LAG_S, GATE_LEAD_S, echo_span
from scanner_sim.survey.setup import PassOptions, PassSetup

NO_GATE = {"instrument.gate_delay_ns": None, "instrument.gate_width_ns": None}


def _setup(name, **changes):
    with warnings.catch_warnings():
        warnings.simplefilter("error", SetupWarning)
        return PassSetup.build(load_scene(name).with_overrides(changes), PassOptions(max_pulses=2000, progress=False))


@pytest.mark.parametrize("altitude_m", [3.0, 6.0, 12.0])
def test_a_scene_without_a_gate_gets_one_around_the_echoes_it_gives(altitude_m):
    """The rule opens the far channel 20 ns before the earliest echo of the sampled beams and closes it 20 ns after the
    latest one's pulse; at nadir over flat ground an echo arrives 2 h / c_w after the pulse, so the gate follows the
    altitude: it opens 20 to 40 ns (relief, the cable, the sector's edge) before that."""
    setup = _setup("cable_survey", **NO_GATE, **{"platform.altitude_m": altitude_m})
    far = [ch for ch in setup.model.instrument.channels if ch.gated][0]
    nadir_s = 2.0 * altitude_m / setup.model.water.speed_m_s
    assert nadir_s - 40e-9 < far.gate_delay_s <= nadir_s - GATE_LEAD_S
    span = echo_span(setup.target, setup.trajectory, setup.scanner, setup.model.water.speed_m_s, setup.first_slot,
                     setup.end_slot)
    close = far.gate_delay_s + far.gate_width_s
    assert far.gate_delay_s <= span.near_s - GATE_LEAD_S + 1e-9
    assert span.far_s + setup.model.instrument.pulse.duration_s + GATE_LAG_S <= close + 1e-9
    assert setup.config.instrument.gate_delay_ns == pytest.approx(far.gate_delay_s * 1e9)  # the summary states it


def test_a_gate_that_shuts_out_the_echoes_draws_a_warning_naming_the_key():
    """mine_field flies at 4 m, its echoes arrive at about 36 ns: a gate opened at 100 ns (the pond's) shuts them
    out of the far channel."""
    config = load_scene("mine_field").with_overrides({"instrument.gate_delay_ns": 100, "instrument.gate_width_ns": 400})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        PassSetup.build(config, PassOptions(max_pulses=100, progress=False))
    messages = [str(w.message) for w in caught if issubclass(w.category, SetupWarning)]
    assert any(m.startswith("instrument.gate_delay_ns = 100: ") and "before it opens" in m for m in messages), messages


def test_the_shipped_surveys_gates_hold_their_echoes_and_the_tank_tests_are_told_theirs_do_not():
    """The gates the shipped surveys set by hand hold their echoes: no warning. The tank scenes keep the paper's
    experiment gates (pool 150 ns, pond 100 ns), which open after their panel's echo (63 and 91 ns): the far
    channel sees nothing there, and the pass says so."""
    for name in ("cable_survey", "mine_field", "seabed_lawnmower"):
        _setup(name)
    for name in ("pool_panel", "pond_panel"):
        with pytest.warns(SetupWarning, match=r"^instrument.gate_delay_ns = 1[05]0: .* shuts out 100% of the echoes"):
            PassSetup.build(load_scene(name), PassOptions(max_pulses=10, progress=False))


@pytest.mark.slow
def test_turbid_water_without_a_gate_loses_almost_nothing_outside_the_gate_at_4_and_8_m(tmp_path):
    """The acceptance: a scene with no gate in turbid water, run by the coverage study at 4 and 8 m, has gaps
    caused by the gate over under 5 % of the area its beams reach (the pond's 100 ns gate, the instrument's own,
    shut out nearly everything at 4 m: the rule is what saves it)."""
    config = load_scene("cable_survey").with_overrides({**NO_GATE, "water": "turbid_harbor"})
    study = run_study(config, StudyPlan(("scene",), (4.0, 8.0), ("mul2023",)), tmp_path, max_pulses=20000,
                      render=False, progress=False)
    for record in study["records"]:
        reached = record["reached_area_m2"]
        assert reached > 20.0
        assert record["gaps_m2"]["outside_gate"] < 0.05 * reached, record
    delays = [r["settings"]["gate_delay_ns"] for r in study["records"]]
    assert delays[0] < delays[1] and np.all(np.asarray(delays) < 100.0)
