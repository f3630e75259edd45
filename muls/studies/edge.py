"""Range bias at the blind-zone edge: a plate 1.60-2.20 m away in every water, per channel, and its cause.

Near the edge of the blind zone the non-coaxial overlap rises steeply with range (0 up to 1.68 m, 0.003 at
1.80 m, 0.05 at 2.0 m, 0.39 at 2.5 m for the ``mul2023``), and with it the water column's backscatter. A plate
stops the column where it stands, while the processor subtracts the calibrated open-water record, which keeps
rising behind the plate; over the echo the residual is the echo minus that missing column, whose slope pulls
the fitted peak early. The study measures the bias and splits it by switching the cause off: the same pulses
noise-free with the column cut at the plate (as simulated) and with the column not cut (the residual is then
the echo alone; what is left is the echo's spread in time by multiple scattering).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..infra.errors import ParameterError, check_fraction
from ..optics.optical_model import OpticalModel
from ..presets import WATER_PRESETS, mul2023, study_water
from ..simulate import simulate
from .common import _num, _ranges, _shots, detections, range_tolerance_m, truth_batch
from .precision import _stats

#: The plate ranges of the study [m]: 1.60 to 2.20 m in 5 cm steps, across the edge of the ``mul2023``'s blind zone.
EDGE_RANGES_M = tuple(round(1.60 + 0.05 * i, 2) for i in range(13))
#: The far channel's gate of the study: open from emission for 400 ns, as for a target this close.
EDGE_GATE_S = (0.0, 400e-9)


def noise_free_errors(model: OpticalModel, batch, truth_m: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Per pulse, the chosen return's range error [m] of ``batch`` without noise: with the column cut at the plate
    (as simulated) and with it not cut, so that the residual over the calibrated baseline is the echo alone
    (NaN where no return detects the plate)."""
    tol = range_tolerance_m(model)
    out = []
    for b in (batch, dataclasses.replace(batch, column_cut_m=np.full_like(batch.column_cut_m, np.inf))):
        _, ranging = simulate(model, b, seed, noise=False)
        out.append(detections(ranging.returns, truth_m, tol)[0])
    return out[0], out[1]


def edge_bias_study(waters=None, ranges_m=EDGE_RANGES_M, shots: int = 200, seed: int = 0, reflectance: float = 0.1,
                    attenuation_model: str | None = None) -> dict:
    """Mean range error and its spread [m] per channel for a plate at normal incidence at ``ranges_m`` [m] in each
    of ``waters`` (preset names; None: every preset), ``shots`` noisy pulses per range, and the cause.

    Per channel as :func:`muls.studies.precision_study` ranges it (its peak nearest the truth within 3 range bins);
    ``chosen`` for the instrument's returns. ``noise_free_m``: the chosen return's mean error without noise;
    ``echo_alone_m``: the same with the column not cut at the plate (see the module doc); their difference,
    ``column_deficit_m``, is the bias the missing column behind the plate makes. ``attenuation_model``: as
    :func:`~muls.studies.precision_study`. Returns {water: {range: {"ch1": {...}, ..., "chosen": {...},
    "noise_free_m", "echo_alone_m", "column_deficit_m", "overlap"}}, "settings": {...}}.
    """
    names = sorted(WATER_PRESETS) if waters is None else list(waters)
    if not names:
        raise ParameterError("waters = []: give at least one water preset")
    for name in names:
        if name not in WATER_PRESETS:
            raise ParameterError(f"waters = {name!r}: must be one of {', '.join(sorted(WATER_PRESETS))}")
    r = _ranges("ranges_m", ranges_m)
    shots = _shots("shots", shots)
    check_fraction("reflectance", reflectance)
    instrument = mul2023(*EDGE_GATE_S)
    truth, batch = truth_batch(instrument, r, shots, float(reflectance), 0)
    overlap = instrument.geometry.overlap(r)
    out = {}
    for name in names:
        water = study_water(name, attenuation_model)
        model = OpticalModel.build(instrument, water)
        _, ranging = simulate(model, batch, seed)
        tol = range_tolerance_m(model)
        per_channel = {ch: detections(ranging.peaks, truth, tol, (j + 1,))
                       for j, ch in enumerate(instrument.channel_names)}
        per_channel["chosen"] = detections(ranging.returns, truth, tol)
        cut, alone = noise_free_errors(model, batch, truth, seed)
        rows = {}
        for i, range_m in enumerate(r):
            s = slice(i * shots, (i + 1) * shots)
            row = {ch: _stats(err[s], sat[s]) for ch, (err, sat) in per_channel.items()}
            nf, ea = _mean(cut[s]), _mean(alone[s])
            row.update(noise_free_m=_num(nf, 5), echo_alone_m=_num(ea, 5),
                       column_deficit_m=_num(nf - ea, 5) if nf is not None and ea is not None else None,
                       overlap=_num(overlap[i], 5))
            rows[f"{range_m:.2f}"] = row
        out[name] = rows
    out["settings"] = {"waters": names, "attenuation_model": water.attenuation_model, "instrument": instrument.name,
                       "ranges_m": r.tolist(), "shots": shots, "seed": int(seed), "reflectance": float(reflectance),
                       "gate_delay_ns": EDGE_GATE_S[0] * 1e9, "gate_width_ns": EDGE_GATE_S[1] * 1e9}
    return out


def _mean(errors: np.ndarray) -> float | None:
    kept = errors[np.isfinite(errors)]
    return float(kept.mean()) if kept.size else None
