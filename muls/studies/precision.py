"""Range precision per channel (paper Table 2, Figure 11)."""

from __future__ import annotations

import numpy as np

from ..infra.errors import check_fraction
from ..optics.optical_model import OpticalModel
from ..presets import mul2023, study_water
from ..simulate import simulate
from ..water.properties import Water
from .common import (
    DETECTION_TOLERANCE_BINS,
    _gate,
    _num,
    _ranges,
    _shots,
    _water,
    detections,
    range_tolerance_m,
    truth_batch,
)


def _stats(error: np.ndarray, saturated: np.ndarray) -> dict:
    detected = np.isfinite(error)
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
                    gate_width_s: float | None = None, record_mode: str = "windowed",
                    attenuation_model: str | None = None) -> dict:
    """Range precision and mean deviation [m] per channel of static pulses on a flat panel.

    Each channel is ranged on its own: per shot, its peak nearest the truth (``Ranging.peaks``) among those
    that detect the panel (:func:`muls.studies.common.detections`: within 3 range bins, or clipped and
    explained by the echo). ``precision_m`` is the sample std of the kept ranges, ``mean_deviation_m`` their
    mean minus the truth, ``detected_fraction`` kept shots over all shots, ``saturated_fraction`` clipped
    peaks among the kept ones. ``chosen`` gives the same for the instrument's chosen returns. The CH3 gate is
    that of the paper's experiment in the water unless given [s]. ``attenuation_model``: the rule the
    water uses (None: as configured; the ``muls`` command passes the studies' rule, ``monte_carlo``).
    Returns {"8.5": {"ch1": {...}, "ch2": {...}, "ch3": {...}, "chosen": {...}}, ..., "settings": {...}};
    precision is None below 2 detections.
    """
    w = study_water(_water(water), attenuation_model)
    r = _ranges("ranges_m", ranges_m)
    shots = _shots("shots", shots)
    check_fraction("reflectance", reflectance)
    delay, width = _gate(w, gate_delay_s, gate_width_s)
    instrument = mul2023(gate_delay_s=delay, gate_width_s=width)
    model = OpticalModel.build(instrument, w)
    truth, batch = truth_batch(instrument, r, shots, float(reflectance), 0)
    _, ranging = simulate(model, batch, seed, mode=record_mode)
    tol = range_tolerance_m(model)
    out = {}
    per_channel = {name: detections(ranging.peaks, truth, tol, (j + 1,))
                   for j, name in enumerate(instrument.channel_names)}
    per_channel["chosen"] = detections(ranging.returns, truth, tol)
    for i, range_m in enumerate(r):
        rows = slice(i * shots, (i + 1) * shots)
        out[f"{range_m:g}"] = {name: _stats(err[rows], sat[rows]) for name, (err, sat) in per_channel.items()}
    out["settings"] = {
        "water": w.name, "attenuation_model": w.attenuation_model,
        "instrument": instrument.name, "ranges_m": r.tolist(), "shots": shots, "seed": int(seed),
        "reflectance": float(reflectance), "gate_delay_ns": delay * 1e9, "gate_width_ns": width * 1e9,
        "record_mode": record_mode, "tolerance_bins": DETECTION_TOLERANCE_BINS, "tolerance_m": tol,
        "speed_m_s": w.speed_m_s,
    }
    return out
