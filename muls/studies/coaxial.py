"""Coaxial vs non-coaxial backscatter (paper Figure 13)."""

from __future__ import annotations

import numpy as np

from ..infra.errors import check_positive
from ..optics.optical_model import OpticalModel, PulseBatch
from ..optics.radiometry import lidar_attenuation_per_m
from ..presets import coaxial, mul2023, study_water
from ..water.properties import Water
from .common import (
    _list,
    _water,
)


def coaxial_study(water: str | Water = "turbid_harbor", t_max_ns: float = 200.0, step_ns: float = 0.2,
                  attenuation_model: str | None = None) -> dict:
    """Noise-free water-column power [W] of ``coaxial()`` and ``mul2023()``, both as non-gated receivers.

    The column alone (the model's: the Monte Carlo's column under the ``monte_carlo`` rule, else MULS Eq. 4, convolved
    with the pulse, no target: ``OpticalModel.column_power_w``) on
    a grid of ``step_ns`` up to ``t_max_ns`` after emission; same parameters except the transceiver offset
    (0 vs 130 mm). The coaxial design's window return (Eq. 3), a separate echo at the window, is reported
    as ``coaxial_window_peak_w`` and left out of the curves and the ratio. ``peak_ratio`` = peak coaxial /
    peak non-coaxial column power. ``attenuation_model``: the rule the water uses (None: as configured; the
    ``muls`` command passes the studies' rule, ``monte_carlo``).
    """
    w = study_water(_water(water), attenuation_model)
    check_positive("t_max_ns", t_max_ns)
    check_positive("step_ns", step_ns)
    t = np.arange(0.0, t_max_ns + 0.5 * step_ns, step_ns) * 1e-9
    co_model = OpticalModel.build(coaxial(), w)
    non_model = OpticalModel.build(mul2023(), w)
    co = co_model.column_power_w(t)
    non = non_model.column_power_w(t)
    energy = co_model.echoes(PulseBatch.flat_target(co_model.instrument, [np.inf])).energy_j
    window_peak = float(energy.max() * co_model.instrument.pulse.peak_per_s) \
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
            "water": w.name, "attenuation_model": w.attenuation_model,
            "quantity": "noise-free water-column power at the receiver (no target)",
            "t_max_ns": float(t_max_ns), "step_ns": float(step_ns),
            "non_coaxial_offset_m": non_model.instrument.receiver.offset_m,
            "blind_zone_m": geometry.blind_zone_m, "full_overlap_m": geometry.full_overlap_m,
            "k_per_m_at_10_m": float(lidar_attenuation_per_m(non_model.instrument, w, 10.0)),
            "beta_pi_per_m_sr": w.beta_pi_per_m_sr,
        },
    }
