"""The peak search (muls/ranging/peaks.py): the fit table, the order of peaks, the prototype's plain peak
detection."""

import numpy as np
import pytest
from conftest import detection_model as _model

from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.simulate import simulate


def test_the_peak_fits_table_lookup_is_numpys_interp_bit_for_bit():
    """The compiled lookup of the three-point fit's table (``bracket`` and ``interp_at``, in place of numba's scalar
    np.interp) gives numpy.interp's values exactly: inside the grid, on its points, beyond both ends, at +-inf and NaN."""
    import numba

    from muls.infra.lookup import bracket, interp_at

    @numba.njit
    def lookup(xs, xp, fp):
        out = np.empty(xs.size)
        for i in range(xs.size):
            out[i] = interp_at(xs[i], bracket(xs[i], xp), xp, fp)
        return out

    table = _model().fit_table
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(table.feature[0] - 0.3, table.feature[-1] + 0.3, 20000), table.feature,
                        [np.nan, -np.inf, np.inf]])
    for values in (table.offset, table.centre):
        np.testing.assert_array_equal(lookup(x, table.feature, values), np.interp(x, table.feature, values))


def test_each_return_keeps_the_peak_a_stable_lexsort_would_put_last():
    """``best_of_clusters`` (one pass over runs of peaks) against numpy: the last of a stable lexsort by (cluster,
    unsaturated, score) in each cluster; with saturated and unsaturated peaks mixed, tied scores and NaN."""
    from muls.ranging.returns import best_of_clusters

    rng = np.random.default_rng(5)
    n = 5000
    new = rng.random(n) < 0.4
    new[0] = True
    saturated = rng.random(n) < 0.3
    score = rng.integers(0, 6, n).astype(float)  # many ties
    score[rng.random(n) < 0.05] = np.nan
    cluster = np.cumsum(new) - 1
    order = np.lexsort((score, ~saturated, cluster))
    last = np.ones(n, bool)
    last[:-1] = cluster[order][1:] != cluster[order][:-1]
    np.testing.assert_array_equal(best_of_clusters(new, saturated, score), np.sort(order[last]))


def _prototype(model):
    from dataclasses import replace

    ins = model.instrument
    return OpticalModel.build(replace(ins, processing=replace(ins.processing, peak_fit="sample_maximum")), model.water)


def test_sample_maximum_ranges_are_quantised_to_the_sample_interval():
    """Without noise, the CH0 reference and the echo are both timed at their highest sample, taken with the
    same free-running clock. With the echo delay tau = (n + f) samples, the two indices differ by n or n + 1,
    so the range error takes two values, -f and 1 - f range bins (c_w x 1 ns / 2), with probabilities 1 - f
    and f over the pulses' random phases: mean 0, standard deviation sqrt(f (1 - f)) bins."""
    model = _prototype(_model())
    n = 600
    batch = PulseBatch.flat_target(model.instrument, np.full(n, 15.0), pulse_id=np.arange(n))  # nothing clips
    _, ranging = simulate(model, batch, seed=5, noise=False)
    err = ranging.returns.range_m - 15.0
    bin_m = model.water.speed_m_s * 1e-9 / 2.0
    f = (15.0 / bin_m) % 1.0  # tau in samples = range in bins
    assert err.size == n
    assert np.all(np.isclose(err, -f * bin_m, atol=1e-9) | np.isclose(err, (1.0 - f) * bin_m, atol=1e-9))
    assert err.std() == pytest.approx(np.sqrt(f * (1.0 - f)) * bin_m, rel=0.1)
    assert abs(err.mean()) < 0.01
    # the pulse-shape fit of the same records is far finer
    _, fitted = simulate(_model(), batch, seed=5, noise=False)
    assert np.abs(fitted.returns.range_m - 15.0).max() < 0.01


def test_sample_maximum_times_a_clipped_echo_at_its_first_clipped_sample():
    """A clipped echo's plateau starts before its true peak: plain peak detection ranges it short, by more
    the wider the plateau; the pulse-shape fit recovers the peak from the plateau's width."""
    model = _prototype(_model())
    batch = PulseBatch.flat_target(model.instrument, np.full(50, 5.0), pulse_id=np.arange(50))
    _, ranging = simulate(model, batch, seed=2)
    ch1 = ranging.peaks.select(ranging.peaks.channel == 1)
    assert ch1.saturated.all()
    assert np.all(ch1.range_m < 5.0 - 0.1)
    _, fitted = simulate(_model(), batch, seed=2)
    ch1_fit = fitted.peaks.select(fitted.peaks.channel == 1)
    assert np.all(np.abs(ch1_fit.range_m - 5.0) < 0.1)


@pytest.mark.parametrize("water", ["pool", "coastal_ocean", "turbid_harbor"])
def test_the_baseline_the_digitiser_hands_the_peak_search_is_its_own_to_the_bit(water):
    """Where the digitiser decides the channels on the processor's calibrated baseline (``deciding_only``), it hands
    that baseline to the peak search (``Waveforms.baseline_w``) instead of the search computing it again. Checked
    against ``baseline_values`` at the windows' sample times as ``Waveforms.sample_times_s`` gives them (numpy, not
    the kernel's loop), with each pulse's background: equal to the bit; and the peaks, returns and dropouts of the
    records with the baseline handed equal those of the same records without it."""
    import dataclasses

    from muls import mul2023, water_preset
    from muls.optics.sample_kernels import baseline_values
    from muls.ranging.returns import range_batch
    from muls.receiver.digitiser import digitise

    model = OpticalModel.build(mul2023(60e-9, 400e-9), water_preset(water))
    ranges = np.repeat(np.linspace(1.5, 30.0, 40), 5)
    batch = PulseBatch.flat_target(model.instrument, ranges, reflectance=np.tile([0.03, 0.1, 0.3, 0.6, 0.9], 40),
                                   background_w=np.linspace(0.0, 2e-7, ranges.size))  # daylight from none to bright
    echoes = model.echoes(batch)
    records = digitise(model, batch, 5, echoes=echoes, deciding_only=True, ranging_only=True)
    assert records.baseline_w is not None and records.baseline_w.shape == (len(records.window_pulse),
                                                                            records.codes.shape[2])
    times = records.sample_times_s(model)
    for w in range(times.shape[0]):
        expected = np.empty(times.shape[1])
        baseline_values(expected, times[w], batch.background_w[records.window_pulse[w]], model.column)
        assert np.array_equal(records.baseline_w[w], expected), w
    handed = range_batch(model, batch, records, echoes)
    own = range_batch(model, batch, dataclasses.replace(records, baseline_w=None), echoes)
    assert len(handed.peaks.pulse) > 40  # (turbid water ranges the near targets only)
    for name in ("peaks", "returns"):
        for field in dataclasses.fields(getattr(own, name)):
            assert np.array_equal(getattr(getattr(handed, name), field.name), getattr(getattr(own, name), field.name),
                                  equal_nan=True), (name, field.name)
    assert np.array_equal(handed.dropout_cause, own.dropout_cause)
    assert digitise(model, batch, 5, echoes=echoes, ranging_only=True).baseline_w is None  # every channel: not decided
