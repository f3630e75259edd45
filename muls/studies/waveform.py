"""One pulse, every channel (paper Figures 7 and 8)."""

from __future__ import annotations

import numpy as np

from ..infra.errors import check_fraction
from ..optics.optical_model import OpticalModel, PulseBatch
from ..presets import mul2023, study_water
from ..ranging.returns import DROPOUT_CAUSES
from ..simulate import simulate
from ..water.properties import Water
from .common import (
    _gate,
    _list,
    _num,
    _ranges,
    _water,
)


def waveform_study(water: str | Water = "pond", range_m: float = 11.5, seed: int = 0, reflectance: float = 0.1,
                   gate_delay_s: float | None = None, gate_width_s: float | None = None,
                   attenuation_model: str | None = None) -> dict:
    """CH0-CH3 full records [LSB] of one pulse of the MUL on a flat panel, noisy and noise-free.

    water: preset name or Water; range_m: panel range [m]; reflectance: Lambertian reflectance [0, 1];
    gate: CH3's gate [s], by default the one of the paper's experiment in that water (pond 100/400 ns,
    pool 150/400 ns, the pond's elsewhere); attenuation_model: the rule the water uses (None: as
    configured; the ``muls`` command passes the studies' rule, ``monte_carlo``). Returns ``time_ns``
    (n_samples,) sample times after emission, ``channels`` and ``noise_free`` {"ch0".."ch3": (n_samples,)
    LSB}, ``returns`` (what the instrument's ranging made of the pulse), ``dropout_cause`` and ``settings``.
    """
    w = study_water(_water(water), attenuation_model)
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
            "water": w.name, "attenuation_model": w.attenuation_model,
        "instrument": instrument.name, "range_m": range_m, "reflectance": float(reflectance),
            "seed": int(seed), "record_mode": "full", "gate_delay_ns": delay * 1e9, "gate_width_ns": width * 1e9,
            "sample_interval_ns": instrument.digitizer.sample_interval_s * 1e9,
            "max_code": instrument.digitizer.max_code, "speed_m_s": w.speed_m_s,
        },
    }
