"""The studies of muls.studies: documented keys, JSON-ready output, and physics that would fail if wrong."""

import json
import math

import numpy as np
import pytest

from muls import studies
from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.presets import POND_GATE_S, POOL_GATE_S, water_preset
from muls.ranging.peaks import Peaks
from muls.simulate import simulate

MAXRANGE_KEYS = {"single_channel_m", "near_field_m", "far_field_m", "total_m", "improvement"}
CHANNEL_KEYS = {"precision_m", "mean_deviation_m", "detected_fraction", "saturated_fraction"}


def _json_roundtrip(result):
    """The result must serialise as strict JSON (no NaN, no numpy scalars)."""
    return json.loads(json.dumps(result, allow_nan=False))


# --- helpers ----------------------------------------------------------------------------------------------

def test_far_gate_opens_20_to_30_ns_before_the_echo():
    c_w = water_preset("clean_ocean").speed_m_s
    ranges = np.linspace(4.0, 100.0, 500)
    lead = 2.0 * ranges / c_w - studies.far_gate_delay_s(ranges, c_w)
    assert np.all(lead >= 20e-9 - 1e-15) and np.all(lead < 30e-9 + 1e-15)
    assert studies.far_gate_delay_s(1.0, c_w) == 0.0  # never negative


def test_detections_pick_the_closest_detecting_peak_per_pulse_and_channel():
    peaks = Peaks(pulse=np.array([0, 0, 0, 2]), channel=np.array([1, 1, 3, 1]),
                  time_s=np.zeros(4), range_m=np.array([4.0, 5.1, 5.0, 7.3]), amplitude_lsb=np.ones(4),
                  snr=np.ones(4), saturated=np.array([False, True, False, False]), peak_power_w=np.ones(4),
                  echo_index=np.arange(4))
    truth = np.array([5.0, 6.0, 7.0])
    err, sat = studies.detections(peaks, truth, 0.5, (1,))
    np.testing.assert_allclose(err[[0, 2]], [0.1, 0.3])
    assert math.isnan(err[1]) and sat.tolist() == [True, False, False]
    err_all, _ = studies.detections(peaks, truth, 0.5)
    assert err_all[0] == 0.0
    # beyond the tolerance: an unclipped peak is not the target, a clipped one the echo explains is
    err, _ = studies.detections(peaks, truth, 0.2, (1,))
    assert np.isnan(err[2]) and err[0] == pytest.approx(0.1)
    err, sat = studies.detections(peaks, truth, 0.01, (1,))
    assert err[0] == pytest.approx(0.1) and sat[0]
    # a clipped peak no echo explains (the water column's plateau) is not the target
    orphan = Peaks(**{**peaks.__dict__, "echo_index": np.array([0, -1, 2, 3])})
    err, _ = studies.detections(orphan, truth, 0.01, (1,))
    assert np.isnan(err[0])


def test_experiment_gates():
    assert studies.experiment_gate_s("pond") == POND_GATE_S
    assert studies.experiment_gate_s("pool") == POOL_GATE_S
    assert studies.experiment_gate_s("coastal_ocean") == POND_GATE_S


# --- waveform ---------------------------------------------------------------------------------------------

def test_waveform_study_keys_shapes_and_gate():
    r = _json_roundtrip(studies.waveform_study("pond", 11.5, seed=3))
    n = len(r["time_ns"])
    assert set(r["channels"]) == {"ch0", "ch1", "ch2", "ch3"} == set(r["noise_free"])
    assert all(len(v) == n for v in list(r["channels"].values()) + list(r["noise_free"].values()))
    assert r["settings"]["gate_delay_ns"] == pytest.approx(100.0) and r["settings"]["gate_width_ns"] == pytest.approx(400.0)
    t = np.array(r["time_ns"])
    ch3 = np.array(r["noise_free"]["ch3"])
    dark = ch3[0]
    # CH3 is gated: only its dark level before the gate opens, signal (column + echo) inside it.
    assert np.all(ch3[t < 99.0] == pytest.approx(dark))
    assert ch3[(t > 100.0) & (t < 130.0)].max() > dark + 5.0  # five times the dark noise
    # The noisy record scatters around the noise-free one (dark noise ~1 LSB far from any signal).
    tail = t > 700.0
    assert abs(np.mean(np.array(r["channels"]["ch1"])[tail]) - np.mean(np.array(r["noise_free"]["ch1"])[tail])) < 0.3
    assert studies.waveform_study("pool", 3.0)["settings"]["gate_delay_ns"] == pytest.approx(150.0)


def test_waveform_study_echo_arrives_at_the_time_of_flight():
    """In clear water the CH1 echo of a panel at 9 m peaks 2R/c_w (+ the pulse's own peak delay) in."""
    r = studies.waveform_study("pool", 9.0, seed=1)
    t = np.array(r["time_ns"])
    ch1 = np.array(r["noise_free"]["ch1"])
    c_w = water_preset("pool").speed_m_s
    t_echo = 2e9 * 9.0 / c_w
    window = (t > t_echo - 10) & (t < t_echo + 30)
    assert t_echo < t[window][np.argmax(ch1[window])] < t_echo + 15.0


def test_waveform_study_rejects_bad_range():
    with pytest.raises(ValueError, match="range_m"):
        studies.waveform_study("pond", -1.0)
    with pytest.raises(ValueError, match="must be one of"):
        studies.waveform_study("mud", 5.0)


# --- precision --------------------------------------------------------------------------------------------

def test_precision_study_keys_and_ch1_precision_worsens_with_range():
    """At 4 and 5 m in the pond, where the Monte Carlo's attenuation leaves CH1 an echo well above its threshold
    (at the paper's 8.5-11.5 m it leaves less than the dark noise: docs/studies.md)."""
    r = _json_roundtrip(studies.precision_study("pond", [4.0, 5.0], shots=150, seed=2))
    assert set(r) == {"4", "5", "settings"}
    for key in ("4", "5"):
        for ch in ("ch1", "ch2", "ch3"):
            assert CHANNEL_KEYS <= set(r[key][ch])
            assert 0.0 <= r[key][ch]["detected_fraction"] <= 1.0
    p4, p5 = r["4"]["ch1"]["precision_m"], r["5"]["ch1"]["precision_m"]
    assert p4 is not None and p5 is not None
    assert p5 > p4  # lower SNR farther away (paper section 4.2)
    # Detections lie within the 3-bin tolerance, so the mean deviation does too.
    tol = r["settings"]["tolerance_m"]
    assert abs(r["4"]["ch1"]["mean_deviation_m"]) < tol


def test_precision_study_null_when_nothing_is_detected():
    """CH3's pond gate opens at 100 ns, after the echo of a panel at 8.5 m (77 ns): nothing to range."""
    r = _json_roundtrip(studies.precision_study("pond", [8.5], shots=50))
    assert r["8.5"]["ch3"]["detected_fraction"] == 0.0
    assert r["8.5"]["ch3"]["precision_m"] is None and r["8.5"]["ch3"]["saturated_fraction"] is None


def test_precision_study_is_repeatable_from_its_seed():
    a = studies.precision_study("pond", [4.5], shots=60, seed=7)
    b = studies.precision_study("pond", [4.5], shots=60, seed=7)
    c = studies.precision_study("pond", [4.5], shots=60, seed=8)
    assert a == b
    assert a["4.5"]["ch1"] != c["4.5"]["ch1"]


# --- coaxial ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("water", ["clean_ocean", "coastal_ocean", "turbid_harbor"])
def test_coaxial_backscatter_exceeds_non_coaxial(water):
    r = _json_roundtrip(studies.coaxial_study(water))
    assert {"peak_ratio", "time_ns", "coaxial_w", "non_coaxial_w", "settings"} <= set(r)
    assert r["peak_ratio"] > 1.0
    t = np.array(r["time_ns"]) * 1e-9
    non = np.array(r["non_coaxial_w"])
    co = np.array(r["coaxial_w"])
    # Before the pulse reaches the blind-zone edge Z1 (overlap 0) only multiply scattered light reaches the
    # non-coaxial receiver: a few hundredths of what the coaxial one sees there at most.
    z1 = r["settings"]["blind_zone_m"]
    blind = t < 2.0 * z1 / water_preset(water).speed_m_s
    assert np.all(non[blind] <= 0.05 * co[blind])
    # (Long after the near field the two Monte Carlo runs, one per receiver, differ by their statistical error at
    # 1e-6 of the peak and less: test_under_single_scattering_... compares the late columns.)
    late = studies.coaxial_study(water, t_max_ns=300.0)
    t = np.array(late["time_ns"])
    co, non = np.array(late["coaxial_w"]), np.array(late["non_coaxial_w"])
    assert np.all(co[t < 30.0] >= non[t < 30.0])


def test_under_single_scattering_the_blind_zone_is_dark_and_late_columns_agree():
    """Eq. 4 (the paper's k_lidar, single scattering): the non-coaxial column is exactly dark before Z1, and long
    after full overlap both designs see the same column."""
    r = studies.coaxial_study("coastal_ocean", t_max_ns=300.0, attenuation_model="k_lidar")
    t = np.array(r["time_ns"]) * 1e-9
    co, non = np.array(r["coaxial_w"]), np.array(r["non_coaxial_w"])
    assert np.all(non[t < 2.0 * r["settings"]["blind_zone_m"] / water_preset("coastal_ocean").speed_m_s] == 0.0)
    np.testing.assert_allclose(non[t >= 200e-9], co[t >= 200e-9], rtol=1e-5)


def test_coaxial_ratio_grows_with_turbidity():
    ratios = [studies.coaxial_study(w)["peak_ratio"] for w in ("clean_ocean", "coastal_ocean", "turbid_harbor")]
    assert ratios[0] < ratios[1] < ratios[2]


# --- maximum range ----------------------------------------------------------------------------------------

@pytest.mark.slow
def test_maxrange_study_orders_waters_and_channels():
    """Clearer water reaches farther in every group. In the turbid harbor the Monte Carlo's column clips the gated
    CH3 wherever its gate opens before an echo it could see, so the harbor has no far-field range."""
    r = _json_roundtrip(studies.maxrange_study(shots=60, seed=1))
    waters = ("clean_ocean", "coastal_ocean", "turbid_harbor")
    for w in waters:
        assert MAXRANGE_KEYS <= set(r[w])
        assert all(r[w][k] is not None for k in MAXRANGE_KEYS if not (w == "turbid_harbor" and k == "far_field_m"))
        assert r[w]["total_m"] >= r[w]["single_channel_m"]
        assert r[w]["improvement"] == pytest.approx(r[w]["total_m"] / r[w]["single_channel_m"], abs=1e-3)
        # total (chosen returns) reaches as far as the better of the near and far fields, to the fine step.
        best = max(v for v in (r[w]["near_field_m"], r[w]["far_field_m"]) if v is not None)
        assert abs(r[w]["total_m"] - best) <= studies.FINE_STEP_M + 1e-9
    assert r["turbid_harbor"]["far_field_m"] is None
    for key in ("single_channel_m", "total_m", "near_field_m"):
        assert r["clean_ocean"][key] > r["coastal_ocean"][key] > r["turbid_harbor"][key]
    assert r["clean_ocean"]["far_field_m"] > r["coastal_ocean"]["far_field_m"]
    assert r["clean_ocean"]["near_field_m"] < r["clean_ocean"]["far_field_m"]
    assert r["settings"]["shots"] == 60


def test_maxrange_study_one_water_small():
    """Coastal water: the gated CH3 reaches beyond the near channels. In the pond and the turbid harbour the Monte
    Carlo's column (with Petzold's backscatter in the pond, which has no measured beta(pi)) clips CH3 wherever its
    gate opens before an echo it could see: no far-field range at all, the total is the near field's."""
    r = studies.maxrange_study(["coastal_ocean", "pond"], shots=20, seed=0)
    assert r["pond"]["far_field_m"] is None and r["pond"]["total_m"] == r["pond"]["near_field_m"]
    t = r["coastal_ocean"]
    assert MAXRANGE_KEYS <= set(t) and set(r) == {"coastal_ocean", "pond", "settings"}
    assert t["far_field_m"] > t["near_field_m"]
    # The edge is resolved to the fine step: the next fine range fails the 90 % criterion.
    curves = t["curves"]
    ranges = np.array(curves["range_m"])
    assert np.all(np.diff(ranges) > 0)
    beyond = ranges > t["far_field_m"] + 1e-9
    assert np.all(np.array(curves["far"])[beyond] < 0.9)
    assert np.min(ranges[beyond]) - t["far_field_m"] <= studies.FINE_STEP_M + 1e-9


def test_maxrange_rejects_bad_shots():
    with pytest.raises(ValueError, match="shots"):
        studies.maxrange_study(shots=0)


# --- bench ------------------------------------------------------------------------------------------------

def test_bench_study_keys_small():
    r = _json_roundtrip(studies.bench_study(pulses=2000, full_pulses=200, repeats=1))
    assert r["windowed_pulses_per_s"] > 0 and r["full_record_pulses_per_s"] > 0
    assert {"cpu_count", "numba_threads", "loadavg_1_5_15"} <= set(r["machine"])
    assert r["windowed"]["pulses"] == 2000 and r["full_record"]["pulses"] == 200


def test_maxrange_gains_as_a_designer_sets_them():
    """The single channel and PMT1 (through CH2) get the highest gain that keeps the water column unclipped,
    CH1 is CH2's tube (nine times CH2 by the 9:1 split), PMT2 runs at 20,000; each group names its limit."""
    from muls.photon_budget import LIMITS
    from muls.presets import designed_mul, single_channel, study_water

    r = studies.maxrange_study(["turbid_harbor"], shots=20, seed=0, attenuation_model="k_lidar")
    t = r["turbid_harbor"]
    water = study_water("turbid_harbor", "k_lidar")
    assert t["gains"]["single"] == pytest.approx(single_channel(water).channels[0].gain)
    mul = designed_mul(water)
    assert t["gains"]["pmt1"] == pytest.approx(mul.channel("ch2").gain) == pytest.approx(mul.channel("ch1").gain)
    assert mul.channel("ch1").volts_per_watt == pytest.approx(9.0 * mul.channel("ch2").volts_per_watt)
    assert t["gains"]["pmt2"] == 20000.0
    # the column fits in CH2: its noise-free peak stays under the rule's ceiling (top code - 5 sigma), and ends within
    # a few codes of it below the cap, checked on the record of a pulse meeting nothing
    model = OpticalModel.build(mul, water)
    rec, _ = simulate(model, PulseBatch.flat_target(mul, np.full(32, np.inf)), seed=0, mode="full",
                      keep_noise_free=True, noise=False)
    top = float(rec.noise_free_lsb[:, 1, :].max())
    headroom = 1023.0 - 5.0 * math.sqrt(1.0 + 0.0111330 / 9.0 * t["gains"]["pmt1"] / 2000.0 * top) - top
    assert headroom >= -3.0
    if t["gains"]["pmt1"] < 20000.0:
        assert headroom == pytest.approx(0.0, abs=3.0)
    for group in ("single", "near", "far", "total"):
        assert t["limits"][group]["cause"] in LIMITS
    assert study_water("turbid_harbor").attenuation_model == "monte_carlo"
