"""Background light (MULS Eqs. 8-10) reaches a pass through the scene key water.background_radiance_w_m2_sr_nm."""

import math

import pytest

from scanner_sim.config import ConfigError, load_scene
from scanner_sim.survey.setup import PassOptions, PassSetup

RADIANCE = 0.5  # L_b [W/(m^2 sr nm)]


def _chunk(radiance):
    """The pool panel (7 m, echo at ~63 ns, reflectance 0.1), the far channel gated open from 80 ns, full
    records: behind the panel the beam is stopped, so CH3 then reads its dark level plus the background."""
    config = load_scene("pool_panel").with_overrides({
        "water.background_radiance_w_m2_sr_nm": radiance, "survey.max_pulses": 200,
        "instrument.gate_delay_ns": 80, "instrument.gate_width_ns": 400})
    setup = PassSetup.build(config, PassOptions())
    return setup, setup.simulate_chunk(next(setup.slot_chunks()), whole_records=True)


def test_background_light_raises_the_far_channels_baseline_by_eqs_8_to_10():
    """After the panel's echo, with the gate open, CH3 reads its dark level plus the background.

    By hand from Table 1: A_r 4.4e-3 m^2, eta_o 0.6, filter 1 nm, FOV 0.1 rad (full), panel rho 0.1 at 7 m;
    CH3 converts 0.98 x 1 x 0.077 A/W x 20000 x 50 ohm x 1024 LSB/V = 7.727e7 LSB/W.
    """
    setup, lit = _chunk(RADIANCE)
    _, dark = _chunk(0.0)
    water = setup.model.water
    common = RADIANCE * 4.4e-3 * 0.6 * 1.0 * math.exp(-2.0 * water.two_way_attenuation_per_m * 7.0)
    power_w = common * 0.1 * 0.1**2 / 4 + common * water.beta_pi_per_m_sr * math.pi * 0.1**2 / 4  # Eqs. 9, 10, 8
    expected_lsb = power_w * 0.98 * 1.0 * 0.077 * 20000 * 50 * 1024
    t_ns = lit.waveforms.sample_times_s(setup.model)[0] * 1e9
    after_echo = (t_ns > 160) & (t_ns < 460)  # the bright echo's tail has decayed below 0.01 LSB by 160 ns
    ch3 = setup.model.instrument.channel_names.index("ch3")
    rise = lit.waveforms.codes[:, ch3, after_echo].mean() - dark.waveforms.codes[:, ch3, after_echo].mean()
    assert expected_lsb > 5.0  # a level the test can resolve
    assert rise == pytest.approx(expected_lsb, rel=0.05, abs=0.3)


def test_a_negative_background_names_its_key():
    with pytest.raises(ConfigError, match="water.background_radiance_w_m2_sr_nm"):
        load_scene("pool_panel").with_overrides({"water.background_radiance_w_m2_sr_nm": -1.0})
