"""Maximum detectable range (paper section 5, Table 3)."""

from __future__ import annotations

import time

import numpy as np

from ..infra.errors import check_fraction, check_positive
from ..optics.optical_model import OpticalModel
from ..photon_budget import LIMITS, channel_budget, limiting_cause
from ..presets import designed_mul, single_channel, study_water
from ..simulate import simulate
from ..water.properties import Water
from .common import (
    COARSE_CHUNK,
    COARSE_START_M,
    COARSE_STEP_M,
    COARSE_STOP_FRACTION,
    DETECTION_FRACTION,
    DETECTION_TOLERANCE_BINS,
    FAR_GATE_LEAD_S,
    FAR_GATE_STEP_S,
    FAR_GATE_WIDTH_S,
    FINE_STEP_M,
    MAXRANGE_WATERS,
    _list,
    _shots,
    _water,
    detections,
    far_gate_delay_s,
    range_tolerance_m,
    truth_batch,
)


def _fraction(detected: np.ndarray, shots: int) -> np.ndarray:
    return detected.reshape(-1, shots).mean(axis=1)


def _single_fractions(model: OpticalModel, ranges_m, shots, reflectance, seed, first_id) -> dict:
    """{"single": (n_ranges,)} share of shots whose chosen return detects the panel (:func:`detections`); one batch."""
    truth, batch = truth_batch(model.instrument, ranges_m, shots, reflectance, first_id)
    _, ranging = simulate(model, batch, seed, mode="windowed")
    error, _ = detections(ranging.returns, truth, range_tolerance_m(model))
    return {"single": _fraction(np.isfinite(error), shots)}


def _mul_model(water: Water, gate_delay_s: float) -> OpticalModel:
    """The designed MUL (:func:`muls.presets.designed_mul`) with CH3 gated from ``gate_delay_s``."""
    return OpticalModel.build(designed_mul(water, float(gate_delay_s), FAR_GATE_WIDTH_S), water)


def _mul_fractions(water: Water, ranges_m, shots, reflectance, seed, first_id) -> dict:
    """{"near", "far", "total": (n_ranges,)} for the MUL with CH3 gated for each range (far_gate_delay_s).

    Ranges sharing a gate delay go through one :func:`simulate` call; near = nearest CH1/CH2 peak,
    far = nearest CH3 peak, total = nearest chosen return, each detecting the panel (:func:`detections`).
    """
    delays = far_gate_delay_s(ranges_m, water.speed_m_s)
    out = {g: np.zeros(ranges_m.shape[0]) for g in ("near", "far", "total")}
    for delay in np.unique(delays):
        idx = np.nonzero(delays == delay)[0]
        model = _mul_model(water, delay)
        truth, batch = truth_batch(model.instrument, ranges_m[idx], shots, reflectance, first_id, idx)
        _, ranging = simulate(model, batch, seed, mode="windowed")
        tol = range_tolerance_m(model)
        for group, channels, peaks in (("near", (1, 2), ranging.peaks), ("far", (3,), ranging.peaks),
                                       ("total", None, ranging.returns)):
            error, _ = detections(peaks, truth, tol, channels)
            out[group][idx] = _fraction(np.isfinite(error), shots)
    return out


GROUP_CHANNELS = {"single": ("ch1",), "near": ("ch1", "ch2"), "far": ("ch3",), "total": ("ch1", "ch2", "ch3")}
#: The most ranges one simulate call of the scan holds (x shots pulses): a coarse chunk, or the fine steps above
#: the four groups' edges, simulated together.
MAX_BATCH_RANGES = max(COARSE_CHUNK, len(GROUP_CHANNELS) * (round(COARSE_STEP_M / FINE_STEP_M) - 1))


def _limit(water: Water, single: OpticalModel, group: str, edge_m, reflectance: float) -> dict | None:
    """What stops a group one fine step beyond its maximum range: :func:`muls.photon_budget.limiting_cause` of its
    channel with the best SNR there (the gate, the column, too few photons, or the largest noise term), with
    that channel's SNR and the terms behind it."""
    if edge_m is None:
        return None
    r = round(edge_m + FINE_STEP_M, 6)
    model = single if group == "single" else _mul_model(water, float(far_gate_delay_s(r, water.speed_m_s)))
    _, budget = channel_budget(model, r, reflectance)
    name = max(GROUP_CHANNELS[group], key=lambda c: budget[c]["snr"])
    b = budget[name]
    cause = limiting_cause(b, model.instrument.processing.threshold_sigma)
    return {"range_m": r, "channel": name, "cause": cause, "snr": round(b["snr"], 3),
            "photon_limited_snr": None if b["photon_limited_snr"] is None else round(b["photon_limited_snr"], 3),
            "peak_lsb": round(b["peak_lsb"], 4), "noise_terms_lsb": {k: round(v, 4) for k, v in b["noise_terms_lsb"].items()},
            "photoelectrons": round(b["photoelectrons"], 2)}


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
    mul = _mul_model(water, 0.0).instrument
    return {
        "single_channel_m": edges["single"],
        "near_field_m": edges["near"],
        "far_field_m": edges["far"],
        "total_m": total,
        "improvement": None if not (total and edges["single"]) else round(total / edges["single"], 3),
        "near_far_max_m": max((e for e in (edges["near"], edges["far"]) if e is not None), default=None),
        "single_channel_gain": single.instrument.channels[0].gain,
        "gains": {"single": single.instrument.channels[0].gain, "pmt1": mul.channel("ch1").gain,
                  "pmt2": mul.channel("ch3").gain},
        "limits": {g: _limit(water, single, g, edges[g], reflectance) for g in groups},
        "range_tolerance_m": range_tolerance_m(single),
        "curves": {"range_m": _list(all_r, 4), **{g: _list(curves[g], 4) for g in groups}},
    }


def maxrange_study(waters=MAXRANGE_WATERS, shots: int = 200, reflectance: float = 0.1, seed: int = 0,
                   detection_fraction: float = DETECTION_FRACTION, max_range_m: float | None = None,
                   attenuation_model: str | None = None) -> dict:
    """Maximum detectable range [m] per water: single channel, MUL near field, far field, total.

    A range is detectable when, of ``shots`` seeded pulses on a flat panel (``reflectance``, normal
    incidence), at least ``detection_fraction`` detect it (:func:`detections`: a range within 3 range bins
    of the truth, or a clipped peak the echo explains); the maximum
    range is the largest detectable range scanned (coarse 1 m grid, then 0.1 m above the edge). Single and
    total use the chosen returns (``Ranging.returns``) of ``single_channel(water)`` and of the MUL; near
    and far use the MUL's per-channel peaks (CH1 or CH2; CH3 with its gate placed for each range by
    :func:`far_gate_delay_s`). Gains as a designer sets them: the single channel and PMT1 (through CH2) the
    highest that keeps the water column unclipped, CH1 nine times CH2 by the split, PMT2 20,000
    (:func:`muls.presets.designed_mul`). ``attenuation_model``: the rule every water uses (None: as each
    water is configured). Windowed records. Returns {water: {single_channel_m, near_field_m, far_field_m,
    total_m, improvement, near_far_max_m, single_channel_gain, gains, limits, range_tolerance_m, curves}},
    plus ``settings``; a range is None when no scanned range passes; ``limits`` says what stops each group.
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
        w = study_water(_water(name), attenuation_model)
        out[w.name] = _max_range_one_water(w, shots, float(reflectance), int(seed), float(detection_fraction),
                                           max_range_m)
    out["settings"] = {
        "waters": [_water(n).name for n in names], "shots": shots,
        "attenuation_model": attenuation_model or "as each water is configured",
        "gains": ("single channel and PMT1 (through CH2): the highest gain <= 20000 keeping the water column "
                  "unclipped; CH1 = 9 x CH2 by the split; PMT2 (CH3) at 20000"),
        "limits": f"one fine step beyond each edge, the cause of its best channel: {', '.join(LIMITS)}",
        "reflectance": float(reflectance),
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
