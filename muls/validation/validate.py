"""``muls validate-pass``: a consistency check of the scattering tables every pass uses.

A pass models each echo with the ``monte_carlo`` attenuation rule, the finite-aperture overlap and multiple scattering from the
tables (:mod:`muls.montecarlo.scattering_tables`), which one Monte Carlo run per water and receiver built. Here the pass's
waveform model is set beside a fresh run of that same Monte Carlo (another seed, flat 0.1 plates at :data:`VALIDATION_RANGES_M`,
between the tables' ranges), for the MUL in each water of :data:`VALIDATION_WATERS`. It shows what tabulating lost
(interpolation in range, the echo's spread cut to a few nodes, the smoothed column), not whether the Monte Carlo itself is
right: both sides share its physics (``muls mobley1993`` and ``muls multiscatter`` set the Monte Carlo against published results
and the analytic rules). The ratios:

- ``echo_energy_ratio``: the pass model's echo energy over the Monte Carlo's;
- ``echo_peak_ratio``: the peak of the pass model's echo, through the band-limited pulse, over the Monte Carlo's
  target signal's peak through the same pulse;
- ``column_ratio``: the water column's energy from 0 to :data:`COLUMN_WINDOW_S`, pulse and all, the beam stopping at
  the plate; the Monte Carlo's column is rescaled to the water's beta_pi from its phase function's b p(pi), as the
  model rescales its table;
- ``mc_rel_err``: the largest relative standard error of the Monte Carlo's three quantities (None where it saw no
  light in one of them);
- ``within``: True or False where ``mc_rel_err`` is under :data:`MAX_MC_REL_ERR`, None (not judged) elsewhere: a
  ratio whose reference is that uncertain says nothing of the tables.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..montecarlo.run import TargetPlanes, run_monte_carlo
from ..optics.optical_model import OpticalModel, PulseBatch
from ..optics.radiometry import two_way_transmission
from ..presets import mul2023, water_preset
from .power import mc_power_w

VALIDATION_WATERS = ("pool", "clean_ocean", "coastal_ocean", "pond", "turbid_harbor")
VALIDATION_RANGES_M = (2.0, 3.0, 5.0, 10.0, 20.0, 30.0)
#: [s] The column is compared over its first 50 ns: the near field, where multiple scattering lights the blind zone.
COLUMN_WINDOW_S = 50e-9
#: Beam packets of each water's run (another seed than the tables': :data:`VALIDATION_SEED`).
VALIDATION_PACKETS = 400_000
VALIDATION_SEED = 7
#: The acceptance: |ratio - 1| within these where the Monte Carlo's error is below MAX_MC_REL_ERR.
ECHO_ENERGY_TOLERANCE, ECHO_PEAK_TOLERANCE, COLUMN_TOLERANCE, MAX_MC_REL_ERR = 0.20, 0.25, 0.30, 0.03
#: Fewest beam packets that can judge a case. The Monte Carlo's relative error falls as 1/sqrt(packets); its smallest,
#: measured at 400,000 packets, is 0.28 % (the pool at 5 and 10 m; 2.6 % at 4,000), so below 400,000 (0.28 / 3)**2,
#: about 3,500, every case's error is over MAX_MC_REL_ERR and no case can be judged.
MIN_VALIDATION_PACKETS = 3_500


def validate_pass(waters=VALIDATION_WATERS, ranges_m=VALIDATION_RANGES_M, packets: int = VALIDATION_PACKETS,
                  seed: int = VALIDATION_SEED) -> dict:
    """Each water and range of the pass model against the Monte Carlo (module doc): ``{"cases": [{"water",
    "range_m", "echo_energy_ratio", "echo_peak_ratio", "column_ratio", "mc_rel_err"}], "packets", "seed",
    "seconds"}``; a ratio is None where the Monte Carlo saw no light. Fewer than :data:`MIN_VALIDATION_PACKETS`
    packets, which can judge no case, are refused (ValueError)."""
    check_packets("packets", packets)
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
            error = max(_rel(mc_echo_err, mc_echo_j), _rel(target_err[peak], target_w[peak]),
                        _rel(mc_column_err, mc_column_j))
            case = {
                "water": name, "range_m": r,
                "echo_energy_ratio": _ratio(echoes.energy_j.sum(), mc_echo_j),
                "echo_peak_ratio": _ratio(model_target.max(), target_w[peak]),
                "column_ratio": _ratio(model_column_j, mc_column_j),
                "mc_rel_err": round(error, 5) if math.isfinite(error) else None,
            }
            cases.append(case | {"within": judge(case)})
    return {"cases": cases, "packets": int(packets), "seed": int(seed),
            "seconds": round(time.perf_counter() - started, 1)}


def _ratio(model_value: float, mc_value: float) -> float | None:
    return round(float(model_value / mc_value), 5) if mc_value > 0.0 else None


def _rel(error: float, value: float) -> float:
    return float(error / value) if value > 0.0 else math.inf


def check_packets(key: str, packets: int) -> int:
    """``packets``, or a ValueError naming ``key`` when fewer than :data:`MIN_VALIDATION_PACKETS` (no case judged)."""
    if packets < MIN_VALIDATION_PACKETS:
        raise ValueError(f"{key} = {packets}: at least {MIN_VALIDATION_PACKETS:,}; with fewer every case's Monte Carlo "
                         f"error is over the {MAX_MC_REL_ERR:.0%} a case is judged within (the error falls as 1/sqrt of "
                         "the packets: 0.28 % at best with 400,000), so no case could be judged")
    return packets


def judge(case: dict) -> bool | None:
    """Whether a case meets the acceptance (module doc); None (not judged) where the Monte Carlo's error is at or over
    :data:`MAX_MC_REL_ERR`, or unknown: a reference that uncertain can neither pass nor fail the tables."""
    if case["mc_rel_err"] is None or case["mc_rel_err"] >= MAX_MC_REL_ERR:
        return None
    return all(case[key] is not None and abs(case[key] - 1.0) <= tol for key, tol in (
        ("echo_energy_ratio", ECHO_ENERGY_TOLERANCE), ("echo_peak_ratio", ECHO_PEAK_TOLERANCE),
        ("column_ratio", COLUMN_TOLERANCE)))


def verdict(case: dict) -> str:
    """``yes``, ``NO`` or ``not judged``: a case's ``within`` (:func:`judge`) as the table prints it."""
    return {True: "yes", False: "NO", None: "not judged"}[case["within"]]
