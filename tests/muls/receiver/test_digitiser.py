"""Digitiser (Eqs. 12, 13), noise statistics, ranging (Eq. 14), channel choice, dropout causes, record modes.

The instrument's processing is tested on echoes of known strength: the waters here use the paper's Eq. 6 with single
scattering (:func:`paper_water`), whose echoes and columns the cases were built around; the product's physics (the
Monte Carlo's attenuation, spread and column) has tests of its own (tests/muls/optics/test_scattering.py)."""

import numpy as np
import pytest
from conftest import detection_model as _model

from muls import mul2023
from muls.instrument.channels import shot_noise_lsb2_per_w
from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.simulate import simulate


def test_quantisation_rounds_and_clipping_saturates():
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, [3.0, 25.0])
    rec, _ = simulate(model, batch, seed=2, mode="full", keep_noise_free=True, noise=False)
    top = model.instrument.digitizer.max_code
    expected = np.clip(np.floor(rec.noise_free_lsb.astype(float) + 0.5), 0, top)
    assert np.array_equal(rec.codes, expected.astype(np.uint16))
    assert rec.codes[0].max() == top  # the 3 m echo clips
    assert rec.codes.dtype == np.uint16 and rec.codes.min() >= 0



def test_shot_noise_variance_matches_its_formula():
    """Residuals over the noise-free record have variance dark^2 + 2 e B F M^2 S_k xi_i P (xi_v R_L)^2 + 1/12."""
    model = _model("pond")
    ins = model.instrument
    batch = PulseBatch.flat_target(ins, np.full(800, 30.0), pulse_id=np.arange(800))
    rec, _ = simulate(model, batch, seed=11, mode="full", keep_noise_free=True)
    ch = 0  # ch1 sees the column far above its dark noise; its clipped samples are left out
    channel = ins.channels[ch]
    clean = rec.noise_free_lsb[:, ch, :].astype(float)
    codes = rec.codes[:, ch, :].astype(float)
    power_w = (clean - channel.dark_mean_lsb) / (channel.volts_per_watt * ins.digitizer.lsb_per_volt)
    shot = shot_noise_lsb2_per_w(channel, ins.digitizer.bandwidth_hz, ins.digitizer.lsb_per_volt) * power_w
    strong = (shot > 4 * channel.dark_std_lsb**2) & (clean < ins.digitizer.max_code - 8 * np.sqrt(shot + 1))
    assert strong.sum() > 2000
    z = (codes - clean)[strong] / np.sqrt(channel.dark_std_lsb**2 + shot[strong] + 1 / 12)
    assert z.var() == pytest.approx(1.0, abs=0.05)
    assert abs(z.mean()) < 0.05



def test_record_modes_agree_on_detections_and_ranges():
    model = _model("coastal_ocean", (100e-9, 400e-9))
    rng = np.random.default_rng(4)
    batch = PulseBatch.flat_target(model.instrument, rng.uniform(1.0, 60.0, 300), rng.uniform(0.02, 0.5, 300))
    _, windowed = simulate(model, batch, seed=9, mode="windowed")
    _, full = simulate(model, batch, seed=9, mode="full")
    for field in ("pulse", "channel", "saturated"):
        assert np.array_equal(getattr(windowed.returns, field), getattr(full.returns, field)), field
    for field in ("range_m", "amplitude_lsb"):
        assert np.allclose(getattr(windowed.returns, field), getattr(full.returns, field), rtol=0, atol=1e-9), field
    assert np.array_equal(windowed.dropout_cause, full.dropout_cause)



def test_batching_does_not_change_results():
    model = _model("coastal_ocean")
    ranges = np.random.default_rng(5).uniform(2.0, 40.0, 200)
    whole = simulate(model, PulseBatch.flat_target(model.instrument, ranges), seed=21)[1]
    parts = [simulate(model, PulseBatch.flat_target(model.instrument, ranges[s], pulse_id=np.arange(200)[s]), seed=21)[1]
             for s in (slice(0, 77), slice(77, 200))]
    assert np.array_equal(whole.returns.range_m, np.concatenate([p.returns.range_m for p in parts]))
    assert np.array_equal(whole.dropout_cause, np.concatenate([p.dropout_cause for p in parts]))



def test_seed_changes_noise_but_not_noise_free_result():
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.full(50, 19.0))
    a = simulate(model, batch, seed=1)[1].returns.range_m
    b = simulate(model, batch, seed=2)[1].returns.range_m
    assert not np.array_equal(a, b)
    assert abs(a.mean() - b.mean()) < 0.02



def test_gate_closes_after_its_width():
    """CH3 open from 100 to 150 ns: a panel whose echo starts at 181 ns (20 m) leaves CH3 at its dark level."""
    model = _model("pool", (100e-9, 50e-9))
    rec, _ = simulate(model, PulseBatch.flat_target(model.instrument, np.full(8, 20.0)), seed=1, mode="full",
                      keep_noise_free=True, noise=False)
    t_ns = rec.sample_times_s(model) * 1e9
    ch3 = rec.noise_free_lsb[:, 2, :]
    assert np.all(ch3[t_ns >= 150.0] == pytest.approx(8.0))
    assert ch3[(t_ns > 100.0) & (t_ns < 150.0)].max() > 8.0  # the column inside the gate
    assert rec.noise_free_lsb[:, 1, :][(t_ns > 181.0) & (t_ns < 200.0)].max() > 20.0  # CH2 sees the echo



def test_channel_arrays_reference_slot_and_detectors():
    """Slot 0 is CH0: no gain, never gated, no shot noise, no detector; CH1 and CH2 share PMT1 (0), CH3 is 1."""
    from muls.instrument.channels import ChannelArrays

    arrays = ChannelArrays.of(mul2023())
    assert arrays.lsb_per_w[0] == 0.0 and arrays.shot_lsb2_per_w[0] == 0.0
    assert arrays.gate_open_s[0] == -np.inf and arrays.gate_close_s[0] == np.inf
    assert arrays.detector.tolist() == [-1, 0, 0, 1]
    assert arrays.gate_close_s[3] == pytest.approx(500e-9)
    assert arrays.signal().detector.tolist() == [0, 0, 1]



def test_digitise_defaults_and_records():
    """digitise adds noise unless told not to, keeps the noise-free record only when asked, records its mode,
    gives full records of CH0 in full mode, uses the reference's own dark level for CH0, and names a bad mode."""
    from dataclasses import replace

    from muls.receiver.digitiser import digitise

    base = _model()
    ins = replace(base.instrument, reference=replace(base.instrument.reference, dark_mean_lsb=20.0))
    model = OpticalModel.build(ins, base.water)
    batch = PulseBatch.flat_target(ins, np.full(4, 12.0))
    rec = digitise(model, batch, seed=3)
    assert rec.noise_free_lsb is None and rec.reference_noise_free_lsb is None and rec.mode == "windowed"
    quiet = digitise(model, batch, seed=3, noise=False, keep_noise_free=True)
    assert not np.array_equal(rec.codes, quiet.codes)  # noise is on by default
    full = digitise(model, batch, seed=3, mode="full", keep_noise_free=True, noise=False)
    assert full.mode == "full" and full.reference.shape == (4, ins.digitizer.n_samples)
    assert full.reference_noise_free_lsb.shape == full.reference.shape and full.noise_free_lsb.shape == full.codes.shape
    assert full.reference_noise_free_lsb[:, :5] == pytest.approx(20.0)  # before the pulse: CH0's own dark level
    # and after it: the emitted pulse has ended (a level left there survived the mutation run)
    after = full.reference_times_s(model)[0] >= ins.pulse.duration_s
    assert after.sum() > 100 and np.all(full.reference_noise_free_lsb[:, after] == 20.0)
    with pytest.raises(ValueError, match="record_mode"):
        digitise(model, batch, seed=3, mode="sparse")



@pytest.mark.parametrize("mode", ["windowed", "full"])
def test_noise_free_records_of_a_single_pulse_are_its_codes_before_rounding(mode):
    """With noise off, each code is its noise-free level rounded and clipped to [0, 1023] (Eq. 13), for CH0
    and every channel, also for a batch of one pulse in one window (what muls waveform and muls experiment
    draw their noise-free curves from)."""
    from muls.receiver.digitiser import digitise

    model = _model()
    for n in (1, 3):
        rec = digitise(model, PulseBatch.flat_target(model.instrument, np.full(n, 3.0)), seed=2, mode=mode,
                       keep_noise_free=True, noise=False)
        for clean, codes in ((rec.noise_free_lsb, rec.codes), (rec.reference_noise_free_lsb, rec.reference)):
            np.testing.assert_array_equal(np.clip(np.floor(clean.astype(float) + 0.5), 0, 1023), codes)
        assert rec.noise_free_lsb.max() > 1023  # CH1 clips on the 3 m panel: the clean level runs on above it
        assert rec.reference_noise_free_lsb.max() > 600  # CH0 sees the emitted pulse (600 LSB over its dark level)



def test_an_echo_that_brings_no_light_gets_no_window():
    """A black panel (reflectance 0) sends no echo: the windowed record has no window for it, only CH0's
    record (an empty window would cost samples and carry only noise)."""
    from muls.receiver.digitiser import digitise

    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.array([5.0, 5.0, 5.0]), reflectance=np.array([0.1, 0.0, 0.1]))
    rec = digitise(model, batch, seed=1)
    assert rec.window_pulse.tolist() == [0, 2] and rec.reference.shape[0] == 3



@pytest.mark.parametrize("near_m, gap_ns", [((4.0, 9.0), 12.0), ((4.0, 9.0), 30.0), ((12.0, 16.0), 30.0),
                                             ((12.0, 16.0), 45.0), ((12.0, 16.0), 60.0)])
def test_regression_windowed_records_hold_chained_echoes_whole(near_m, gap_ns):
    """Root cause: a pulse's second echo 9 to 64 ns behind its first got a window of its own, which started in
    the first echo's tail; the run that chains the two then began at the window's first sample (and ran off
    the end of the first window), and the ranging drops runs cut by a window's edge, so both echoes were lost
    in windowed mode (27 of 119 peaks found at 30 ns in the pool, strong echoes; 114 of 160 unclipped). Echoes
    whose windows would overlap now share one window that runs to the last one's reach, and the windowed and
    full records give the same peaks."""
    model = _model("pool", (150e-9, 400e-9))
    c_w = model.water.speed_m_s
    n = 40
    near = np.linspace(*near_m, n)
    far = near + 0.5 * c_w * gap_ns * 1e-9
    batch = PulseBatch(pulse_id=np.arange(n), return_pulse=np.repeat(np.arange(n), 2),
                       return_range_m=np.column_stack([near, far]).ravel(),
                       return_weight_per_sr=np.full(2 * n, 0.5 * 0.1 / np.pi),
                       column_cut_m=far[:, None].copy(), column_cut_weight=np.ones((n, 1)), background_w=np.zeros(n))
    records, windowed = simulate(model, batch, seed=4, mode="windowed")
    _, full = simulate(model, batch, seed=4, mode="full")
    assert windowed.peaks.pulse.size == full.peaks.pulse.size >= 2 * n
    assert np.array_equal(windowed.peaks.channel, full.peaks.channel)
    assert np.allclose(windowed.peaks.range_m, full.peaks.range_m, rtol=0, atol=1e-9)
    assert records.window_pulse.size == n  # one window per pulse: the two echoes chain
    # and that window runs from 8 ns before the first echo to 56 ns after the second one's start, no further
    assert 64 + gap_ns <= records.codes.shape[2] <= 65 + gap_ns



@pytest.mark.parametrize("peak_fit", ["pulse", "sample_maximum"])
def test_regression_clipped_echo_whose_tail_outlasts_its_window_is_ranged(peak_fit):
    """Root cause: the ranging drops a run cut by a window's end (its maximum might lie beyond it), and a clipped
    echo's run was no exception. In the pool at the pond's gain M1 = 2000, CH1's 3 m echo (about 40,000 LSB
    unclipped) clips over 27 samples and its slow tail stays above half the threshold until about the end of
    the 64-sample window; where noise carried it past, the echo was lost in windowed mode (16 of 1000 shots)
    though the full record ranged it. A clipped run whose plateau ends inside the window is timed by that
    plateau and its clip levels alone, so it is kept: windowed and full records give the same CH1 peaks."""
    from dataclasses import replace

    from muls.experiments import pool

    exp = pool()
    ins = mul2023(exp.gate_delay_s, exp.gate_width_s, 2000.0, 20000.0)
    ins = replace(ins, processing=replace(ins.processing, peak_fit=peak_fit))
    model = OpticalModel.build(ins, exp.water)
    batch = PulseBatch.flat_target(ins, np.full(150, 3.0), 0.1)  # seed 0: shots 17 and 120 were lost
    _, windowed = simulate(model, batch, seed=0, mode="windowed")
    _, full = simulate(model, batch, seed=0, mode="full")
    ch1_w, ch1_f = windowed.peaks.channel == 1, full.peaks.channel == 1
    assert np.array_equal(windowed.peaks.pulse[ch1_w], np.arange(150))  # one clipped CH1 peak per shot
    assert windowed.peaks.saturated[ch1_w].all()
    assert np.array_equal(windowed.peaks.pulse[ch1_w], full.peaks.pulse[ch1_f])
    assert np.allclose(windowed.peaks.range_m[ch1_w], full.peaks.range_m[ch1_f], rtol=0, atol=1e-9)



def test_a_shut_gate_leaves_only_dark_noise():
    """Before its gate opens CH3 reads its dark level with dark and rounding noise alone (1 + 1/12 LSB^2), though
    the pond's column then carries PMT2's shot noise of thousands of LSB^2 at gain 20,000."""
    model = _model("pond", (200e-9, 400e-9))
    rec, _ = simulate(model, PulseBatch.flat_target(model.instrument, np.full(200, 40.0)), seed=8, mode="full",
                      keep_noise_free=True)
    t_ns = rec.sample_times_s(model) * 1e9
    shut = (t_ns > 5.0) & (t_ns < 195.0)
    resid = rec.codes[:, 2, :].astype(float)[shut] - 8.0
    assert np.all(rec.noise_free_lsb[:, 2, :][shut] == pytest.approx(8.0))
    assert resid.var() == pytest.approx(1.0 + 1.0 / 12.0, rel=0.05)
    assert abs(resid.mean()) < 0.02



def test_dark_noise_is_independent_per_channel_and_on_ch0():
    """Far from any signal every channel, CH0 included, reads its dark level with 1 LSB of dark noise and the
    rounding's 1/12 LSB^2; the channels' dark noises do not correlate with each other or with CH0's at the same
    sample (only their shot noise is shared). The MUL gets a fourth channel (a copy of CH2) so that a second
    pair of dark-noise draws is used too."""
    from dataclasses import replace

    base = _model("pool", (150e-9, 400e-9))
    ins = replace(base.instrument, channels=base.instrument.channels + (replace(base.instrument.channels[1], name="ch4"),))
    model = OpticalModel.build(ins, base.water)
    rec, _ = simulate(model, PulseBatch.flat_target(model.instrument, np.full(300, np.inf)), seed=9, mode="full",
                      keep_noise_free=True)
    t_ns = rec.sample_times_s(model)[0] * 1e9
    quiet = t_ns > 700.0  # the pool's column has faded far below 0.01 LSB
    resid = [rec.codes[:, j, quiet].astype(float).ravel() - 8.0 for j in range(4)]
    for r in resid:
        assert r.var() == pytest.approx(1.0 + 1.0 / 12.0, rel=0.05)
    for a, b in ((0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3)):
        assert abs(np.corrcoef(resid[a], resid[b])[0, 1]) < 0.02
    ref_times = rec.reference_times_s(model)[0] * 1e9
    ch0 = rec.reference[:, ref_times < -2.0].astype(float).ravel() - 8.0  # before the laser fires
    assert ch0.size > 3000 and ch0.var() == pytest.approx(1.0 + 1.0 / 12.0, rel=0.08)
    ch0_late = rec.reference[:, quiet].astype(float).ravel() - 8.0  # CH0 long after the emitted pulse
    for r in resid:
        assert abs(np.corrcoef(ch0_late, r)[0, 1]) < 0.02



def test_sample_and_reference_times_are_the_free_running_clock():
    """Sample k of a pulse is taken at -pretrigger + k x 1 ns + the pulse's phase, in every window and in CH0's
    record; the phase lies in [0, 1 ns) and is the same for CH0 and the channels (one clock)."""
    model = _model()
    rec, _ = simulate(model, PulseBatch.flat_target(model.instrument, np.array([9.0, 14.0, 30.0])), seed=2)
    phase = rec.phase_s
    assert np.all((phase >= 0.0) & (phase < 1e-9)) and np.unique(phase).size == 3
    k = rec.window_start[:, None] + np.arange(rec.codes.shape[2])[None, :]
    np.testing.assert_allclose(rec.sample_times_s(model), -16e-9 + k * 1e-9 + phase[rec.window_pulse][:, None],
                               rtol=0, atol=1e-18)
    kr = np.arange(rec.reference.shape[1])[None, :]
    np.testing.assert_allclose(rec.reference_times_s(model), -16e-9 + kr * 1e-9 + phase[:, None], rtol=0, atol=1e-18)



def test_ch0_uses_the_references_own_dark_noise():
    """A reference photodiode with 2 LSB of dark noise reads 4 + 1/12 LSB^2 before the laser fires."""
    from dataclasses import replace

    base = _model()
    ins = replace(base.instrument, reference=replace(base.instrument.reference, dark_std_lsb=2.0))
    model = OpticalModel.build(ins, base.water)
    rec, _ = simulate(model, PulseBatch.flat_target(ins, np.full(300, 10.0)), seed=5, mode="full")
    ref = rec.reference[:, rec.reference_times_s(model)[0] * 1e9 < -2.0].astype(float).ravel()
    assert ref.var() == pytest.approx(4.0 + 1.0 / 12.0, rel=0.08)
