"""Shared by the studies: detection criterion, gates, argument checks, JSON helpers."""

from __future__ import annotations

import math

import numpy as np

from ..infra.errors import ParameterError, check_positive
from ..infra.memory import check_memory
from ..optics.optical_model import OpticalModel, PulseBatch
from ..presets import POND_GATE_S, POOL_GATE_S, water_preset
from ..ranging.peaks import Peaks
from ..water.properties import Water

#: Detection criterion of the studies (:func:`detections`): a measured range counts as the target when it
#: lies within this many range bins (c_w x sample interval / 2) of the truth, or when its peak is clipped
#: and the target's echo explains it.
DETECTION_TOLERANCE_BINS = 3
#: Share of seeded pulses that must detect the target for a range to count as detectable.
DETECTION_FRACTION = 0.9
#: The three Petzold waters of the paper's Table 3.
MAXRANGE_WATERS = ("clean_ocean", "coastal_ocean", "turbid_harbor")
#: Far-field gate as a user places it for a target at range R: the delay is rounded down to a 10 ns step so
#: that the gate opens 20 to 30 ns before the echo starts (2 R / c_w), and it stays open 400 ns (the width
#: used in both of the paper's experiments).
FAR_GATE_LEAD_S = 20e-9
FAR_GATE_STEP_S = 10e-9
FAR_GATE_WIDTH_S = 400e-9
#: Range scan of the maximum-range study: a coarse grid, then a fine one above each group's last coarse
#: pass (the edge is resolved to FINE_STEP_M).
COARSE_START_M = 1.0
COARSE_STEP_M = 1.0
FINE_STEP_M = 0.1
#: Coarse ranges are simulated in chunks of this many; the scan stops after a chunk where no group reaches
#: this detection fraction anywhere (nothing beyond can pass the 90 % criterion).
COARSE_CHUNK = 10
COARSE_STOP_FRACTION = 0.1
#: Bytes a study's simulate call holds per pulse, by record mode: the growth of peak RSS between 10,000- and
#: 80,000-shot runs on the 2-core machine (muls experiment pond and pool, precision, maxrange in turbid_harbor,
#: bench: 1.3 to 1.9 kB a windowed pulse, 8.8 kB a full record), rounded up.
PULSE_BYTES = {"windowed": 3_000, "full": 12_000}


# ----------------------------------------------------------------------------------------------------------
# Shared helpers


def experiment_gate_s(water_name: str) -> tuple[float, float]:
    """(delay, width) [s] of CH3's gate in the paper's experiment in that water; the pond's elsewhere."""
    return POOL_GATE_S if water_name == "pool" else POND_GATE_S


def range_tolerance_m(model: OpticalModel, bins: int = DETECTION_TOLERANCE_BINS) -> float:
    """``bins`` range bins [m]: bins x c_w x sample interval / 2."""
    return bins * model.water.speed_m_s * model.instrument.digitizer.sample_interval_s / 2.0


def far_gate_delay_s(range_m, speed_m_s: float) -> np.ndarray:
    """CH3 gate delay [s] a user would set for a target at ``range_m`` (any shape) [m] (see FAR_GATE_*)."""
    start = 2.0 * np.asarray(range_m, float) / speed_m_s
    return np.maximum(0.0, np.floor((start - FAR_GATE_LEAD_S) / FAR_GATE_STEP_S) * FAR_GATE_STEP_S)


def detections(peaks: Peaks, truth_m: np.ndarray, tolerance_m: float, channels=None) -> tuple[np.ndarray, np.ndarray]:
    """Per pulse, the signed error [m] of the peak (or return) that detects its target, and whether it was
    clipped.

    A peak detects the target when it lies within ``tolerance_m`` of the truth, or when it is clipped and
    the pulse's echo explains it (``Peaks.echo_index`` >= 0; the studies' batches hold one target per
    pulse). Noise cannot reach the top code, so a clipped peak the echo explains is the echo, however its
    plateau was timed: plain peak detection (``peak_fit = "sample_maximum"``) times it at the plateau's
    first sample, which the pulse's rise can put several range bins ahead of the echo's peak. Of several
    detecting peaks, the one nearest the truth.

    peaks: any :class:`muls.ranging.returns.Peaks` (``Ranging.peaks`` or ``Ranging.returns``); truth_m: (n_pulses,)
    true ranges [m]; channels: 1-based channel indices to keep, or None for all. Returns (n_pulses,) float
    errors (NaN where no peak on those channels detects the target) and (n_pulses,) bool clipped flags.
    """
    error_all = peaks.range_m - truth_m[peaks.pulse]
    keep = np.abs(error_all) <= tolerance_m
    keep |= peaks.saturated & (peaks.echo_index >= 0)
    if channels is not None:
        keep &= np.isin(peaks.channel, channels)
    pulse = peaks.pulse[keep]
    error = error_all[keep]
    order = np.lexsort((np.abs(error), pulse))
    first = np.ones(order.shape[0], bool)
    first[1:] = pulse[order][1:] != pulse[order][:-1]
    best = order[first]
    out = np.full(truth_m.shape[0], np.nan)
    out[pulse[best]] = error[best]
    saturated = np.zeros(truth_m.shape[0], bool)
    saturated[pulse[best]] = peaks.saturated[keep][best]
    return out, saturated


def _water(water: str | Water) -> Water:
    return water if isinstance(water, Water) else water_preset(water)


def _ranges(key: str, values) -> np.ndarray:
    r = np.atleast_1d(np.asarray(values, float))
    if r.size == 0 or np.any(~np.isfinite(r)) or np.any(r <= 0.0):
        raise ParameterError(f"{key} = {np.asarray(values).tolist()!r}: every range must be a finite number > 0 [m]")
    return r


def _shots(key: str, shots) -> int:
    if isinstance(shots, bool) or int(shots) != shots or shots < 1:
        raise ParameterError(f"{key} = {shots!r}: must be an integer >= 1")
    return int(shots)


def check_pulse_memory(key: str, value: int, per_value: int, what: str, unit: str, mode: str = "windowed",
                       available_bytes: int | None = None) -> None:
    """Refuse, before allocating, ``key`` = ``value`` ``unit`` (shots, pulses) when one simulate call of ``value``
    x ``per_value`` pulses (``what``, e.g. "3 distances x 1,000 shots") would need more memory than a command
    may plan on (:func:`muls.infra.memory.check_memory`, :data:`PULSE_BYTES`)."""
    per = per_value * PULSE_BYTES[mode]
    check_memory(key, value, value * per, what, lambda budget: f"at most {int(budget // per):,} {unit} on this machine",
                 available_bytes)


def _gate(water: Water, gate_delay_s, gate_width_s) -> tuple[float, float]:
    delay, width = experiment_gate_s(water.name)
    delay = delay if gate_delay_s is None else gate_delay_s
    width = width if gate_width_s is None else gate_width_s
    if not (math.isfinite(delay) and delay >= 0.0):
        raise ParameterError(f"gate_delay_s = {delay!r}: must be >= 0")
    check_positive("gate_width_s", width)
    return float(delay), float(width)


def _list(a, digits: int | None = None) -> list:
    """JSON-ready list: NaN -> None, optional rounding."""
    a = np.asarray(a, float)
    if digits is not None:
        a = np.round(a, digits)
    return [None if not math.isfinite(v) else float(v) for v in a.tolist()]


def _num(v, digits: int | None = None):
    if v is None or not math.isfinite(v):
        return None
    return round(float(v), digits) if digits is not None else float(v)


def truth_batch(instrument, ranges_m: np.ndarray, shots: int, reflectance: float, first_id: int, index=None):
    """``shots`` pulses per range, range-major; pulse ids first_id + index * shots + shot (distinct shots)."""
    index = np.arange(ranges_m.shape[0]) if index is None else np.asarray(index)
    truth = np.repeat(ranges_m, shots)
    ids = first_id + (index[:, None] * shots + np.arange(shots)[None, :]).ravel().astype(np.int64)
    return truth, PulseBatch.flat_target(instrument, truth, reflectance, pulse_id=ids)
