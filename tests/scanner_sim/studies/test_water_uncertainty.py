"""Coverage as a band over a water's unknown phase function (scanner_sim/studies/water_uncertainty.py,
``scanner-sim coverage --water-uncertainty``) and the scene's ``water.phase_function``."""

import pytest

from muls.montecarlo import tables as tables_module
from muls.montecarlo.tables import table_packets
from muls.water.phase_family import SENSITIVITY_FAMILY, fournier_forand_member
from scanner_sim.config import load_scene
from scanner_sim.config.errors import ConfigError
from scanner_sim.studies import water_uncertainty
from scanner_sim.studies.coverage_study import StudyPlan, run_study

#: Quick table runs for the test (the command uses the standard tables for its passes).
TEST_PACKETS = 10_000


def test_a_scene_names_its_phase_function_beside_a_preset_and_a_bad_one_is_refused_by_key():
    scene = load_scene("cable_survey")
    spec = fournier_forand_member(0.005, "test").spec
    water = scene.with_overrides({"water.phase_function": spec}).water_model()
    assert water.phase_function == spec and scene.water_model().phase_function == "petzold"
    with pytest.raises(ConfigError, match="water.phase_function"):
        scene.with_overrides({"water.phase_function": "mie"})


@pytest.mark.slow
def test_coverage_band_of_the_turbid_cable_survey_at_4_m_orders_low_default_high(tmp_path, monkeypatch):
    """The pass with the weakest-echo phase function covers no more, and the strongest-echo one no less, than the
    default (the same seed, the same pulses): a stronger echo at the nadir range is detected at least as often
    everywhere across a 4 m swath. A few pulses a pass, quick tables, in this process."""
    monkeypatch.setattr(tables_module, "user_cache_dir", lambda: tmp_path / "tables")
    monkeypatch.setattr(water_uncertainty, "FAMILY", (SENSITIVITY_FAMILY[0], fournier_forand_member(0.005, "test"),
                                                      fournier_forand_member(0.025, "test")))
    monkeypatch.setattr(water_uncertainty, "RANKING_PACKETS", TEST_PACKETS)
    plan = StudyPlan(("turbid_harbor",), (4.0,), ("mul2023",), water_uncertainty=True)
    with table_packets(TEST_PACKETS):
        study = run_study(load_scene("cable_survey"), plan, tmp_path / "out", max_pulses=20_000, render=False,
                          progress=False)
    assert study["study"]["water_uncertainty"] is True and study["study"]["phase_function"] == "petzold (default)"
    (record,) = study["records"]
    band = record["water_uncertainty"]
    assert band["low_member"]["label"] == "FF b_b/b 0.025" and band["high_member"]["label"] == "FF b_b/b 0.005"
    for key in ("covered_fraction", "order_1a_fraction"):
        low, default, high = band[key]
        assert low <= default <= high, (key, band[key])
    assert band["covered_fraction"][1] == record["covered_fraction"]
