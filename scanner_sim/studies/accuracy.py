"""How far a pass lies from the truth and from the reference level: error metrics that compare like with like.

Against the truth mesh (:func:`vs_truth`), each return is judged against the surface whose echo the instrument
ranged (``PointRecords.range_error_m``, see :func:`scanner_sim.survey.georeference.georeference`), so a second return is
judged against the second surface; a return that no echo explains is a false alarm. Against the reference
(:func:`vs_reference`), the same pulses of the same seed are compared return by return: each pulse's returns are
paired with the reference's by position (:func:`match_returns`), and what is left over is missing or extra.
Waveforms (:class:`WaveformFit`) are compared sample by sample over the samples both records hold. Every metric
is a pure function of records.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from muls.receiver.digitiser import Waveforms
from scanner_sim.records.point_records import PointRecords
from scanner_sim.survey.georeference import NO_OBJECT

#: [m] Largest distance at which a return is the same return as the reference's in the same pulse: under half the
#: range length of the 10 ns pulse in water (1.1 m, the nearest two returns of one pulse the ranging resolves), and
#: above any ranging error of a return that found its surface.
MATCH_TOLERANCE_M = 0.5


def _quantile(values: np.ndarray, q: float) -> float | None:
    return float(np.quantile(values, q)) if values.size else None


def vs_truth(points: PointRecords, n_pulses: int, hidden: np.ndarray | None = None) -> dict:
    """The points of ``n_pulses`` pulses against the truth mesh.

    ``points_per_pulse``; ``median_abs_range_error_m`` and ``p95_abs_range_error_m`` of the returns an echo
    explains (measured minus true range along the point's line of sight, to the surface it ranged);
    ``false_alarms_per_pulse``: returns no echo explains (noise class, object -1); ``hidden_points_per_pulse``:
    points on a surface the receiver cannot see (``hidden`` (n,) bool per point, None when not known).
    """
    n = max(int(n_pulses), 1)
    real = points.object_id != NO_OBJECT
    error = np.abs(points.range_error_m[real].astype(np.float64))
    error = error[np.isfinite(error)]
    return {
        "points_per_pulse": len(points) / n,
        "median_abs_range_error_m": _quantile(error, 0.5),
        "p95_abs_range_error_m": _quantile(error, 0.95),
        "false_alarms_per_pulse": int(np.count_nonzero(~real)) / n,
        "hidden_points_per_pulse": None if hidden is None else int(np.count_nonzero(hidden)) / n,
    }


def _same_pulse_pairs(pulse_a: np.ndarray, pulse_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every (i, j) with ``pulse_a[i] == pulse_b[j]``, as two index arrays (a pulse has at most 15 returns)."""
    order_b = np.argsort(pulse_b, kind="stable")
    sorted_b = pulse_b[order_b]
    lo = np.searchsorted(sorted_b, pulse_a, "left")
    count = np.searchsorted(sorted_b, pulse_a, "right") - lo
    i = np.repeat(np.arange(pulse_a.size), count)
    within = np.arange(i.size) - np.repeat(np.cumsum(count) - count, count)
    return i, order_b[np.repeat(lo, count) + within]


def _nearest(owner: np.ndarray, distance: np.ndarray, size: int) -> np.ndarray:
    """(size,) index of each owner's nearest pair (-1: no pair)."""
    best = np.full(size, -1)
    order = np.lexsort((distance, owner))
    first = np.ones(order.size, bool)
    first[1:] = owner[order][1:] != owner[order][:-1]
    best[owner[order][first]] = order[first]
    return best


def match_returns(points: PointRecords, reference: PointRecords, tolerance_m: float = MATCH_TOLERANCE_M
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i into ``points``, j into ``reference``) of the same return: same pulse, each the other's nearest
    return of that pulse, and closer than ``tolerance_m`` [m]. One-to-one; the rest are missing or extra."""
    i, j = _same_pulse_pairs(points.pulse_index, reference.pulse_index)
    distance = np.linalg.norm(points.xyz[i] - reference.xyz[j], axis=1)
    best_of_i = _nearest(i, distance, len(points))
    best_of_j = _nearest(j, distance, len(reference))
    pair = np.arange(i.size)
    mutual = (best_of_i[i] == pair) & (best_of_j[j] == pair) & (distance < tolerance_m)
    return i[mutual], j[mutual]


def vs_reference(points: PointRecords, reference: PointRecords, n_pulses: int) -> dict:
    """The points of a pass against the reference's points of the same ``n_pulses`` pulses and seed.

    ``missing_per_pulse``: reference returns with no partner; ``extra_per_pulse``: returns the reference does
    not have; ``median_position_diff_m`` and ``p95_position_diff_m``: distance between partners [m];
    ``class_agreement``: share of partners with the same class (None without partners).
    """
    n = max(int(n_pulses), 1)
    i, j = match_returns(points, reference)
    distance = np.linalg.norm(points.xyz[i] - reference.xyz[j], axis=1)
    return {
        "missing_per_pulse": (len(reference) - j.size) / n,
        "extra_per_pulse": (len(points) - i.size) / n,
        "median_position_diff_m": _quantile(distance, 0.5),
        "p95_position_diff_m": _quantile(distance, 0.95),
        "class_agreement": float(np.mean(points.classification[i] == reference.classification[j])) if i.size else None,
    }


@dataclass(frozen=True)
class WaveformFit:
    """Sums that give R^2 of a pass's digitised samples against the reference's same samples, over any number
    of chunks (add two with ``+``): count, sum and sum of squares of the reference samples, sum of squared
    differences [LSB^2]."""

    count: int = 0
    sum_ref: float = 0.0
    sum_ref_sq: float = 0.0
    sum_residual_sq: float = 0.0

    @classmethod
    def of(cls, records: Waveforms, reference: Waveforms) -> WaveformFit:
        """The sums over every signal sample ``records`` holds (of its synthesised channels), against the same
        sample of ``reference``, a ``full`` record of the same pulses (same order) and seed: the window of pulse p
        starting at sample s is compared with samples s.. of the reference's record of pulse p, channel by
        channel."""
        if reference.mode != "full":
            raise ValueError(f"reference records: mode {reference.mode!r}, expected 'full'")
        if records.n_pulses != reference.n_pulses:
            raise ValueError(f"records of {records.n_pulses} pulses against a reference of {reference.n_pulses}")
        width = records.codes.shape[2]
        samples = records.window_start[:, None] + np.arange(width)[None, :]  # (n_windows, width)
        ref = reference.codes[records.window_pulse[:, None, None], np.arange(records.codes.shape[1])[None, :, None],
                              samples[:, None, :]].astype(np.float64)
        diff = records.codes.astype(np.float64) - ref
        if records.synthesised is not None:  # channels left out of a window hold no samples
            held = np.broadcast_to(records.synthesised[:, :, None], ref.shape)
            ref, diff = ref[held], diff[held]
        return cls(ref.size, float(ref.sum()), float(np.square(ref).sum()), float(np.square(diff).sum()))

    def __add__(self, other: WaveformFit) -> WaveformFit:
        return WaveformFit(self.count + other.count, self.sum_ref + other.sum_ref, self.sum_ref_sq + other.sum_ref_sq,
                           self.sum_residual_sq + other.sum_residual_sq)

    @property
    def r2(self) -> float | None:
        """1 - (sum of squared differences) / (sum of squares of the reference about its mean); None when empty
        or the reference is constant."""
        total = self.sum_ref_sq - self.sum_ref**2 / self.count if self.count else 0.0
        return 1.0 - self.sum_residual_sq / total if total > 0.0 else None


def coverage_difference(coverage: float | None, reference_coverage: float | None) -> float | None:
    """Covered share of a pass minus the reference's (None when either is not known)."""
    return None if coverage is None or reference_coverage is None else coverage - reference_coverage
