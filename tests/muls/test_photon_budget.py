"""The signal chain's absolute numbers, each computed here by hand from Table 1 (MULS Eqs. 7, 12, 13 and
the shot noise of the PMT), so that a factor anywhere in the chain (1.5 on Eq. 12, on the noise bandwidth,
on the excess-noise factor) fails a test.

Table 1 and section 3: E_t 500 uJ, A_r 4.4e-3 m^2, eta_o 0.6, split 2:98, voltage split 9:1, S_k 77 mA/W,
R_L 50 ohm, 10 bits, V_d 1 V (assumption), B 200 MHz (first-order low-pass), gains 2000 / 20000 (section
4.2), F 1.2 (assumption), e = 1.602176634e-19 C, h nu at 532 nm = 3.7339e-19 J.
"""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from muls import Channel, mul2023, water_preset
from muls.instrument.channels import ChannelArrays, noise_bandwidth_hz, shot_noise_lsb2_per_w
from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.photon_budget import channel_budget, quantum_efficiency
from muls.simulate import simulate

# --- by hand -----------------------------------------------------------------------------------------------
# V/W of Eq. 12: xi_i xi_v S_k M R_L
CH1_V_PER_W = 0.02 * 0.9 * 0.077 * 2000 * 50  # 138.6
CH2_V_PER_W = 0.02 * 0.1 * 0.077 * 2000 * 50  # 15.4
CH3_V_PER_W = 0.98 * 1.0 * 0.077 * 20000 * 50  # 75,460
# LSB/W of Eq. 13: 2^10 codes per 1 V
CH1_LSB_PER_W, CH2_LSB_PER_W, CH3_LSB_PER_W = 141_926.4, 15_769.6, 77_271_040.0
# Noise bandwidth of a first-order low-pass of 3 dB bandwidth 200 MHz: pi/2 x 200 MHz
NOISE_BANDWIDTH_HZ = 314_159_265.4
# Shot-noise variance per LSB of signal, sigma^2 / level = 2 e B_n F M xi_v R_L x 1024 [LSB]:
#   CH1: 2 x 1.602177e-19 = 3.204354e-19; x 3.141593e8 = 1.006672e-10; x 1.2 = 1.208006e-10; x 2000
#   = 2.416012e-7; x 0.9 x 50 = 1.087206e-5; x 1024 = 0.0111330
CH1_SHOT_LSB2_PER_LSB = 0.0111330
CH2_SHOT_LSB2_PER_LSB = CH1_SHOT_LSB2_PER_LSB / 9.0  # xi_v 0.1 instead of 0.9
CH3_SHOT_LSB2_PER_LSB = 0.0111330 * (20000 / 2000) * (1.0 / 0.9)  # gain 20000, xi_v 1
# Photoelectrons per LSB.ns of a CH1 echo: a photoelectron's charge e M through xi_v R_L gives
# e M xi_v R_L = 1.4418e-14 V s = 0.014764 LSB ns, so 67.73 photoelectrons make 1 LSB ns.
CH1_PE_PER_LSB_NS = 67.73
# Quantum efficiency of a 77 mA/W cathode at 532 nm: S_k h nu / e = 0.077 x 3.7339e-19 / 1.602177e-19
QE_532 = 0.17945

#: The pond under the paper's Eq. 6 (single scattering): the tests of the noise chain need its strong, smooth column.
PAPER_POND = water_preset("pond").with_models(attenuation_model="k_lidar")


def test_gains_in_volts_and_codes_per_watt_are_table_1():
    ins = mul2023()
    for name, v in (("ch1", CH1_V_PER_W), ("ch2", CH2_V_PER_W), ("ch3", CH3_V_PER_W)):
        assert ins.channel(name).volts_per_watt == pytest.approx(v, rel=1e-12)
    arrays = ChannelArrays.of(ins)
    np.testing.assert_allclose(arrays.lsb_per_w[1:], [CH1_LSB_PER_W, CH2_LSB_PER_W, CH3_LSB_PER_W], rtol=1e-12)


def test_noise_bandwidth_is_pi_over_2_of_the_3db_bandwidth():
    """The equivalent noise bandwidth of |H|^2 = 1 / (1 + (f/B)^2), integrated numerically to 1e4 B."""
    assert noise_bandwidth_hz(200e6) == pytest.approx(NOISE_BANDWIDTH_HZ, rel=1e-9)
    f = np.linspace(0.0, 1e4, 2_000_001)
    integral = np.trapezoid(1.0 / (1.0 + f**2), f) + 1e-4  # tail beyond 1e4 B: int 1/f^2 = 1e-4
    assert noise_bandwidth_hz(1.0) == pytest.approx(integral, rel=1e-6)


def test_shot_noise_per_code_of_signal_is_the_hand_value():
    ins = mul2023()
    dig = ins.digitizer
    for name, lsb, expected in (("ch1", CH1_LSB_PER_W, CH1_SHOT_LSB2_PER_LSB), ("ch2", CH2_LSB_PER_W, CH2_SHOT_LSB2_PER_LSB),
                                ("ch3", CH3_LSB_PER_W, CH3_SHOT_LSB2_PER_LSB)):
        got = shot_noise_lsb2_per_w(ins.channel(name), dig.bandwidth_hz, dig.lsb_per_volt) / lsb
        assert got == pytest.approx(expected, rel=1e-4), name


def test_shot_noise_scales_with_the_excess_noise_factor():
    """F enters the variance once: a tube with F = 1.8 has 1.5 times the variance of one with 1.2."""
    ch = mul2023().channel("ch1")
    dig = mul2023().digitizer
    ratio = shot_noise_lsb2_per_w(replace(ch, excess_noise=1.8), dig.bandwidth_hz, dig.lsb_per_volt) / \
        shot_noise_lsb2_per_w(ch, dig.bandwidth_hz, dig.lsb_per_volt)
    assert ratio == pytest.approx(1.5, rel=1e-12)


def test_photoelectrons_per_code_and_quantum_efficiency():
    """An echo of N photoelectrons in PMT1 gives N / 67.73 LSB ns in CH1: checked on the noise-free record."""
    assert quantum_efficiency(0.077, 532e-9) == pytest.approx(QE_532, rel=1e-4)
    ins = mul2023().with_channel("ch3", gate_delay_s=None, gate_width_s=None)
    water = water_preset("pool")
    model = OpticalModel.build(ins, water)
    z, rho = 12.0, 0.05
    photons, budget = channel_budget(model, z, rho)
    rec = [simulate(model, PulseBatch.flat_target(ins, [z], r), seed=1, mode="full", keep_noise_free=True,
                    noise=False)[0].noise_free_lsb[0, 0].astype(float) for r in (rho, 0.0)]
    area_lsb_ns = (rec[0] - rec[1]).sum() * 1.0  # 1 ns samples
    assert budget["ch1"]["photoelectrons"] / area_lsb_ns == pytest.approx(CH1_PE_PER_LSB_NS, rel=3e-3)
    assert budget["ch1"]["photoelectrons"] == pytest.approx(photons * 0.6 * 0.02 * QE_532, rel=1e-4)


def test_echo_energy_in_codes_by_hand_from_eq7():
    """A 0.1 plate at 12 m in the pool: Eq. 7 with Eq. 6's k_lidar worked by hand, times CH2's LSB/W."""
    w0 = 0.006 / 0.056
    k = 0.056 * (0.19 * (1.0 - w0)) ** (w0 / 2.0)  # Eq. 6: 0.050923
    assert k == pytest.approx(0.050923, rel=1e-4)
    energy = 500e-6 * 4.4e-3 * (0.1 / math.pi) * 0.9 * 0.6 * (1 - 0.0039) ** 2 * math.exp(-2 * k * 12.0) / 144.0
    ins = mul2023().with_channel("ch3", gate_delay_s=None, gate_width_s=None)
    model = OpticalModel.build(ins, water_preset("pool").with_models(attenuation_model="k_lidar"))
    rec = [simulate(model, PulseBatch.flat_target(ins, [12.0], r), seed=1, mode="full", keep_noise_free=True,
                    noise=False)[0].noise_free_lsb[0, 1].astype(float) for r in (0.1, 0.0)]
    area_lsb_s = (rec[0] - rec[1]).sum() * 1e-9
    assert area_lsb_s == pytest.approx(energy * CH2_LSB_PER_W, rel=2e-3)


def test_record_noise_is_dark_plus_hand_shot_plus_rounding():
    """On the pond's column, CH1's residual variance is 1 + 0.0111330 x level + 1/12 [LSB^2] (hand value). The column of
    Eq. 6's k_lidar gives a few thousand samples of a few hundred LSB to test on."""
    ins = mul2023()
    model = OpticalModel.build(ins, PAPER_POND)
    batch = PulseBatch.flat_target(ins, np.full(400, 30.0), pulse_id=np.arange(400))
    rec, _ = simulate(model, batch, seed=11, mode="full", keep_noise_free=True)
    clean = rec.noise_free_lsb[:, 0, :].astype(float)
    level = clean - 8.0
    var = 1.0 + CH1_SHOT_LSB2_PER_LSB * level + 1.0 / 12.0
    strong = (level > 300.0) & (clean < 1023 - 8 * np.sqrt(var))
    assert strong.sum() > 2000
    z = (rec.codes[:, 0, :].astype(float) - clean)[strong] / np.sqrt(var[strong])
    assert z.var() == pytest.approx(1.0, abs=0.05)


def test_one_pmt_one_shot_noise_draw_split_between_its_outputs():
    """Two outputs of one tube carry the same shot noise, so their residuals correlate as
    <s_a s_b> / sqrt(<s_a^2 + 1/12> <s_b^2 + 1/12>) (shot sigmas s, rounding 1/12, no dark noise); channels
    of other tubes (two more, so the draws of a second pair of tubes are used too) do not correlate, and each
    carries its own tube's full shot variance, independent of the channels' dark noise (c has 1 LSB of it)."""
    base = mul2023()
    chans = (Channel("a", "pmt1", split_ratio=0.02, voltage_ratio=0.6, gain=2000.0, dark_std_lsb=0.0),
             Channel("b", "pmt1", split_ratio=0.02, voltage_ratio=0.3, gain=2000.0, dark_std_lsb=0.0),
             Channel("c", "pmt2", split_ratio=0.02, voltage_ratio=0.6, gain=2000.0, dark_std_lsb=1.0),
             Channel("d", "pmt3", split_ratio=0.02, voltage_ratio=0.6, gain=2000.0, dark_std_lsb=0.0))
    ins = replace(base, channels=chans)
    model = OpticalModel.build(ins, PAPER_POND)
    batch = PulseBatch.flat_target(ins, np.full(1200, 30.0), pulse_id=np.arange(1200))
    rec, _ = simulate(model, batch, seed=5, mode="full", keep_noise_free=True)
    clean = rec.noise_free_lsb.astype(float)
    level = clean[:, 0, :] - 8.0
    keep = (level > 200.0) & (clean[:, 0, :] < 1000.0)
    assert keep.sum() > 2000
    resid = rec.codes.astype(float) - clean
    a, b, c, d = (resid[:, j, :][keep] for j in range(4))
    # shot variance of an output: 2 e B_n F M xi_v R_L x 1024 per LSB of its level (CH1's value scaled by xi_v)
    s_a = np.sqrt(CH1_SHOT_LSB2_PER_LSB * (0.6 / 0.9) * level[keep])
    s_b = np.sqrt(CH1_SHOT_LSB2_PER_LSB * (0.3 / 0.9) * 0.5 * level[keep])  # half a's level
    expected = np.mean(s_a * s_b) / math.sqrt(np.mean(s_a**2 + 1 / 12) * np.mean(s_b**2 + 1 / 12))
    assert np.corrcoef(a, b)[0, 1] == pytest.approx(expected, abs=0.02)
    for other, dark in ((a, 0.0), (c, 1.0), (d, 0.0)):  # c and d see what a sees, through tubes of their own
        assert other.var() == pytest.approx(np.mean(s_a**2 + 1 / 12) + dark, rel=0.05)
    assert max(abs(np.corrcoef(a, c)[0, 1]), abs(np.corrcoef(a, d)[0, 1]), abs(np.corrcoef(c, d)[0, 1])) < 0.03


# --- the photon budget of the study points (muls budget) ------------------------------------------------------

def test_photons_at_the_aperture_by_hand_from_eq7():
    """A 0.1 panel at 9 m in the pool, Eq. 6's k_lidar (0.050923, by hand above), full overlap: photons reaching
    the aperture are Eq. 7 without the receiver's eta_o, over h nu = 3.7339e-19 J."""
    from muls.studies import budget_study

    energy = 500e-6 * 4.4e-3 * (0.1 / math.pi) * 0.9 * (1 - 0.0039) ** 2 * math.exp(-2 * 0.050923 * 9.0) / 81.0
    r = budget_study("k_lidar", waters=(), ranges_m=())
    case = next(c for c in r["cases"] if c["study"] == "pool" and c["range_m"] == 9.0)
    assert case["photons_at_aperture"] == pytest.approx(energy / 3.7339e-19, rel=1e-3)
    ch1 = case["channels"]["ch1"]
    assert ch1["photoelectrons"] == pytest.approx(case["photons_at_aperture"] * 0.6 * 0.02 * QE_532, rel=1e-3)
    assert set(ch1) >= {"photoelectrons", "peak_lsb", "noise_lsb", "snr", "detectable"}
    assert set(ch1["noise_lsb"]) == {"dark", "shot", "total"}


def test_photon_limited_snr_does_not_depend_on_the_gain():
    """Shot noise and signal both scale with the PMT gain: their ratio is fixed by the photoelectrons alone,
    while the SNR over the dark noise grows with the gain."""
    from muls.presets import mul2023

    water = water_preset("pond")
    low, high = (OpticalModel.build(mul2023(gain_pmt1=m), water) for m in (2000.0, 20000.0))
    _, a = channel_budget(low, 9.0, 0.1)
    _, b = channel_budget(high, 9.0, 0.1)
    assert a["ch1"]["photon_limited_snr"] == pytest.approx(b["ch1"]["photon_limited_snr"], rel=1e-9)
    assert a["ch1"]["photoelectrons"] == pytest.approx(b["ch1"]["photoelectrons"], rel=1e-12)
    assert b["ch1"]["snr"] > a["ch1"]["snr"]
    # CH1 and CH2 share PMT1's photoelectrons and its shot noise: the same photon-limited SNR
    assert a["ch1"]["photon_limited_snr"] == pytest.approx(a["ch2"]["photon_limited_snr"], rel=1e-9)


def test_budget_json_lists_what_exceeds_the_photon_budget(capsys):
    from muls.cli import main

    assert main(["budget", "--json"]) == 0
    r = json.loads(capsys.readouterr()[0])
    waters = {c["water"] for c in r["cases"]}
    assert waters == {"pond", "pool", "clean_ocean", "coastal_ocean", "turbid_harbor"}
    assert sorted({c["range_m"] for c in r["cases"] if c["water"] == "clean_ocean"}) == [float(x) for x in range(5, 111, 5)]
    for row in r["beyond_the_budget"]:
        assert row["photons_needed_at_aperture"] > row["photons_at_aperture"]
        assert row["factor"] > 1.0
    # a photon-limited SNR under the threshold is exactly what 'beyond the budget' means
    for c in r["cases"]:
        for name in c["paper_ranged"]:
            b = c["channels"][name]
            listed = any(x["study"] == c["study"] and x["range_m"] == c["range_m"] and x["channel"] == name
                         for x in r["beyond_the_budget"])
            assert listed == (b["photon_limited_snr"] is not None and b["photon_limited_snr"] < 5.0)
