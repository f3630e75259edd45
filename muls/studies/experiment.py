"""The paper's tank tests predicted: per distance and channel, detection, precision, deviation and clipping
(paper Table 2 and Figure 11), and one shot's waveforms per distance (Figures 7, 8 and 10)."""

from __future__ import annotations

import time

import numpy as np

from ..experiments import EXPERIMENT_SHOTS, RANGING, Experiment, experiment_preset
from ..optics.optical_model import OpticalModel, PulseBatch
from ..ranging.returns import DROPOUT_CAUSES
from ..simulate import simulate
from .common import DETECTION_TOLERANCE_BINS, _list, _num, _shots, detections, range_tolerance_m, truth_batch


def channel_stats(error: np.ndarray, saturated: np.ndarray) -> dict:
    """Statistics of one channel at one distance from the per-shot signed errors [m] of the peaks that
    detect the panel (NaN: none does; :func:`muls.studies.common.detections`).

    ``precision_m``: sample standard deviation of the detected ranges (None below 2);
    ``mean_abs_deviation_m``: mean absolute deviation of the detected ranges from their mean;
    ``bias_m``: their mean minus the truth (signed); ``clipped_fraction``: clipped peaks among them.
    """
    detected = np.isfinite(error)
    e = error[detected]
    n = int(e.shape[0])
    return {
        "detected_fraction": round(n / error.shape[0], 4),
        "precision_m": _num(np.std(e, ddof=1), 5) if n >= 2 else None,
        "mean_abs_deviation_m": _num(np.mean(np.abs(e - e.mean())), 5) if n >= 1 else None,
        "bias_m": _num(np.mean(e), 5) if n >= 1 else None,
        "clipped_fraction": round(float(saturated[detected].mean()), 4) if n else None,
    }


def _waveform(model: OpticalModel, range_m: float, reflectance: float, seed: int, pulse_id: int) -> dict:
    """One shot's full record of every channel [LSB], noisy and noise-free, and its peaks."""
    ins = model.instrument
    batch = PulseBatch.flat_target(ins, [range_m], reflectance, pulse_id=[pulse_id])
    records, ranging = simulate(model, batch, seed, mode="full", keep_noise_free=True)
    names = ("ch0",) + ins.channel_names
    noisy = [records.reference[0]] + [records.codes[0, j] for j in range(len(ins.channels))]
    clean = [records.reference_noise_free_lsb[0]] + [records.noise_free_lsb[0, j] for j in range(len(ins.channels))]
    cause = int(ranging.dropout_cause[0])
    return {
        "range_m": range_m,
        "time_ns": _list(records.sample_times_s(model)[0] * 1e9, 3),
        "channels": {n: np.asarray(v).astype(int).tolist() for n, v in zip(names, noisy)},
        "noise_free": {n: _list(v, 3) for n, v in zip(names, clean)},
        "reference_time_ns": float(ranging.reference_time_s[0] * 1e9),
        "peaks": [{"channel": names[int(c)], "time_ns": float(t * 1e9), "range_m": _num(r, 4), "saturated": bool(s)}
                  for c, t, r, s in zip(ranging.peaks.channel, ranging.peaks.time_s, ranging.peaks.range_m,
                                        ranging.peaks.saturated)],
        "dropout_cause": None if cause < 0 else DROPOUT_CAUSES[cause],
    }


def experiment_study(experiment: str | Experiment = "pond", shots: int = EXPERIMENT_SHOTS, seed: int = 0,
                     ranging: str = "prototype", waveforms: bool = True) -> dict:
    """Predict one of the paper's tank tests (:mod:`muls.experiments`).

    ``shots`` static pulses on the panel at each distance (windowed records, one :func:`simulate` call), each
    channel ranged on its own (its peak nearest the truth among those that detect the panel, as the
    precision study does: :func:`muls.studies.common.detections`), with the prototype's plain peak
    detection (``ranging = "prototype"``) or the project's pulse-shape fit (``"template"``). Returns
    {"distances": {"8.5": {"ch1": :func:`channel_stats`, "ch2", "ch3"}, ...}, "settings": {...}} and,
    with ``waveforms``, "waveforms": one full-record shot per distance.
    """
    exp = experiment if isinstance(experiment, Experiment) else experiment_preset(experiment)
    shots = _shots("shots", shots)
    t0 = time.perf_counter()
    instrument = exp.instrument(ranging)
    model = OpticalModel.build(instrument, exp.water)
    r = np.asarray(exp.distances_m, float)
    truth, batch = truth_batch(instrument, r, shots, exp.reflectance, 0)
    _, result = simulate(model, batch, seed, mode="windowed")
    tol = range_tolerance_m(model)
    per_channel = {name: detections(result.peaks, truth, tol, (j + 1,)) for j, name in enumerate(instrument.channel_names)}
    distances = {}
    for i, d in enumerate(r):
        rows = slice(i * shots, (i + 1) * shots)
        distances[f"{d:g}"] = {name: channel_stats(err[rows], sat[rows]) for name, (err, sat) in per_channel.items()}
    out = {
        "distances": distances,
        "settings": {
            **exp.settings(), "ranging": ranging, "peak_fit": RANGING[ranging], "shots": shots, "seed": int(seed),
            "record_mode": "windowed", "tolerance_bins": DETECTION_TOLERANCE_BINS, "tolerance_m": tol,
            "speed_m_s": exp.water.speed_m_s, "max_code": instrument.digitizer.max_code,
            "detection": "per channel: its peak nearest the truth within the tolerance, or clipped and explained by "
                         "the panel's echo (Ranging.peaks)",
            "mean_abs_deviation": "mean |range - mean range| of the detected shots",
            "bias": "mean range of the detected shots minus the true distance",
        },
    }
    if waveforms:
        first_id = r.shape[0] * shots  # ids after the statistics' shots: a shot of its own
        out["waveforms"] = [_waveform(model, float(d), exp.reflectance, seed, first_id + i) for i, d in enumerate(r)]
    out["settings"]["elapsed_s"] = round(time.perf_counter() - t0, 2)
    return out
