"""Values in plausible but wrong units (scanner_sim/config/unit_slips.py): a warning naming the key and the slip,
and none for the shipped scenes."""

import warnings

import pytest

from scanner_sim.config import load_scene
from scanner_sim.config.errors import SetupWarning
from scanner_sim.config.loading import shipped_scenes
from scanner_sim.config.unit_slips import warn_unit_slips
from scanner_sim.survey.setup import PassOptions, PassSetup


def _caught(config) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_unit_slips(config)
    return [str(w.message) for w in caught if issubclass(w.category, SetupWarning)]


@pytest.mark.parametrize("key, value, slip", [
    ("scanner.sector_deg", 1.5708, "radians? (1.5708 rad would be 90 deg)"),
    ("instrument.gate_delay_ns", 3.5e-8, "seconds? (3.5e-08 s would be 35 ns)"),
    ("instrument.gate_width_ns", 4e-7, "seconds? (4e-07 s would be 400 ns)"),
    ("instrument.pulse_width_ns", 1e-8, "seconds? (1e-08 s would be 10 ns)"),
    ("instrument.pulse_energy_j", 500.0, "millijoules or microjoules?"),
    ("instrument.fov_full_rad", 3.0, "degrees or milliradians?"),
    ("instrument.beam_divergence_full_rad", 2.0, "degrees or milliradians?"),
])
def test_a_value_in_another_unit_draws_a_warning_naming_the_key(key, value, slip):
    """Radians in a _deg key, seconds in a _ns key, millijoules read as joules, degrees in a _rad key: each validates
    (the value is positive) and would run, so only a warning can catch it."""
    if key.startswith("instrument.gate"):
        changes = {"instrument.gate_delay_ns": 35, "instrument.gate_width_ns": 400, key: value}
    else:
        changes = {key: value}
    messages = _caught(load_scene("cable_survey").with_overrides(changes))
    assert len(messages) == 1 and messages[0].startswith(f"{key} = {value:g}: ") and slip in messages[0], messages


def test_the_shipped_scenes_and_their_plausible_neighbours_draw_none():
    for name in shipped_scenes():
        assert _caught(load_scene(name)) == [], name
    plausible = {"scanner.sector_deg": 2.5, "instrument.gate_delay_ns": 0.5, "instrument.pulse_energy_j": 0.01,
                 "instrument.fov_full_rad": 0.5}
    assert _caught(load_scene("cable_survey").with_overrides(plausible)) == []


def test_the_pass_set_up_warns_and_still_runs():
    config = load_scene("cable_survey").with_overrides({"scanner.sector_deg": 1.2})
    with pytest.warns(SetupWarning, match=r"^scanner.sector_deg = 1.2: under 2 degrees: radians\?"):
        setup = PassSetup.build(config, PassOptions(max_pulses=100, progress=False))
    assert setup.config.scanner.sector_deg == 1.2
