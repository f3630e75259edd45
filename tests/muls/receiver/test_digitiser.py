"""Digitiser (Eqs. 12, 13), noise statistics, ranging (Eq. 14), channel choice, dropout causes, record modes.

The instrument's processing is tested on echoes of known strength: the waters here use the paper's Eq. 6 with single
scattering (:func:`paper_water`), whose echoes and columns the cases were built around; the product's physics (the
Monte Carlo's attenuation, spread and column) has tests of its own (tests/muls/optics/test_scattering.py)."""

import numpy as np
import pytest

from muls import mul2023, water_preset
from muls.infra.noise import standard_normal
from muls.instrument.channels import shot_noise_lsb2_per_w
from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.ranging.returns import DROPOUT_CAUSES, NO_DROPOUT
from muls.simulate import simulate

RANGE_TOL_NOISE_FREE_M = 0.01


def paper_water(name: str):
    """The preset water under the paper's Eq. 6 (k_lidar), single scattering."""
    return water_preset(name).with_models(attenuation_model="k_lidar")


def _model(water="pool", gate=(150e-9, 400e-9)):
    ins = mul2023(*gate)
    return OpticalModel.build(ins, paper_water(water))


def _causes(ranging):
    counts = np.bincount(ranging.dropout_cause[ranging.dropout_cause >= 0], minlength=len(DROPOUT_CAUSES))
    return {name: int(n) for name, n in zip(DROPOUT_CAUSES, counts) if n}


def test_echoes_are_sorted_by_delay_within_each_pulse_as_a_stable_sort_leaves_them():
    """Pulses of 0 to 91 echoes (the reference level's footprint), with ties and with every delay equal: in place,
    the order numpy's stable lexsort gives, energy and source moved along (both the insertion sort of a few echoes
    and the delay buckets that come first for more)."""
    from muls.optics.optical_model import INSERTION_SORT_MAX, _sort_by_delay_within

    rng = np.random.default_rng(3)
    counts = np.array([0, 1, 7, INSERTION_SORT_MAX, INSERTION_SORT_MAX + 1, 40, 91, 91, 91])
    pulse = np.repeat(np.arange(counts.size), counts)
    delay = rng.integers(0, 30, pulse.size) * 1e-9 + 40e-9  # many ties
    delay[pulse == 7] = 55e-9  # one pulse whose echoes all arrive together
    delay[pulse == 8] = rng.normal(60e-9, 3e-9, 91)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    energy, source = rng.random(pulse.size), np.arange(pulse.size, dtype=np.int64)
    expected = np.lexsort((delay, pulse))
    d, e, s = delay.copy(), energy.copy(), source.copy()
    _sort_by_delay_within(offsets, d, e, s)
    np.testing.assert_array_equal(s, source[expected])
    np.testing.assert_array_equal(d, delay[expected])
    np.testing.assert_array_equal(e, energy[expected])


@pytest.mark.parametrize("mode", ["windowed", "full"])
@pytest.mark.parametrize("dark_std, peak_lsb", [(1.0, 600.0), (40.0, 600.0), (3.0, 1100.0)])
def test_ranging_only_ch0_records_give_the_ranges_of_whole_ones(mode, dark_std, peak_lsb):
    """CH0 records synthesised only around their peak (``ranging_only``) hold the whole records' codes there and 0
    elsewhere, and the ranging reads the same reference times and ranges from them: quiet and very noisy photodiodes,
    and one whose peak clips at the top code (a plateau, where the first top code is the peak)."""
    from dataclasses import replace

    from muls.ranging.peaks import find_peaks

    ins = mul2023()
    ins = replace(ins, reference=replace(ins.reference, dark_std_lsb=dark_std, peak_lsb=peak_lsb))
    model = OpticalModel.build(ins, paper_water("pool"))
    batch = PulseBatch.flat_target(ins, np.linspace(2.0, 12.0, 300), pulse_id=np.arange(300))
    echoes = model.echoes(batch)
    whole = simulate(model, batch, 5, mode)
    part = simulate(model, batch, 5, mode, ranging_only=True)
    kept = part[0].reference > 0
    assert kept.sum(axis=1).max() < 0.6 * kept.shape[1]
    np.testing.assert_array_equal(part[0].reference[kept], whole[0].reference[kept])
    held = part[0].codes > 0  # full records: the signal channels too, only where the peak search may read them
    np.testing.assert_array_equal(part[0].codes[held], whole[0].codes[held])
    assert held.all() if mode == "windowed" else held.mean() < 0.5
    np.testing.assert_array_equal(find_peaks(model, batch, part[0], echoes)[1], find_peaks(model, batch, whole[0], echoes)[1])
    np.testing.assert_array_equal(part[1].returns.range_m, whole[1].returns.range_m)
    np.testing.assert_array_equal(part[1].dropout_cause, whole[1].dropout_cause)


def _sparse_case(case):
    """(instrument, water preset, background light [W]) of a case that puts many full-record samples near the bounds
    of what the peak search reads: the prototype in pool water, a 2-sigma threshold, 12 LSB of dark noise, strong
    background light, clean ocean water, or a range gate opening on the column."""
    from dataclasses import replace

    ins, water, background = mul2023(), "pool", 0.0
    if case == "low threshold":
        ins = replace(ins, processing=replace(ins.processing, threshold_sigma=2.0))
    elif case == "dark noise":
        ins = replace(ins, channels=tuple(replace(ch, dark_std_lsb=12.0) for ch in ins.channels))
    elif case == "daylight":
        background = 3e-5
    elif case == "clean ocean":
        water = "clean_ocean"
    elif case == "gated near":
        ins = mul2023(20e-9, 300e-9)
    return ins, water, background


@pytest.mark.parametrize("case", ["pool", "low threshold", "dark noise", "daylight", "clean ocean", "gated near"])
def test_full_records_coded_only_where_the_peak_search_reads_give_the_same_peaks(case):
    """Full records under ``ranging_only`` get codes only where the peak search may read them (a run may start or go
    on, a code may clip, and their neighbours), 0 elsewhere: the same peaks, every field, and the same ranges and
    dropouts as whole records. Cases that put many samples near the bounds: a threshold of 2 sigma (noise runs in
    every record), dark noise of 12 LSB, strong background light (shot noise over the whole record), clean ocean water's
    strong backscatter and clipped near targets, and a range gate opening on the column."""

    from muls.optics.optical_model import baseline_values
    from muls.ranging.peaks import find_peaks

    ins, water, background = _sparse_case(case)
    model = OpticalModel.build(ins, paper_water(water))
    n = 400
    ranges = np.concatenate([np.linspace(0.6, 40.0, n - 20), np.full(20, np.inf)])
    batch = PulseBatch.flat_target(ins, ranges, reflectance=np.linspace(0.02, 0.9, n), pulse_id=np.arange(n) + 7,
                                   background_w=np.full(n, background))
    echoes = model.echoes(batch)
    whole = simulate(model, batch, 11, "full")
    part = simulate(model, batch, 11, "full", ranging_only=True)
    held = part[0].codes > 0
    assert held.mean() < (0.3 if case == "pool" else 1.0)  # in clear conditions most samples are left out
    np.testing.assert_array_equal(part[0].codes[held], whole[0].codes[held])
    # Every sample the search reads in the whole records has its code: over half the threshold above the channel's
    # calibrated baseline (where the backscatter alone does not clip it) or at the top code, and the samples beside.
    times, chans = whole[0].sample_times_s(model), model.channels.signal()
    uncut = np.zeros(times.shape)
    for w in range(times.shape[0]):
        baseline_values(uncut[w], times[w], background, model.column)
    read = np.zeros(held.shape, bool)
    for c in range(held.shape[1]):
        base = np.where((chans.gate_open_s[c] <= times) & (times < chans.gate_close_s[c]), uncut, 0.0)
        expected = chans.dark_mean_lsb[c] + chans.lsb_per_w[c] * base
        sigma = np.sqrt(chans.dark_std_lsb[c] ** 2 + chans.shot_lsb2_per_w[c] * base + 1.0 / 12.0)
        code = whole[0].codes[:, c].astype(float)
        run = (code - expected > 0.5 * ins.processing.threshold_sigma * sigma) & (expected < ins.digitizer.max_code)
        read[:, c] = run | (code >= ins.digitizer.max_code)
    read[..., 1:] |= read[..., :-1].copy()
    read[..., :-1] |= read[..., 1:].copy()
    np.testing.assert_array_equal(part[0].codes[read], whole[0].codes[read])
    found, expected = find_peaks(model, batch, part[0], echoes)[0], find_peaks(model, batch, whole[0], echoes)[0]
    assert expected.pulse.size > n // 2
    for name in expected.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(found, name), getattr(expected, name), err_msg=name)
    np.testing.assert_array_equal(part[1].returns.range_m, whole[1].returns.range_m)
    np.testing.assert_array_equal(part[1].dropout_cause, whole[1].dropout_cause)


@pytest.mark.parametrize("case", ["pool", "low threshold", "clean ocean", "gated near"])
def test_the_search_within_a_sample_of_nonzero_codes_finds_what_the_search_of_every_sample_finds(case):
    """On full records coded only where the search reads (mostly 0), the peak search that computes residuals and looks
    for runs only within a sample of a nonzero code finds, field for field, the peaks of the search over every sample
    of the same records (the records relabelled ``windowed`` take that one): a code of 0 is under every run."""
    from dataclasses import replace

    from muls.ranging.peaks import find_peaks

    ins, water, _ = _sparse_case(case)
    model = OpticalModel.build(ins, paper_water(water))
    n = 300
    batch = PulseBatch.flat_target(ins, np.linspace(0.6, 40.0, n), reflectance=np.linspace(0.02, 0.9, n),
                                   pulse_id=np.arange(n) + 3)
    echoes = model.echoes(batch)
    records = simulate(model, batch, 4, "full", ranging_only=True)[0]
    assert (records.codes > 0).mean() < (0.3 if case == "pool" else 1.0)
    sparse, dense = find_peaks(model, batch, records, echoes)[0], find_peaks(model, batch, replace(records, mode="windowed"),
                                                                             echoes)[0]
    assert dense.pulse.size > n // 2
    for name in dense.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(sparse, name), getattr(dense, name), err_msg=name)


def test_code_segments_cover_each_nonzero_code_and_its_neighbours_and_merge_where_they_touch():
    """By hand: stretches within a sample of a nonzero code; two stretches two zeros apart share a zero and merge,
    three apart stay two; a record's ends clip them."""
    from muls.ranging.peaks import _code_segments

    row = np.array([5, 0, 0, 0, 0, 7, 7, 0, 0, 3, 0, 0, 0, 0, 0, 0, 0, 9], np.uint16)
    first, end = np.zeros(10, np.int64), np.zeros(10, np.int64)
    m = _code_segments(row, first, end)
    assert [(int(a), int(b)) for a, b in zip(first[:m], end[:m])] == [(0, 2), (4, 11), (16, 18)]
    assert _code_segments(np.zeros(6, np.uint16), first, end) == 0
    assert _code_segments(np.ones(6, np.uint16), first, end) == 1 and (first[0], end[0]) == (0, 6)


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


def test_peak_order_is_the_two_stable_lexsorts_with_duplicates_dropped():
    """``peak_order`` (one pass over each pulse's few peaks) against numpy: a stable lexsort by (pulse, channel, index),
    repeats of (pulse, channel, index) dropped but the first, then a stable lexsort by (pulse, time); with runs found
    twice by overlapping windows, equal times on different channels, and pulses without peaks between."""
    from muls.ranging.peaks import peak_order

    rng = np.random.default_rng(11)
    pulse = np.sort(rng.choice(np.arange(0, 3000, 3), 4000))
    channel = rng.integers(1, 4, pulse.size)
    index = rng.integers(20, 30, pulse.size) + rng.choice([0.0, 0.25, 0.5], pulse.size)
    time_s = np.floor(index) * 1e-9 + 1e-12 * (pulse % 7)  # a function of (pulse, index), with ties across both
    order = np.lexsort((index, channel, pulse))
    keep = np.ones(order.size, bool)
    keep[1:] = ((pulse[order][1:] != pulse[order][:-1]) | (channel[order][1:] != channel[order][:-1])
                | (index[order][1:] != index[order][:-1]))
    order = order[keep]
    expected = order[np.lexsort((time_s[order], pulse[order]))]
    assert expected.size < pulse.size  # duplicates were there to drop
    np.testing.assert_array_equal(peak_order(pulse, channel, index, time_s), expected)


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


def test_counter_based_normals_are_standard_and_independent():
    x = standard_normal(7, np.repeat(np.arange(200), 500), 3, np.tile(np.arange(500), 200))
    assert abs(x.mean()) < 0.01
    assert x.var() == pytest.approx(1.0, abs=0.02)
    assert abs(np.corrcoef(x[:-1], x[1:])[0, 1]) < 0.01
    assert not np.array_equal(x, standard_normal(8, np.repeat(np.arange(200), 500), 3, np.tile(np.arange(500), 200)))


def test_inverse_normal_cdf_is_the_exact_one_to_acklams_accuracy_tails_included():
    """The draws' map from a uniform p to a normal (Acklam's rational approximation, a central and a tail
    formula) agrees with the exact inverse normal CDF (scipy's ndtri) to his stated 1.15e-9 relative, from
    1e-10 to 1 - 1e-10: both tails and the switch between the formulas at p = 0.02425 and 0.97575."""
    from scipy.special import ndtri

    from muls.infra.noise import _inverse_normal_cdf

    tail = np.logspace(-10.0, -1.3, 60)
    p = np.concatenate([tail, np.linspace(0.02, 0.98, 97), [0.02424, 0.02426, 0.97574, 0.97576], 1.0 - tail])
    x = np.array([_inverse_normal_cdf(v) for v in p])
    np.testing.assert_allclose(x, ndtri(p), rtol=1.2e-9, atol=1e-12)


def test_the_uniforms_behind_the_normals_stay_inside_0_1_and_are_symmetric():
    """Each 32-bit half of a draw maps to the centre of one of 2^32 equal cells of (0, 1): the extreme halves
    give 2^-33 and 1 - 2^-33 (never 0 or 1, where the inverse normal CDF is infinite), and k and 2^32 - 1 - k
    give p and 1 - p exactly, so the normals are symmetric. Cases sampling cannot reach (4e9 draws apart)."""
    from muls.infra.noise import centred_unit

    top = 2**32 - 1
    assert centred_unit(np.uint64(0)) == 2.0**-33 and centred_unit(np.uint64(top)) == 1.0 - 2.0**-33
    for k in (0, 1, 12345, 2**31 - 1, top):
        assert centred_unit(np.uint64(k)) + centred_unit(np.uint64(top - k)) == 1.0


def test_block_draws_equal_the_draws_one_by_one_tails_included():
    """The digitiser draws a window's normals a block at once (``fill_normal_pairs``: the central formula on SIMD
    lanes, then the tails patched); each must equal the draw-by-draw ``normal_half_at`` bit for bit, in both
    halves, with the low half skipped or not, at any first index: else records would depend on the blocking."""
    from muls.infra.noise import fill_hashes, fill_normal_pairs, fill_normals_of, normal_half_at, seed_key, stream_base

    n = 5000
    for pulse, stream, first in ((0, 2, 0), (17, 3, 123), (2**40, 4, 999_983)):
        base = np.uint64(stream_base(seed_key(11), pulse, stream))
        expected = np.array([[normal_half_at(base, first + k, half) for k in range(n)] for half in (0, 1)])
        assert (np.abs(expected) > 1.97).sum() > 0.04 * expected.size  # the tail formula is exercised
        high, low, tails = np.empty(n), np.empty(n), np.empty(n, np.uint64)
        fill_normal_pairs(base, first, high, low, tails)
        assert np.array_equal(high, expected[0]) and np.array_equal(low, expected[1])
        only_high = np.empty(n)
        fill_normal_pairs(base, first, only_high, np.empty(0), tails)
        assert np.array_equal(only_high, expected[0])
        # the normals of listed positions from their hashes (full records drawn only where read)
        hashes = np.empty(n, np.uint64)
        fill_hashes(base, first, hashes)
        listed = np.sort(np.random.default_rng(pulse).choice(n, n // 3, replace=False))
        for half in (0, 1):
            some, flags = np.empty(listed.size), np.empty(listed.size, np.bool_)
            fill_normals_of(hashes, half, listed, some, flags)
            assert np.array_equal(some, expected[half][listed])


def test_the_table_bound_on_a_normal_lies_above_it_and_close():
    """``normal_upper_bound`` (a table of 4,096 cells of the 32-bit half) is at least the normal of every half, checked
    at both ends of every cell and at random halves, and within 0.015 of it where |x| < 2.5: a bound below a draw would
    leave a code out of a full record that the peak search reads."""
    from muls.infra.noise import UPPER_BOUND_SHIFT, normal_of_bits, normal_upper_bound

    cells = np.arange(1 << (32 - int(UPPER_BOUND_SHIFT)), dtype=np.uint64)
    edges = np.concatenate([cells << UPPER_BOUND_SHIFT, ((cells + np.uint64(1)) << UPPER_BOUND_SHIFT) - np.uint64(1)])
    bits = np.concatenate([edges, np.random.default_rng(2).integers(0, 2**32, 200_000, dtype=np.uint64)])
    normal = np.array([normal_of_bits(b) for b in bits])
    bound = np.array([normal_upper_bound(b) for b in bits])
    assert (bound >= normal).all()
    central = np.abs(normal) < 2.5
    assert (bound - normal)[central].max() < 0.015


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


@pytest.mark.parametrize("range_m", [7.0, 9.0, 12.0, 16.0, 19.0])
def test_noise_free_ranging_within_1_cm(range_m):
    """Echoes of 150 LSB and more: only the sampling phase and 10-bit rounding remain."""
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.full(20, range_m), pulse_id=np.arange(20))
    _, ranging = simulate(model, batch, seed=5, noise=False)
    assert ranging.returns.pulse.size == 20
    assert np.all(np.abs(ranging.returns.range_m - range_m) < RANGE_TOL_NOISE_FREE_M)


@pytest.mark.parametrize("range_m", [22.0, 30.0])
def test_noise_free_ranging_of_weak_echoes_is_quantisation_limited(range_m):
    """A 24 LSB echo at 30 m ranges to several cm with 10 bits; a 14-bit digitiser brings it within 1 cm."""
    from dataclasses import replace

    base = mul2023(150e-9, 400e-9)
    fine = replace(base, digitizer=replace(base.digitizer, bits=14))
    model = OpticalModel.build(fine, paper_water("pool"))
    batch = PulseBatch.flat_target(fine, np.full(20, range_m), pulse_id=np.arange(20))
    _, ranging = simulate(model, batch, seed=5, noise=False)
    assert np.all(np.abs(ranging.returns.range_m - range_m) < RANGE_TOL_NOISE_FREE_M)


def test_channel_choice_high_gain_saturated_falls_to_low_gain():
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.full(30, 9.0), pulse_id=np.arange(30))
    _, ranging = simulate(model, batch, seed=3)
    ch1_peaks = ranging.peaks.select(ranging.peaks.channel == 1)
    assert ch1_peaks.saturated.all()
    assert np.all(ranging.returns.channel == 2)
    assert not ranging.returns.saturated.any()


def test_channel_choice_echo_in_gate_uses_ch3():
    model = _model("pond", (100e-9, 400e-9))
    batch = PulseBatch.flat_target(model.instrument, np.full(30, 13.0), pulse_id=np.arange(30))
    _, ranging = simulate(model, batch, seed=3)
    assert np.all(ranging.returns.channel == 3)
    assert np.all(np.abs(ranging.returns.range_m - 13.0) < 0.2)


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


@pytest.mark.parametrize("water, gate, range_m, rho, cause", [
    ("pool", (150e-9, 400e-9), np.inf, 0.1, "no_hit"),
    ("pool", (150e-9, 400e-9), 1.0, 0.1, "blind_zone"),
    ("turbid_harbor", (100e-9, 400e-9), 20.0, 0.1, "below_threshold"),
    ("coastal_ocean", (100e-9, 400e-9), 3.0, 0.1, "saturated"),
    ("turbid_harbor", (100e-9, 400e-9), 3.5, 0.001, "masked_by_backscatter"),
    ("pond", (200e-9, 400e-9), 13.0, 0.1, "outside_gate"),
])
def test_each_dropout_cause_is_reached(water, gate, range_m, rho, cause):
    from dataclasses import replace

    model = _model(water, gate)
    ins = model.instrument
    model = OpticalModel.build(replace(ins, processing=replace(ins.processing, saturation_policy="drop")), model.water)
    batch = PulseBatch.flat_target(model.instrument, np.full(20, range_m), rho)
    _, ranging = simulate(model, batch, seed=6)
    assert ranging.returns.pulse.size == 0
    assert _causes(ranging) == {cause: 20}


def test_saturated_returns_kept_under_keep_policy():
    model = _model("coastal_ocean", (100e-9, 400e-9))
    ins = model.instrument
    assert ins.processing.saturation_policy == "keep"  # the default
    _, ranging = simulate(model, PulseBatch.flat_target(ins, np.full(20, 3.0)), seed=6)
    assert ranging.returns.pulse.size == 20
    assert ranging.returns.saturated.all()
    assert np.all(ranging.dropout_cause == NO_DROPOUT)
    # The clipped plateau's width recovers the peak time through the known pulse shape.
    assert np.all(np.abs(ranging.returns.range_m - 3.0) < 0.1)


def test_regression_clipped_run_after_backscatter_blindness_is_not_an_echo():
    """Root cause: a far channel gated open at 40 ns in turbid water is clipped by the column itself; the echo
    lies inside that blind stretch, and the clipped samples that follow it were taken as an echo plateau,
    ranged ~0.8 m long. A run must rise from samples where the channel can see."""
    model = _model("turbid_harbor", (40e-9, 400e-9))
    _, ranging = simulate(model, PulseBatch.flat_target(model.instrument, np.full(30, 7.5), 0.14), seed=1)
    far = ranging.peaks.select(ranging.peaks.channel == 3)
    assert far.pulse.size == 0
    assert set(np.unique(ranging.dropout_cause[ranging.dropout_cause >= 0])) <= {DROPOUT_CAUSES.index("masked_by_backscatter")}


def test_regression_plateau_through_backscatter_blindness_is_not_an_echo():
    """Root cause: in turbid water at 3.2 m the column alone clips CH1 from 23 to 31 ns and the echo keeps it
    clipped after that; the plateau was measured from its first clipped sample (in the column), so CH1 ranged
    the seabed ~0.7 m short and a second, true return came from CH2. A plateau that passes through samples
    the backscatter alone clips has an unknown start: the channel cannot range it."""
    model = _model("turbid_harbor", (35e-9, 400e-9))
    _, ranging = simulate(model, PulseBatch.flat_target(model.instrument, np.full(40, 3.2), 0.14), seed=3)
    assert np.all(ranging.number_of_returns[ranging.return_number == 1] == 1)
    assert np.all(np.abs(ranging.returns.range_m - 3.2) < 0.15)


def test_regression_second_plateau_explained_by_the_first_echo_does_not_hang():
    """Root cause: two clipped plateaus one sample apart (a moored mine's top, then the seabed, at 1.9 m in
    single_channel coastal water). Once the first echo's model was taken off, the second plateau's clip level
    was negative, log() gave NaN, the peak index -inf, and adding that echo's model looped ~2^63 times.
    A plateau whose clip level the echoes before it already explain is not ranged; the grid lookup is total."""
    from muls.infra.lookup import on_geometric_grid

    ratio, rise, _ = _model().clip_table
    for x in (0.0, -1.0, float("nan")):
        assert on_geometric_grid(x, ratio, rise) == rise[0]
    code = (
        "import numpy as np\n"
        "from scanner_sim.config import load_scene\n"
        "from scanner_sim.studies.coverage_study import combination_config\n"
        "from scanner_sim.survey.setup import PassOptions, PassSetup\n"
        "cfg = combination_config(load_scene('mine_field'), 'coastal_ocean', 3.0, 'single_channel')\n"
        "chunk = PassSetup.build(cfg, PassOptions(water='coastal_ocean')).simulate_chunk(np.array([44049]))\n"
        "assert np.all(np.isfinite(chunk.points.xyz)) and len(chunk.points) >= 1\n"
    )
    import subprocess
    import sys

    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_two_echoes_in_one_footprint_give_two_returns_and_close_ones_merge():
    model = _model()

    def batch_for(ranges):
        n = 20
        return PulseBatch(
            pulse_id=np.arange(n), return_pulse=np.repeat(np.arange(n), 2),
            return_range_m=np.tile(ranges, n), return_weight_per_sr=np.full(2 * n, 0.5 * 0.05 / np.pi),
            column_cut_m=np.full((n, 1), max(ranges)), column_cut_weight=np.ones((n, 1)), background_w=np.zeros(n))

    _, apart = simulate(model, batch_for([15.0, 17.0]), seed=1)
    assert np.all(apart.number_of_returns == 2)
    assert np.allclose(apart.returns.range_m[apart.return_number == 1], 15.0, atol=0.1)
    assert np.allclose(apart.returns.range_m[apart.return_number == 2], 17.0, atol=0.15)
    _, close = simulate(model, batch_for([15.0, 15.3]), seed=1)
    assert np.all(close.number_of_returns == 1)
    merged = close.returns.range_m
    assert np.all((merged > 15.0) & (merged < 15.3))  # one biased range between the two surfaces



@pytest.mark.parametrize("near_reflectance", [0.5, 0.9])
@pytest.mark.parametrize("mode, deciding_only", [("windowed", False), ("windowed", True), ("full", False)])
def test_return_behind_clipped_echo_is_ranged(mode, deciding_only, near_reflectance):
    """Root cause: the peak search went on behind an unclipped peak (its modelled pulse taken off, the search
    resumed right after it) but not behind a clipped one: it resumed after the whole run, and a clipped echo's
    tail runs on over a surface a few metres behind, so that surface was never reported (0 of 1000 pulses, no
    dropout, no flag) while the same plate 10 % darker, unclipped, let it be ranged on every pulse. Half the beam on
    a plate 7 m away whose echo clips every channel open there, half on sand 2 m behind: the sand is ranged at 9 m
    on every pulse, in both record modes and with only the deciding channels (every fidelity level's path). With
    the whiter plate CH1's plateau runs on over the sand's echo (one plateau, two echoes): the model fitted to it
    is wrong behind it, and what that leaves in the residual must not be reported as a third surface."""
    from muls.optics.radiometry import lambertian_weight

    model = _model()
    ins = model.instrument
    n, near_m, far_m = 200, 7.0, 7.0 + 2.0
    half = [0.5 * lambertian_weight(ins, r, rho) for r, rho in ((near_m, near_reflectance), (far_m, 0.43))]
    batch = PulseBatch(
        pulse_id=np.arange(n), return_pulse=np.repeat(np.arange(n), 2), return_range_m=np.tile([near_m, far_m], n),
        return_weight_per_sr=np.tile(half, n), column_cut_m=np.full((n, 1), far_m), column_cut_weight=np.ones((n, 1)),
        background_w=np.zeros(n))
    _, ranging = simulate(model, batch, seed=4, mode=mode, deciding_only=deciding_only)
    first, second = (ranging.returns.select(ranging.return_number == k) for k in (1, 2))
    # The premise: the plate's return is clipped in every channel (a return keeps a clipped peak only then).
    assert first.pulse.size == n and first.saturated.all() and np.all(np.abs(first.range_m - near_m) < 0.15)
    assert second.pulse.size == n and not second.saturated.any()
    assert np.all(np.abs(second.range_m - far_m) < 0.15)  # IHO S-44 Exclusive Order, the coverage tolerance
    assert np.all(ranging.number_of_returns == 2)


def test_no_late_return_from_an_echo_rising_inside_a_plateau():
    """Root cause: behind a clipped plateau the search goes on once the single pulse fitted to the plateau is taken
    off. Where a second echo rises before the first echo's plateau ends (a step 1 m down, 8.9 ns behind, under a
    10 ns pulse), the plateau holds both: the fitted pulse is off, and what it leaves of the second echo peaks
    late, where it was reported as a third surface (step_edges, slot 749: CH1 at 7.19 m, 0.49 m behind the step
    CH2 ranges at 6.75 m). An echo whose peak lies less than the pulse's rise behind the plateau's end began
    inside the plateau, so the clipping channel cannot time it and no longer reports it; CH2, which does not clip,
    ranges it. Two-thirds of the beam on sand 5.7 m away, a third on sand 1 m lower (step_edges' geometry, CH1
    clipped over the upper echo on every pulse): every return lies on one of the two surfaces, within 0.25 m (the
    late points lay 0.3-0.54 m behind the lower one)."""
    from muls.optics.radiometry import lambertian_weight

    ins = mul2023(26e-9, 158e-9)  # step_edges' gate (a CH3 gate that opens past both echoes)
    model = OpticalModel.build(ins, water_preset("coastal_ocean"))
    n, upper_m, lower_m = 400, 5.7, 6.7
    weights = [share * lambertian_weight(ins, r, 0.43) for share, r in ((2 / 3, upper_m), (1 / 3, lower_m))]
    batch = PulseBatch(
        pulse_id=np.arange(n), return_pulse=np.repeat(np.arange(n), 2), return_range_m=np.tile([upper_m, lower_m], n),
        return_weight_per_sr=np.tile(weights, n), column_cut_m=np.full((n, 1), lower_m),
        column_cut_weight=np.ones((n, 1)), background_w=np.zeros(n))
    records, ranging = simulate(model, batch, seed=7)
    assert np.all(records.codes[:, 0].max(axis=1) == ins.digitizer.max_code)  # the premise: CH1 clips every pulse
    ranges = ranging.returns.range_m
    off = np.minimum(np.abs(ranges - upper_m), np.abs(ranges - lower_m))
    assert np.all(off < 0.25), np.sort(ranges[off >= 0.25])
    assert np.count_nonzero(np.abs(ranges - lower_m) < 0.15) >= 0.9 * n  # the lower step is still ranged


# --- the prototype's plain peak detection (Processing.peak_fit = "sample_maximum") ----------------------------

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


# --- the digitiser's contract (gaps a mutation run found) ----------------------------------------------------

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


def test_seed_key_accepts_ints_and_generators_and_names_what_it_refuses():
    """A seed is an integer from 0, or a numpy Generator, which is advanced once: its key is that of the integer
    the generator draws from [0, 2**63). Negative numbers, booleans and floats are refused, naming the seed."""
    from muls.infra.noise import seed_key

    assert seed_key(0) != seed_key(1)
    drawn = int(np.random.default_rng(7).integers(0, 2**63))
    assert seed_key(np.random.default_rng(7)) == seed_key(drawn)
    assert seed_key(np.random.default_rng(7)) != seed_key(np.random.default_rng(8))
    for bad in (-1, True, 1.5, "3"):
        with pytest.raises(ValueError, match="seed"):
            seed_key(bad)
