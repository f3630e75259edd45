"""The error metrics on hand-built records whose answer is known."""

import numpy as np
import pytest

from muls.receiver.digitiser import Waveforms
from scanner_sim.records.point_records import PointRecords
from scanner_sim.studies.accuracy import MATCH_TOLERANCE_M, WaveformFit, match_returns, vs_reference, vs_truth


def _points(pulse, z, classification=None, object_id=None, range_error=None):
    """Points straight below the origin at heights ``z``, one per entry, of pulses ``pulse``."""
    n = len(pulse)
    z = np.asarray(z, float)
    return PointRecords(
        gps_time_s=np.zeros(n), xyz=np.c_[np.zeros(n), np.zeros(n), z], intensity=np.zeros(n, np.uint16),
        return_number=np.ones(n, np.uint8), number_of_returns=np.ones(n, np.uint8),
        classification=np.asarray(classification if classification is not None else [2] * n, np.uint8),
        scan_angle_deg=np.zeros(n), channel=np.ones(n, np.uint8), amplitude_lsb=np.zeros(n), snr=np.zeros(n),
        saturated=np.zeros(n, bool), true_range_m=-z, range_error_m=np.asarray(range_error if range_error is not None
                                                                            else np.zeros(n), float),
        incidence_deg=np.zeros(n), object_id=np.asarray(object_id if object_id is not None else [0] * n, np.int32),
        leg=np.ones(n, np.uint16), pulse_index=np.asarray(pulse, np.int64))


def test_truth_metrics_count_false_alarms_and_skip_them_in_the_range_error():
    """Four pulses; three returns an echo explains with errors 0.01, -0.03 and 0.2 m, and one false alarm with
    a 5 m error (its 'truth' is the first surface on its line): the median of |error| is 0.03 m, the false
    alarm counts only as one per four pulses."""
    points = _points([0, 1, 2, 3], [-5, -5, -5, -4], object_id=[0, 0, 0, -1], classification=[2, 2, 2, 7],
                     range_error=[0.01, -0.03, 0.2, 5.0])
    m = vs_truth(points, 4, hidden=np.array([False, False, True, False]))
    assert m["points_per_pulse"] == 1.0
    assert m["median_abs_range_error_m"] == pytest.approx(0.03, abs=1e-6)
    assert 0.03 < m["p95_abs_range_error_m"] <= 0.2 + 1e-6
    assert m["false_alarms_per_pulse"] == 0.25
    assert m["hidden_points_per_pulse"] == 0.25
    assert vs_truth(points, 4)["hidden_points_per_pulse"] is None


def test_returns_pair_within_their_pulse_by_position_one_to_one():
    """Reference: pulse 0 has returns at z -5 and -7, pulse 1 one at -5. The pass: pulse 0 has one return at
    -5.1 (pairs with -5) and a phantom at -4.3 (0.7 m from anything: extra), pulse 1 has its -5 return and a
    point at -5.2 that competes for the same partner (one-to-one: extra), pulse 2 a return the reference lacks."""
    reference = _points([0, 0, 1], [-5, -7, -5])
    points = _points([0, 0, 1, 1, 2], [-5.1, -4.3, -5.0, -5.2, -5.0])
    i, j = match_returns(points, reference)
    assert sorted(zip(i.tolist(), j.tolist())) == [(0, 0), (2, 2)]
    m = vs_reference(points, reference, 3)
    assert m["missing_per_pulse"] == pytest.approx(1 / 3)  # the -7 m second return of pulse 0
    assert m["extra_per_pulse"] == pytest.approx(3 / 3)
    assert m["median_position_diff_m"] == pytest.approx(0.05)
    assert m["class_agreement"] == 1.0


def test_a_return_further_than_the_tolerance_is_not_the_same_return():
    reference = _points([0], [-5.0])
    near = _points([0], [-5.0 + 0.9 * MATCH_TOLERANCE_M])
    far = _points([0], [-5.0 + 1.1 * MATCH_TOLERANCE_M])
    assert vs_reference(near, reference, 1)["missing_per_pulse"] == 0.0
    m = vs_reference(far, reference, 1)
    assert (m["missing_per_pulse"], m["extra_per_pulse"], m["class_agreement"]) == (1.0, 1.0, None)


def test_class_agreement_is_the_share_of_partners_with_the_same_class():
    reference = _points([0, 1, 2, 3], [-5] * 4, classification=[2, 2, 5, 5])
    points = _points([0, 1, 2, 3], [-5] * 4, classification=[2, 5, 5, 2])
    assert vs_reference(points, reference, 4)["class_agreement"] == 0.5


def _records(codes, window_pulse, window_start, mode, n_pulses):
    return Waveforms(reference=np.zeros((n_pulses, 4), np.uint16), codes=np.asarray(codes, np.uint16),
                   window_pulse=np.asarray(window_pulse, np.int64), window_start=np.asarray(window_start, np.int64),
                   phase_s=np.zeros(n_pulses), mode=mode)


def test_waveform_r2_compares_each_window_with_the_same_samples_of_the_full_record():
    """Two pulses, one channel, 6 samples in full. A window of 3 samples starting at sample 2 of pulse 1 that
    copies the reference has R^2 = 1; one that is off by 1 LSB in one sample has 1 - 1 / SS_tot, SS_tot the
    spread of those 3 reference samples (10, 40, 10: mean 20, SS_tot 600)."""
    full = _records([[[0, 0, 0, 0, 0, 0]], [[5, 5, 10, 40, 10, 5]]], [0, 1], [0, 0], "full", 2)
    same = _records([[[10, 40, 10]]], [1], [2], "windowed", 2)
    assert WaveformFit.of(same, full).r2 == 1.0
    off = _records([[[10, 41, 10]]], [1], [2], "windowed", 2)
    assert WaveformFit.of(off, full).r2 == pytest.approx(1.0 - 1.0 / 600.0)
    shifted = _records([[[5, 10, 40]]], [1], [1], "windowed", 2)  # the right samples from the right place
    assert WaveformFit.of(shifted, full).r2 == 1.0
    wrong_place = _records([[[10, 40, 10]]], [1], [1], "windowed", 2)
    assert WaveformFit.of(wrong_place, full).r2 < 0.0


def test_waveform_r2_counts_only_the_channels_a_window_synthesised():
    """Two channels, one window: channel 2 was left out (its codes 0, ``synthesised`` False), so R^2 is channel 1's
    alone, 1 when it copies the reference; without the mask the zeros would count as a misfit."""
    from dataclasses import replace

    full = _records([[[5, 10, 40, 10], [7, 9, 30, 9]]], [0], [0], "full", 1)
    kept = replace(_records([[[5, 10, 40, 10], [0, 0, 0, 0]]], [0], [0], "windowed", 1),
                   synthesised=np.array([[True, False]]))
    fit = WaveformFit.of(kept, full)
    assert fit.count == 4 and fit.r2 == 1.0
    assert WaveformFit.of(replace(kept, synthesised=None), full).r2 < 0.5


def test_waveform_sums_add_over_chunks_like_one_batch():
    full = _records([[[1, 2, 3, 9]], [[4, 8, 1, 0]]], [0, 1], [0, 0], "full", 2)
    level = _records([[[1, 2, 4, 9]], [[4, 6, 1, 0]]], [0, 1], [0, 0], "full", 2)
    first = _records([[[1, 2, 3, 9]]], [0], [0], "full", 1)
    second = _records([[[4, 8, 1, 0]]], [0], [0], "full", 1)
    a = _records([[[1, 2, 4, 9]]], [0], [0], "full", 1)
    b = _records([[[4, 6, 1, 0]]], [0], [0], "full", 1)
    whole = WaveformFit.of(level, full).r2
    assert (WaveformFit.of(a, first) + WaveformFit.of(b, second)).r2 == pytest.approx(whole)
    ref = np.array([1, 2, 3, 9, 4, 8, 1, 0], float)
    assert whole == pytest.approx(1 - 5.0 / np.sum((ref - ref.mean()) ** 2))  # residuals 1 and 2 LSB: 1 + 4


def test_waveform_fit_refuses_a_windowed_reference():
    w = _records([[[1, 2]]], [0], [0], "windowed", 1)
    with pytest.raises(ValueError, match="expected 'full'"):
        WaveformFit.of(w, w)
