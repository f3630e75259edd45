"""The digitiser's ``deciding_only`` mode (muls.receiver.deciding_channels): which channels of a window can decide a return,
judged before the noise is drawn, checked against the digitisation of every channel with the same seed."""

import numpy as np
import pytest

from muls import mul2023, water_preset
from muls.infra.noise import NORMAL_BOUND, _inverse_normal_cdf, centred_unit
from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.simulate import simulate


def _model(water="pool", gate=(150e-9, 400e-9)):
    return OpticalModel.build(mul2023(*gate), water_preset(water))


def _returns(ranging):
    r = ranging.returns
    return list(zip(r.pulse.tolist(), r.channel.tolist(), r.range_m.tolist()))


def _first_returns(ranging):
    first = ranging.return_number == 1
    r = ranging.returns
    return dict(zip(r.pulse[first].tolist(), zip(r.channel[first].tolist(), r.range_m[first].tolist())))


def test_every_normal_lies_inside_the_bound_that_lets_clipped_samples_skip_their_draws():
    """A sample is left at the top code without drawing its noise when its noise-free level lies more than
    NORMAL_BOUND sigma above it: the bound must exceed the largest normal the streams can give (the outermost of the
    2^32 cells, 2^-33 from 0 or 1: 6.338), and not by much, or few samples would skip."""
    extreme = _inverse_normal_cdf(centred_unit(np.uint64(0)))
    assert -NORMAL_BOUND < extreme < -NORMAL_BOUND + 0.01
    assert _inverse_normal_cdf(centred_unit(np.uint64(2**32 - 1))) == -extreme


@pytest.mark.parametrize("water", ["pool", "clean_ocean", "coastal_ocean", "pond", "turbid_harbor"])
@pytest.mark.parametrize("gate", [(150e-9, 400e-9), (60e-9, 400e-9), (20e-9, 400e-9)])
def test_deciding_channels_give_every_pulse_the_returns_of_all_channels(water, gate):
    """Flat targets from 1.5 to 40 m, reflectance 0.03 to 0.9, in five waters with the far gate late or early: the
    channels kept synthesise exactly the codes that every channel's digitisation gives them (same noise streams),
    every pulse keeps its first return (channel and range) and its dropout cause, and the channels left out are
    0. What may differ are further returns of one echo that several channels' peaks, more than the merge window
    apart, split or bridge (a duplicate 0.4-0.7 m behind); they must stay rare and lie within 1 m of the first."""
    model = _model(water, gate)
    ranges = np.repeat(np.linspace(1.5, 40.0, 60), 8)
    batch = PulseBatch.flat_target(model.instrument, ranges, reflectance=np.tile([0.03, 0.1, 0.3, 0.9], 120))
    every, ranged_every = simulate(model, batch, seed=3)
    kept, ranged_kept = simulate(model, batch, seed=3, deciding_only=True)
    assert every.synthesised is None
    held = np.broadcast_to(kept.synthesised[:, :, None], kept.codes.shape)
    assert np.array_equal(kept.codes[held], every.codes[held])
    assert not kept.codes[~held].any()
    assert kept.synthesised.sum() < every.codes.shape[0] * every.codes.shape[1]  # something was left out
    assert _first_returns(ranged_kept) == _first_returns(ranged_every)
    assert np.array_equal(ranged_kept.dropout_cause, ranged_every.dropout_cause)
    changed = set(_returns(ranged_kept)) ^ set(_returns(ranged_every))
    assert len(changed) <= 0.005 * len(_returns(ranged_every)) + 1
    first = _first_returns(ranged_every)
    assert all(abs(r - first[p][1]) < 1.0 for p, _, r in changed)


def test_a_clipped_high_gain_channel_is_left_out_where_the_low_gain_channel_catches_the_echo():
    """A plate of reflectance 0.3 at 10 m in the pool: the echo clips CH1 (about 5,000 LSB noise-free) while CH2,
    nine times less sensitive, stays below the top code with over a hundred sigma of SNR, so CH2 alone decides
    (CH3's gate, open from 150 ns, is shut over the whole window). With every channel digitised, CH1's peaks there
    are indeed saturated and CH2's returns are the ones chosen."""
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.full(50, 10.0), reflectance=0.3)
    every, ranged_every = simulate(model, batch, seed=1)
    kept, ranged_kept = simulate(model, batch, seed=1, deciding_only=True)
    assert np.all(kept.synthesised == [False, True, False])
    ch1 = ranged_every.peaks.channel == 1
    assert ch1.sum() == 50 and np.all(ranged_every.peaks.saturated[ch1])
    assert np.all(ranged_kept.returns.channel == 2) and _returns(ranged_kept) == _returns(ranged_every)


def test_where_every_channel_clips_only_the_lowest_gain_one_is_synthesised():
    """A bright plate (0.9) at 4 m clips CH1 and CH2 alike: the return is the lowest-gain channel's saturated peak
    (choose_returns), so CH2 alone is synthesised, and gives the same returns."""
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.full(50, 4.0), reflectance=0.9)
    _, ranged_every = simulate(model, batch, seed=1)
    kept, ranged_kept = simulate(model, batch, seed=1, deciding_only=True)
    assert np.all(kept.synthesised == [False, True, False])
    assert np.all(ranged_every.peaks.saturated) and _returns(ranged_kept) == _returns(ranged_every)


def test_an_unclipped_echo_is_decided_by_the_high_gain_channel_alone():
    """A plate of reflectance 0.05 at 10 m in the pool: CH1 stays below the top code whatever the noise (about 830 LSB
    over its dark level) with hundreds of sigma of SNR; CH2 sees a ninth of it, some 90 sigma, far less than CH1's
    and enough to time it inside the merge window: CH2 is left out, and CH1 ranges every pulse as before."""
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.full(50, 10.0), reflectance=0.05)
    _, ranged_every = simulate(model, batch, seed=2)
    kept, ranged_kept = simulate(model, batch, seed=2, deciding_only=True)
    assert np.all(kept.synthesised[:, :2] == [True, False])
    assert _returns(ranged_kept) == _returns(ranged_every) and np.all(ranged_kept.returns.channel == 1)


def test_a_low_gain_peak_timed_by_its_noise_is_kept():
    """A black plate (0.03) at 15 m: CH2's peak (about 15 LSB, SNR 10 to 20) cannot beat CH1's, but at that SNR its
    noise can time it more than the 4 ns merge window from CH1's, and ranging would report it as a second return
    of the plate (as the mine_field survey showed): CH2 is kept, so the returns are those of every channel."""
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.full(50, 15.0), reflectance=0.03)
    _, ranged_every = simulate(model, batch, seed=2)
    kept, ranged_kept = simulate(model, batch, seed=2, deciding_only=True)
    assert np.all(kept.synthesised[:, :2])
    assert _returns(ranged_kept) == _returns(ranged_every)


def test_regression_an_echo_stretched_over_range_keeps_every_channel():
    """Root cause: at grazing incidence (scenes/failures/grazing_89.yaml) a footprint's echoes spread over 1.5 m of
    range make one long hump; the peak search finds several peaks in it per channel, and the low-gain channel's
    peaks chain the high-gain channel's into one return. With only CH1 synthesised its second peak became a return
    of its own: 2.000 points per pulse against 1.991 and a median range error of 0.35 m against 0.09 m. A pulse
    whose echoes spread over more than a sample now keeps every channel that sees them, and ranges as before."""
    model = _model()
    ins = model.instrument
    n, ranges = 30, np.linspace(5.0, 6.5, 19)  # a 3 cm beam at 89 degrees: 19 sub-ray echoes over 1.5 m
    one = PulseBatch.flat_target(ins, ranges, reflectance=0.3, incidence_rad=np.radians(60.0))
    batch = PulseBatch(pulse_id=np.arange(n), return_pulse=np.repeat(np.arange(n), ranges.size),
                       return_range_m=np.tile(ranges, n), return_weight_per_sr=np.tile(one.return_weight_per_sr / 19, n),
                       column_cut_m=np.tile(ranges, (n, 1)), column_cut_weight=np.full((n, ranges.size), 1.0 / 19),
                       background_w=np.zeros(n))
    _, ranged_every = simulate(model, batch, seed=7)
    kept, ranged_kept = simulate(model, batch, seed=7, deciding_only=True)
    assert np.all(kept.synthesised[:, :2])
    assert _returns(ranged_kept) == _returns(ranged_every)


def test_two_echoes_apart_in_one_window_keep_every_channel_that_sees():
    """Two plates 1.5 m apart in one footprint (half the beam each) make two humps in one window: which channel
    wins may differ per echo, so nothing is left out but a channel blind throughout."""
    model = _model()
    ins = model.instrument
    one = PulseBatch.flat_target(ins, np.array([6.0, 7.5]), reflectance=0.3)
    n = 40
    batch = PulseBatch(pulse_id=np.arange(n), return_pulse=np.repeat(np.arange(n), 2),
                       return_range_m=np.tile(one.return_range_m, n),
                       return_weight_per_sr=np.tile(0.5 * one.return_weight_per_sr, n),
                       column_cut_m=np.tile([6.0, 7.5], (n, 1)), column_cut_weight=np.full((n, 2), 0.5),
                       background_w=np.zeros(n))
    every, _ = simulate(model, batch, seed=4, keep_noise_free=True)
    kept, _ = simulate(model, batch, seed=4, deciding_only=True)
    assert every.codes.shape[0] == n  # one window holds both echoes
    assert np.all(kept.synthesised[:, :2])


def test_a_channel_the_backscatter_blinds_is_left_out_and_would_have_found_nothing():
    """In coastal ocean water the column alone (the processor's calibrated baseline) puts CH3 (gain 20,000 on PMT2,
    gate open from 20 ns) above the top code at every sample of the window of a plate at 2 m once its gate is open
    (it is shut before): it is not synthesised, and digitised it gives no peak at all. (In the turbid harbour the
    Monte Carlo's column, attenuated on its way back, falls below the top code within 60 ns: there CH3 is kept.)"""
    model = _model("coastal_ocean", (20e-9, 400e-9))
    batch = PulseBatch.flat_target(model.instrument, np.full(40, 2.0), reflectance=0.3)
    every, ranged_every = simulate(model, batch, seed=6)
    kept, _ = simulate(model, batch, seed=6, deciding_only=True)
    ch3 = model.channels.signal()
    times = every.sample_times_s(model)
    baseline_lsb = ch3.dark_mean_lsb[2] + ch3.lsb_per_w[2] * model.column_power_w(times.ravel()).reshape(times.shape)
    gate_open = times >= 20e-9
    assert gate_open.any() and np.all(baseline_lsb[gate_open] >= model.instrument.digitizer.max_code)
    assert not kept.synthesised[:, 2].any()
    assert not np.any(ranged_every.peaks.channel == 3)


def test_a_channel_blind_through_the_echo_is_left_out_where_its_only_run_joins_the_column():
    """cable_survey's water and far gate (coastal ocean, CH3 open from 35 ns), plates at 5.5 to 9 m: the column alone
    clips CH3 from its gate's opening through the echo, and the echo's tail, where CH3 sees again, runs on from a
    clipped plateau that reaches back into that blind stretch: the peak search takes it for the column. CH3 is then
    left out in most of these windows (the noise's reach leaves a few open), and digitised with every channel it gives
    no peak at all, and every return and dropout is the same. Before this rule every window kept CH3 beside the
    channel that decides (its best SNR, behind the blind samples, could not be compared)."""
    model = _model("coastal_ocean", (35e-9, 400e-9))
    ranges = np.repeat(np.linspace(5.5, 9.0, 8), 12)
    batch = PulseBatch.flat_target(model.instrument, ranges, reflectance=np.tile([0.05, 0.1, 0.2, 0.3, 0.5, 0.9], 16))
    every, ranged_every = simulate(model, batch, seed=4)
    kept, ranged_kept = simulate(model, batch, seed=4, deciding_only=True)
    assert kept.synthesised[:, 2].mean() < 0.2
    assert not np.any(ranged_every.peaks.channel == 3)
    assert sorted(_returns(ranged_kept)) == sorted(_returns(ranged_every))
    np.testing.assert_array_equal(ranged_kept.dropout_cause, ranged_every.dropout_cause)


def test_a_pulse_without_a_window_draws_no_reference_and_keeps_its_dropout():
    """Under deciding_only the CH0 reference is synthesised only for the pulses with a record window: it times their
    returns, and a pulse without one (its beam lit nothing: here targets of zero reflectance) has no return to time.
    Those pulses' CH0 codes are 0, where every channel's digitisation draws them; every other pulse's reference is
    that digitisation's to the bit, and every pulse keeps its first return and its dropout cause."""
    model = _model("coastal_ocean")
    ranges = np.repeat(np.linspace(2.0, 20.0, 40), 6)
    batch = PulseBatch.flat_target(model.instrument, ranges, reflectance=np.tile([0.0, 0.1, 0.0, 0.5, 0.0, 0.9], 40))
    every, ranged_every = simulate(model, batch, seed=5)
    kept, ranged_kept = simulate(model, batch, seed=5, deciding_only=True)
    windowed = np.zeros(batch.n_pulses, bool)
    windowed[kept.window_pulse] = True
    assert 100 <= windowed.sum() < batch.n_pulses
    assert every.reference[~windowed].any() and not kept.reference[~windowed].any()
    np.testing.assert_array_equal(kept.reference[windowed], every.reference[windowed])
    assert _first_returns(ranged_kept) == _first_returns(ranged_every)
    np.testing.assert_array_equal(ranged_kept.dropout_cause, ranged_every.dropout_cause)
