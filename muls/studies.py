"""Studies of the MULS paper's questions, each a function that returns a plain, JSON-ready dict.

- :func:`waveform_study`: CH0-CH3 of one pulse, noisy over noise-free (paper Figures 7, 8, 10, 12);
- :func:`maxrange_study`: maximum detectable range, single channel vs the MUL's near and far fields
  (paper section 5, Figure 14 and Table 3);
- :func:`precision_study`: range precision and mean deviation per channel (paper Table 2, Figure 11);
- :func:`coaxial_study`: water-column backscatter of coaxial vs non-coaxial optics (paper Figure 13);
- :func:`bench_study`: pulses per second of :func:`muls.simulate.simulate` on this machine.

Every study goes through the instrument's own digitiser and ranging (:func:`muls.simulate.simulate`);
randomness comes only from the ``seed`` given to it, and each shot has its own pulse id. Units are SI
inside; JSON keys carry the unit (``_m``, ``_ns``, ``_w``). The decisions behind each study (gate
placement, detection criterion, shots) are written down in docs/studies.md.
"""

from __future__ import annotations

import math
import os
import platform
import time

import numpy as np

from .detection import digitise
from .errors import ParameterError, check_fraction, check_positive
from .peaks import Peaks
from .presets import POND_GATE_S, POOL_GATE_S, coaxial, mul2023, single_channel, water_preset
from .ranging import DROPOUT_CAUSES, range_batch
from .simulate import simulate
from .water import Water
from .waveform import OpticalModel, PulseBatch

#: Detection criterion of the maximum-range and precision studies: a measured range counts as the target
#: when it lies within this many range bins (c_w x sample interval / 2) of the truth.
DETECTION_TOLERANCE_BINS = 3
#: Share of seeded pulses that must detect the target for a range to count as detectable (issue 2).
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


def nearest_to_truth(peaks: Peaks, truth_m: np.ndarray, channels=None) -> tuple[np.ndarray, np.ndarray]:
    """Per pulse, the signed error [m] of the peak (or return) nearest the truth, and whether it was clipped.

    peaks: any :class:`muls.ranging.Peaks` (``Ranging.peaks`` or ``Ranging.returns``); truth_m: (n_pulses,)
    true ranges [m]; channels: 1-based channel indices to keep, or None for all. Returns (n_pulses,) float
    errors (NaN where the pulse has no peak on those channels) and (n_pulses,) bool saturated flags.
    """
    keep = np.ones(peaks.pulse.shape[0], bool) if channels is None else np.isin(peaks.channel, channels)
    pulse = peaks.pulse[keep]
    error = peaks.range_m[keep] - truth_m[pulse]
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


# ----------------------------------------------------------------------------------------------------------
# 1. One pulse, every channel (paper Figures 7 and 8)


def waveform_study(water: str | Water = "pond", range_m: float = 11.5, seed: int = 0, reflectance: float = 0.1,
                   gate_delay_s: float | None = None, gate_width_s: float | None = None) -> dict:
    """CH0-CH3 full records [LSB] of one pulse of the MUL on a flat panel, noisy and noise-free.

    water: preset name or Water; range_m: panel range [m]; reflectance: Lambertian reflectance [0, 1];
    gate: CH3's gate [s], by default the one of the paper's experiment in that water (pond 100/400 ns,
    pool 150/400 ns, the pond's elsewhere). Returns ``time_ns`` (n_samples,) sample times after emission,
    ``channels`` and ``noise_free`` {"ch0".."ch3": (n_samples,) LSB}, ``returns`` (what the instrument's
    ranging made of the pulse), ``dropout_cause`` and ``settings``.
    """
    w = _water(water)
    range_m = float(_ranges("range_m", range_m)[0])
    check_fraction("reflectance", reflectance)
    delay, width = _gate(w, gate_delay_s, gate_width_s)
    instrument = mul2023(gate_delay_s=delay, gate_width_s=width)
    model = OpticalModel.build(instrument, w)
    batch = PulseBatch.flat_target(instrument, [range_m], reflectance, pulse_id=[0])
    records, ranging = simulate(model, batch, seed, mode="full", keep_noise_free=True)
    names = ("ch0",) + instrument.channel_names
    noisy = [records.reference[0]] + [records.codes[0, j] for j in range(len(instrument.channels))]
    clean = [records.reference_noise_free_lsb[0]] + [records.noise_free_lsb[0, j]
                                                      for j in range(len(instrument.channels))]
    ret = ranging.returns
    cause = int(ranging.dropout_cause[0])
    return {
        "time_ns": _list(records.sample_times_s(model)[0] * 1e9, 4),
        "channels": {n: np.asarray(v).astype(int).tolist() for n, v in zip(names, noisy)},
        "noise_free": {n: _list(v, 3) for n, v in zip(names, clean)},
        "returns": [
            {"channel": names[int(c)], "range_m": _num(r, 4), "error_m": _num(r - range_m, 4),
             "amplitude_lsb": _num(a, 2), "snr": _num(s, 2), "saturated": bool(sat)}
            for c, r, a, s, sat in zip(ret.channel, ret.range_m, ret.amplitude_lsb, ret.snr, ret.saturated)
        ],
        "peaks": [
            {"channel": names[int(c)], "range_m": _num(r, 4), "saturated": bool(sat)}
            for c, r, sat in zip(ranging.peaks.channel, ranging.peaks.range_m, ranging.peaks.saturated)
        ],
        "dropout_cause": None if cause < 0 else DROPOUT_CAUSES[cause],
        "settings": {
            "water": w.name, "instrument": instrument.name, "range_m": range_m, "reflectance": float(reflectance),
            "seed": int(seed), "record_mode": "full", "gate_delay_ns": delay * 1e9, "gate_width_ns": width * 1e9,
            "sample_interval_ns": instrument.digitizer.sample_interval_s * 1e9,
            "max_code": instrument.digitizer.max_code, "speed_m_s": w.speed_m_s,
        },
    }


# ----------------------------------------------------------------------------------------------------------
# 2. Maximum detectable range (paper section 5, Table 3)


def _truth_batch(instrument, ranges_m: np.ndarray, shots: int, reflectance: float, first_id: int, index=None):
    """``shots`` pulses per range, range-major; pulse ids first_id + index * shots + shot (distinct shots)."""
    index = np.arange(ranges_m.shape[0]) if index is None else np.asarray(index)
    truth = np.repeat(ranges_m, shots)
    ids = first_id + (index[:, None] * shots + np.arange(shots)[None, :]).ravel().astype(np.int64)
    return truth, PulseBatch.flat_target(instrument, truth, reflectance, pulse_id=ids)


def _fraction(detected: np.ndarray, shots: int) -> np.ndarray:
    return detected.reshape(-1, shots).mean(axis=1)


def _single_fractions(model: OpticalModel, ranges_m, shots, reflectance, seed, first_id) -> dict:
    """{"single": (n_ranges,)} share of shots whose chosen return lies within tolerance; one batch."""
    truth, batch = _truth_batch(model.instrument, ranges_m, shots, reflectance, first_id)
    _, ranging = simulate(model, batch, seed, mode="windowed")
    error, _ = nearest_to_truth(ranging.returns, truth)
    return {"single": _fraction(np.abs(error) <= range_tolerance_m(model), shots)}


def _mul_fractions(water: Water, ranges_m, shots, reflectance, seed, first_id) -> dict:
    """{"near", "far", "total": (n_ranges,)} for the MUL with CH3 gated for each range (far_gate_delay_s).

    Ranges sharing a gate delay go through one :func:`simulate` call; near = nearest CH1/CH2 peak,
    far = nearest CH3 peak, total = nearest chosen return, each within tolerance.
    """
    delays = far_gate_delay_s(ranges_m, water.speed_m_s)
    out = {g: np.zeros(ranges_m.shape[0]) for g in ("near", "far", "total")}
    for delay in np.unique(delays):
        idx = np.nonzero(delays == delay)[0]
        model = OpticalModel.build(mul2023(gate_delay_s=float(delay), gate_width_s=FAR_GATE_WIDTH_S), water)
        truth, batch = _truth_batch(model.instrument, ranges_m[idx], shots, reflectance, first_id, idx)
        _, ranging = simulate(model, batch, seed, mode="windowed")
        tol = range_tolerance_m(model)
        for group, channels, peaks in (("near", (1, 2), ranging.peaks), ("far", (3,), ranging.peaks),
                                       ("total", None, ranging.returns)):
            error, _ = nearest_to_truth(peaks, truth, channels)
            out[group][idx] = _fraction(np.abs(error) <= tol, shots)
    return out


def _largest_passing(ranges_m: np.ndarray, fraction: np.ndarray, level: float):
    ok = fraction >= level
    return float(ranges_m[ok].max()) if ok.any() else None


def _max_range_one_water(water: Water, shots: int, reflectance: float, seed: int, level: float,
                         max_range_m: float | None) -> dict:
    """Coarse scan in chunks until nothing is detectable, then a fine scan above each group's edge."""
    single = OpticalModel.build(single_channel(water), water)
    dig = single.instrument.digitizer
    record_end_m = 0.5 * water.speed_m_s * (dig.record_length_s - 64 * dig.sample_interval_s)
    stop_m = record_end_m if max_range_m is None else min(max_range_m, record_end_m)
    groups = ("single", "near", "far", "total")
    seen_r: list[np.ndarray] = []
    seen_f: dict[str, list[np.ndarray]] = {g: [] for g in groups}
    ids = 0

    def run(ranges):
        nonlocal ids
        ranges = np.asarray(ranges, float)
        fr = _single_fractions(single, ranges, shots, reflectance, seed, ids)
        fr.update(_mul_fractions(water, ranges, shots, reflectance, seed, ids))
        ids += ranges.shape[0] * shots
        seen_r.append(ranges)
        for g in groups:
            seen_f[g].append(fr[g])
        return fr

    start = COARSE_START_M
    while start <= stop_m:
        chunk = np.arange(COARSE_CHUNK) * COARSE_STEP_M + start
        chunk = chunk[chunk <= stop_m]
        fr = run(chunk)
        start = chunk[-1] + COARSE_STEP_M
        if max(float(fr[g].max()) for g in groups) < COARSE_STOP_FRACTION:
            break
    coarse_r = np.concatenate(seen_r)
    fine = set()
    for g in groups:
        edge = _largest_passing(coarse_r, np.concatenate(seen_f[g]), level)
        if edge is not None:
            fine.update(np.round(edge + FINE_STEP_M * np.arange(1, round(COARSE_STEP_M / FINE_STEP_M)), 6))
    fine = np.array(sorted(r for r in fine if r <= stop_m and r not in set(np.round(coarse_r, 6))))
    if fine.size:
        run(fine)
    all_r = np.concatenate(seen_r)
    order = np.argsort(all_r, kind="stable")
    curves = {g: np.concatenate(seen_f[g])[order] for g in groups}
    all_r = all_r[order]
    edges = {g: _largest_passing(all_r, curves[g], level) for g in groups}
    total = edges["total"]
    return {
        "single_channel_m": edges["single"],
        "near_field_m": edges["near"],
        "far_field_m": edges["far"],
        "total_m": total,
        "improvement": None if not (total and edges["single"]) else round(total / edges["single"], 3),
        "near_far_max_m": max((e for e in (edges["near"], edges["far"]) if e is not None), default=None),
        "single_channel_gain": single.instrument.channels[0].gain,
        "range_tolerance_m": range_tolerance_m(single),
        "curves": {"range_m": _list(all_r, 4), **{g: _list(curves[g], 4) for g in groups}},
    }


def maxrange_study(waters=MAXRANGE_WATERS, shots: int = 200, reflectance: float = 0.1, seed: int = 0,
                   detection_fraction: float = DETECTION_FRACTION, max_range_m: float | None = None) -> dict:
    """Maximum detectable range [m] per water: single channel, MUL near field, far field, total.

    A range is detectable when, of ``shots`` seeded pulses on a flat panel (``reflectance``, normal
    incidence), at least ``detection_fraction`` give a range within 3 range bins of the truth; the maximum
    range is the largest detectable range scanned (coarse 1 m grid, then 0.1 m above the edge). Single and
    total use the chosen returns (``Ranging.returns``) of ``single_channel(water)`` and of the MUL; near
    and far use the MUL's per-channel peaks (CH1 or CH2; CH3 with its gate placed for each range by
    :func:`far_gate_delay_s`). Windowed records. Returns {water: {single_channel_m, near_field_m,
    far_field_m, total_m, improvement, near_far_max_m, single_channel_gain, range_tolerance_m, curves}},
    plus ``settings``; a range is None when no scanned range passes.
    """
    shots = _shots("shots", shots)
    check_fraction("reflectance", reflectance)
    check_fraction("detection_fraction", detection_fraction, open_low=True)
    if max_range_m is not None:
        check_positive("max_range_m", max_range_m)
    names = [waters] if isinstance(waters, (str, Water)) else list(waters)
    out = {}
    t0 = time.perf_counter()
    for name in names:
        w = _water(name)
        out[w.name] = _max_range_one_water(w, shots, float(reflectance), int(seed), float(detection_fraction),
                                           max_range_m)
    out["settings"] = {
        "waters": [_water(n).name for n in names], "shots": shots, "reflectance": float(reflectance),
        "incidence_deg": 0.0, "seed": int(seed), "detection_fraction": float(detection_fraction),
        "tolerance_bins": DETECTION_TOLERANCE_BINS, "record_mode": "windowed",
        "coarse_step_m": COARSE_STEP_M, "fine_step_m": FINE_STEP_M, "coarse_start_m": COARSE_START_M,
        "far_gate": (f"CH3 delay = {FAR_GATE_STEP_S * 1e9:g} ns x floor((2R/c_w - {FAR_GATE_LEAD_S * 1e9:g} ns)"
                     f" / {FAR_GATE_STEP_S * 1e9:g} ns), width {FAR_GATE_WIDTH_S * 1e9:g} ns: opens 20-30 ns"
                     " before the echo starts"),
        "near_field": "nearest CH1 or CH2 peak (Ranging.peaks)", "far_field": "nearest CH3 peak (Ranging.peaks)",
        "single_and_total": "chosen returns (Ranging.returns)",
        "elapsed_s": round(time.perf_counter() - t0, 2),
    }
    return out


# ----------------------------------------------------------------------------------------------------------
# 3. Range precision per channel (paper Table 2, Figure 11)


def _stats(error: np.ndarray, saturated: np.ndarray, tol: float) -> dict:
    detected = np.abs(error) <= tol
    e = error[detected]
    n = int(e.shape[0])
    return {
        "precision_m": _num(np.std(e, ddof=1), 5) if n >= 2 else None,
        "mean_deviation_m": _num(np.mean(e), 5) if n >= 1 else None,
        "detected_fraction": round(n / error.shape[0], 4),
        "saturated_fraction": round(float(saturated[detected].mean()), 4) if n else None,
        "detections": n,
    }


def precision_study(water: str | Water = "pond", ranges_m=(8.5, 10.0, 11.5), shots: int = 1000, seed: int = 0,
                    reflectance: float = 0.1, gate_delay_s: float | None = None,
                    gate_width_s: float | None = None, record_mode: str = "windowed") -> dict:
    """Range precision and mean deviation [m] per channel of static pulses on a flat panel.

    Each channel is ranged on its own: per shot, its peak nearest the truth (``Ranging.peaks``), kept when
    within 3 range bins. ``precision_m`` is the sample std of the kept ranges, ``mean_deviation_m`` their
    mean minus the truth, ``detected_fraction`` kept shots over all shots, ``saturated_fraction`` clipped
    peaks among the kept ones. ``chosen`` gives the same for the instrument's chosen returns. The CH3 gate is
    that of the paper's experiment in the water unless given [s]. Returns {"8.5": {"ch1": {...}, "ch2":
    {...}, "ch3": {...}, "chosen": {...}}, ..., "settings": {...}}; precision is None below 2 detections.
    """
    w = _water(water)
    r = _ranges("ranges_m", ranges_m)
    shots = _shots("shots", shots)
    check_fraction("reflectance", reflectance)
    delay, width = _gate(w, gate_delay_s, gate_width_s)
    instrument = mul2023(gate_delay_s=delay, gate_width_s=width)
    model = OpticalModel.build(instrument, w)
    truth, batch = _truth_batch(instrument, r, shots, float(reflectance), 0)
    _, ranging = simulate(model, batch, seed, mode=record_mode)
    tol = range_tolerance_m(model)
    out = {}
    per_channel = {name: nearest_to_truth(ranging.peaks, truth, (j + 1,))
                   for j, name in enumerate(instrument.channel_names)}
    per_channel["chosen"] = nearest_to_truth(ranging.returns, truth)
    for i, range_m in enumerate(r):
        rows = slice(i * shots, (i + 1) * shots)
        out[f"{range_m:g}"] = {name: _stats(err[rows], sat[rows], tol) for name, (err, sat) in per_channel.items()}
    out["settings"] = {
        "water": w.name, "instrument": instrument.name, "ranges_m": r.tolist(), "shots": shots, "seed": int(seed),
        "reflectance": float(reflectance), "gate_delay_ns": delay * 1e9, "gate_width_ns": width * 1e9,
        "record_mode": record_mode, "tolerance_bins": DETECTION_TOLERANCE_BINS, "tolerance_m": tol,
        "speed_m_s": w.speed_m_s,
    }
    return out


# ----------------------------------------------------------------------------------------------------------
# 4. Coaxial vs non-coaxial backscatter (paper Figure 13)


def coaxial_study(water: str | Water = "turbid_harbor", t_max_ns: float = 200.0, step_ns: float = 0.2) -> dict:
    """Noise-free water-column power [W] of ``coaxial()`` and ``mul2023()``, both as non-gated receivers.

    The column alone (MULS Eq. 4 convolved with the pulse, no target: ``OpticalModel.column_power_w``) on
    a grid of ``step_ns`` up to ``t_max_ns`` after emission; same parameters except the transceiver offset
    (0 vs 130 mm). The coaxial design's window return (Eq. 3), a separate echo at the window, is reported
    as ``coaxial_window_peak_w`` and left out of the curves and the ratio. ``peak_ratio`` = peak coaxial /
    peak non-coaxial column power.
    """
    w = _water(water)
    check_positive("t_max_ns", t_max_ns)
    check_positive("step_ns", step_ns)
    t = np.arange(0.0, t_max_ns + 0.5 * step_ns, step_ns) * 1e-9
    co_model = OpticalModel.build(coaxial(), w)
    non_model = OpticalModel.build(mul2023(), w)
    co = co_model.column_power_w(t)
    non = non_model.column_power_w(t)
    energy = co_model.echoes(PulseBatch.flat_target(co_model.instrument, [np.inf])).energy_j
    window_peak = float(energy.max() * co_model.instrument.pulse(co_model.instrument.pulse.peak_delay_s)) \
        if energy.size else 0.0
    geometry = non_model.instrument.geometry
    return {
        "peak_ratio": float(co.max() / non.max()),
        "time_ns": _list(t * 1e9, 4),
        "range_m": _list(0.5 * w.speed_m_s * t, 4),
        "coaxial_w": _list(co),
        "non_coaxial_w": _list(non),
        "coaxial_peak_w": float(co.max()),
        "non_coaxial_peak_w": float(non.max()),
        "coaxial_peak_time_ns": float(t[np.argmax(co)] * 1e9),
        "non_coaxial_peak_time_ns": float(t[np.argmax(non)] * 1e9),
        "coaxial_window_peak_w": window_peak,
        "settings": {
            "water": w.name, "quantity": "noise-free water-column power at the receiver (no target)",
            "t_max_ns": float(t_max_ns), "step_ns": float(step_ns),
            "non_coaxial_offset_m": non_model.instrument.receiver.offset_m,
            "blind_zone_m": geometry.blind_zone_m, "full_overlap_m": geometry.full_overlap_m,
            "k_per_m": w.two_way_attenuation_per_m, "beta_pi_per_m_sr": w.beta_pi_per_m_sr,
        },
    }


# ----------------------------------------------------------------------------------------------------------
# 5. Speed of simulate on this machine


def _machine() -> dict:
    import numba

    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    return {
        "cpu_count": os.cpu_count(), "numba_threads": numba.get_num_threads(),
        "numba_threading_layer": _threading_layer(), "numba_version": numba.__version__,
        "numpy_version": np.__version__, "python": platform.python_version(), "machine": platform.machine(),
        "loadavg_1_5_15": [round(v, 2) for v in load],
    }


def _threading_layer() -> str | None:
    import numba

    try:
        return numba.threading_layer()
    except ValueError:  # no parallel kernel has run yet
        return None


def bench_study(pulses: int = 100_000, full_pulses: int = 10_000, water: str | Water = "coastal_ocean",
                repeats: int = 3, seed: int = 0) -> dict:
    """Pulses per second of :func:`muls.simulate.simulate` (waveform + digitising + ranging).

    Flat 0.1-reflectance targets evenly spread between 2 and 40 m (``np.linspace``), MUL with the pond gate,
    ``pulses`` in windowed mode and ``full_pulses`` in full-record mode, after a warm-up call per mode that
    compiles the kernels. Each mode is timed ``repeats`` times; the reported rate is the median, with the
    digitise / ranging split of that run (``simulate`` is exactly ``digitise`` then ``range_batch``).
    """
    pulses = _shots("pulses", pulses)
    full_pulses = _shots("full_pulses", full_pulses)
    repeats = _shots("repeats", repeats)
    w = _water(water)
    instrument = mul2023()
    model = OpticalModel.build(instrument, w)
    machine_before = _machine()
    for mode in ("windowed", "full"):  # warm-up: compile (or load the cached) kernels
        simulate(model, PulseBatch.flat_target(instrument, np.linspace(2.0, 40.0, 64)), seed, mode=mode)
    result = {}
    for mode, n in (("windowed", pulses), ("full", full_pulses)):
        batch = PulseBatch.flat_target(instrument, np.linspace(2.0, 40.0, n), 0.1)
        runs = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            records = digitise(model, batch, seed, mode=mode)
            t1 = time.perf_counter()
            ranging = range_batch(model, batch, records)
            t2 = time.perf_counter()
            runs.append((t2 - t0, t1 - t0, t2 - t1, int(ranging.returns.pulse.shape[0])))
        runs.sort()
        total, dig_s, rng_s, n_returns = runs[len(runs) // 2]
        result[mode] = {
            "pulses": n, "pulses_per_s": round(n / total, 1), "seconds": round(total, 4),
            "digitise_s": round(dig_s, 4), "range_batch_s": round(rng_s, 4),
            "best_pulses_per_s": round(n / runs[0][0], 1), "all_seconds": [round(r[0], 4) for r in runs],
            "returns": n_returns, "windows": int(records.codes.shape[0]), "samples_per_window": int(records.codes.shape[2]),
        }
    return {
        "windowed_pulses_per_s": result["windowed"]["pulses_per_s"],
        "full_record_pulses_per_s": result["full"]["pulses_per_s"],
        "targets": {"windowed_pulses_per_s": 100_000, "full_record_pulses_per_s": 10_000},
        "windowed": result["windowed"], "full_record": result["full"],
        "machine": {**_machine(), "loadavg_before_1_5_15": machine_before["loadavg_1_5_15"]},
        "settings": {"water": w.name, "instrument": instrument.name, "ranges_m": [2.0, 40.0], "reflectance": 0.1,
                     "repeats": repeats, "seed": int(seed),
                     "record_samples": instrument.digitizer.n_samples, "channels": len(instrument.channels) + 1},
    }
