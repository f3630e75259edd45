"""``muls validate-pass``: the waveform model every pass uses, against a Monte Carlo run of its own.

A pass models each echo with the ``monte_carlo`` attenuation rule, the finite-aperture overlap and multiple
scattering from the tables (:mod:`muls.optics.scattering`), which one Monte Carlo run per water and receiver built. Here a
fresh Monte Carlo run (another seed, flat 0.1 plates at :data:`VALIDATION_RANGES_M`, none of which the tables'
interpolation was asked for) is the reference, for the MUL in each water of :data:`VALIDATION_WATERS`:

- ``echo_energy_ratio``: the pass model's echo energy over the Monte Carlo's;
- ``echo_peak_ratio``: the peak of the pass model's echo, through the band-limited pulse, over the Monte Carlo's
  target signal's peak through the same pulse;
- ``column_ratio``: the water column's energy from 0 to :data:`COLUMN_WINDOW_S`, pulse and all, the beam stopping at
  the plate; the Monte Carlo's column is rescaled to the water's beta_pi from its phase function's b p(pi), as the
  model rescales its table;
- ``mc_rel_err``: the largest relative standard error of the Monte Carlo's three quantities.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..optics.optical_model import OpticalModel, PulseBatch
from ..optics.radiometry import two_way_transmission
from ..presets import mul2023, water_preset
from .power import mc_power_w
from .run import TargetPlanes, run_monte_carlo

VALIDATION_WATERS = ("pool", "clean_ocean", "coastal_ocean", "pond", "turbid_harbor")
VALIDATION_RANGES_M = (2.0, 3.0, 5.0, 10.0, 20.0, 30.0)
#: [s] The column is compared over its first 50 ns: the near field, where multiple scattering lights the blind zone.
COLUMN_WINDOW_S = 50e-9
#: Beam packets of each water's run (another seed than the tables': :data:`VALIDATION_SEED`).
VALIDATION_PACKETS = 400_000
VALIDATION_SEED = 7
#: The acceptance: |ratio - 1| within these where the Monte Carlo's error is below MAX_MC_REL_ERR.
ECHO_ENERGY_TOLERANCE, ECHO_PEAK_TOLERANCE, COLUMN_TOLERANCE, MAX_MC_REL_ERR = 0.20, 0.25, 0.30, 0.03


def validate_pass(waters=VALIDATION_WATERS, ranges_m=VALIDATION_RANGES_M, packets: int = VALIDATION_PACKETS,
                  seed: int = VALIDATION_SEED) -> dict:
    """Each water and range of the pass model against the Monte Carlo (module doc): ``{"cases": [{"water",
    "range_m", "echo_energy_ratio", "echo_peak_ratio", "column_ratio", "mc_rel_err"}], "packets", "seed",
    "seconds"}``; a ratio is None where the Monte Carlo saw no light."""
    instrument = mul2023()
    e_scale = instrument.transmitter.pulse_energy_j * two_way_transmission(instrument)
    cases, started = [], time.perf_counter()
    for name in waters:
        water = water_preset(name)
        model = OpticalModel.build(instrument, water)
        ranges = tuple(sorted(float(r) for r in ranges_m))
        result = run_monte_carlo(instrument, water, TargetPlanes(ranges, 0.1), packets=packets, seed=seed)
        rescale = water.beta_pi_per_m_sr / (water.scattering_per_m * model.attenuation.phase_value_at_pi_per_sr)
        for k, r in enumerate(ranges):
            t = result.time_s
            mc = mc_power_w(result, k, instrument)
            energy, var = result.target(k)
            mc_echo_j, mc_echo_err = energy.sum() * e_scale, math.sqrt(var.sum()) * e_scale
            target_w, target_err = mc["target"]
            peak = int(np.argmax(target_w))
            early = t < COLUMN_WINDOW_S
            column_w, column_err = mc["column"]
            mc_column_j = rescale * column_w[early].sum() * result.time_step_s
            mc_column_err = rescale * math.sqrt((column_err[early] ** 2).sum()) * result.time_step_s
            echoes = model.echoes(PulseBatch.flat_target(instrument, [r], 0.1))
            pulse = instrument.pulse
            model_target = (echoes.energy_j[None, :] * pulse(t[:, None] - echoes.delay_s[None, :])).sum(axis=1)
            model_column_j = model.column_power_w(t[early], cut_m=r).sum() * result.time_step_s
            cases.append({
                "water": name, "range_m": r,
                "echo_energy_ratio": _ratio(echoes.energy_j.sum(), mc_echo_j),
                "echo_peak_ratio": _ratio(model_target.max(), target_w[peak]),
                "column_ratio": _ratio(model_column_j, mc_column_j),
                "mc_rel_err": round(max(_rel(mc_echo_err, mc_echo_j), _rel(target_err[peak], target_w[peak]),
                                        _rel(mc_column_err, mc_column_j)), 5),
            })
    return {"cases": cases, "packets": int(packets), "seed": int(seed),
            "seconds": round(time.perf_counter() - started, 1)}


def _ratio(model_value: float, mc_value: float) -> float | None:
    return round(float(model_value / mc_value), 5) if mc_value > 0.0 else None


def _rel(error: float, value: float) -> float:
    return float(error / value) if value > 0.0 else math.inf


def within_acceptance(case: dict) -> bool:
    """Whether a case meets the acceptance (module doc), or is exempt (the Monte Carlo's error over the limit)."""
    if case["mc_rel_err"] >= MAX_MC_REL_ERR:
        return True
    return all(case[key] is not None and abs(case[key] - 1.0) <= tol for key, tol in (
        ("echo_energy_ratio", ECHO_ENERGY_TOLERANCE), ("echo_peak_ratio", ECHO_PEAK_TOLERANCE),
        ("column_ratio", COLUMN_TOLERANCE)))
