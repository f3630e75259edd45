"""A window's codes (muls/receiver/channel_codes.py): coded only where the peak search reads, the same peaks and
ranges as whole records."""

import numpy as np
import pytest
from conftest import paper_water

from muls import mul2023
from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.simulate import simulate


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

    from muls.optics.sample_kernels import baseline_values
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
