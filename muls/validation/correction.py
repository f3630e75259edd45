"""A tabulated correction of MULS from the Monte Carlo, applied at negligible cost by interpolation.

Per water and instrument, one Monte Carlo run with flat plates at several ranges gives the echo energy
over MULS Eq. 7 (interpolated in ln(ratio) against ln(range)) and the water column over MULS Eq. 4 in time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..infra.errors import ParameterError
from ..instrument.description import Instrument
from ..montecarlo.run import MonteCarloResult, TargetPlanes, run_monte_carlo
from ..optics.optical_model import OpticalModel
from ..optics.radiometry import lambertian_weight, target_factor
from ..water.phase import PhaseFunction, check_phase
from ..water.properties import Water
from .power import mc_power_w, two_way_transmission


def same_phase(water: Water, phase: PhaseFunction) -> Water:
    """``water`` with beta_pi = b p(pi) of ``phase``: MULS's single scattering with the Monte Carlo's phase."""
    return replace(water, beta_pi_measured_per_m_sr=water.scattering_per_m * phase.value_at_pi_per_sr,
                   backscatter_model="measured")


@dataclass(frozen=True)
class MultipleScatteringCorrection:
    """Monte Carlo over MULS for one water and instrument, tabulated, applied by interpolation.

    ranges_m (K,), target_ratio (K,), target_rel_err (K,): echo energy of a flat plate at normal incidence,
    Monte Carlo over MULS Eq. 7 as the water is configured (its attenuation rule); interpolated linearly
    in ln(ratio) between ranges, the end values held outside. time_s (n,), column_ratio (n,): the water
    column, Monte Carlo over MULS Eq. 4 with the water's attenuation rule and the Monte Carlo's own beta_pi
    (b p(pi)), so that the factor corrects the propagation and leaves MULS's backscatter value alone;
    defined where MULS's column is above COLUMN_FLOOR of its peak, the nearest defined value elsewhere.
    column_w (n,): the Monte Carlo column itself [W] rescaled to MULS's beta_pi, which also lights
    MULS's blind zone (a factor cannot).
    """

    water: str
    instrument: str
    ranges_m: np.ndarray
    target_ratio: np.ndarray
    target_rel_err: np.ndarray
    time_s: np.ndarray
    column_ratio: np.ndarray
    column_w: np.ndarray
    packets: int

    #: The column factor is taken where MULS's column exceeds this share of its peak.
    COLUMN_FLOOR = 1e-4

    @classmethod
    def build(cls, instrument: Instrument, water: Water, ranges_m, packets: int = 1_000_000, seed: int = 0,
              phase: str | PhaseFunction = "petzold") -> MultipleScatteringCorrection:
        """Run the Monte Carlo once for all ``ranges_m`` (a flat 0.1 plate) and tabulate the ratios."""
        phase = check_phase(phase)
        targets = TargetPlanes(tuple(sorted(float(r) for r in np.atleast_1d(ranges_m))), 0.1)
        result = run_monte_carlo(instrument, water, targets, phase=phase, packets=packets, seed=seed)
        return cls.from_result(result, instrument, water, phase)

    @classmethod
    def from_result(cls, result: MonteCarloResult, instrument: Instrument, water: Water,
                    phase: str | PhaseFunction = "petzold", scenes=None) -> MultipleScatteringCorrection:
        """Tabulate from an existing run (``scenes``: indices of the ranges to keep; default all)."""
        phase = check_phase(phase)
        if not result.ranges_m:
            raise ParameterError("the Monte Carlo run has no target ranges to tabulate")
        scenes = list(range(len(result.ranges_m))) if scenes is None else list(scenes)
        rho = float(result.settings["reflectance"])
        e_scale = instrument.transmitter.pulse_energy_j * two_way_transmission(instrument)
        ratio, rel = [], []
        for k in scenes:
            r = result.ranges_m[k]
            tm, tv = result.target(k)
            muls = instrument.transmitter.pulse_energy_j * float(
                target_factor(instrument, water, r, lambertian_weight(instrument, r, rho)))  # MULS Eq. 7
            ratio.append(tm.sum() * e_scale / muls)
            rel.append(math.sqrt(tv.sum()) / tm.sum())
        far = len(result.ranges_m) - 1
        keep = result.time_s < 2.0 * result.ranges_m[far] / result.speed_m_s
        t = result.time_s[keep]
        mc_col = mc_power_w(result, far, instrument)["column"][0][keep]
        ref = OpticalModel.build(instrument, same_phase(water, phase)).column_power_w(t, cut_m=result.ranges_m[far])
        defined = ref > cls.COLUMN_FLOOR * ref.max()
        col_ratio = np.interp(t, t[defined], mc_col[defined] / ref[defined])
        scale = water.beta_pi_per_m_sr / (water.scattering_per_m * phase.value_at_pi_per_sr) \
            if water.scattering_per_m > 0 else 1.0
        return cls(water.name, instrument.name, np.array([result.ranges_m[k] for k in scenes]), np.array(ratio),
                   np.array(rel), t, col_ratio, mc_col * scale, result.packets)

    def target_factor(self, range_m):
        """MC / MULS echo energy at ``range_m`` [m] (any shape)."""
        r = np.asarray(range_m, float)
        return np.exp(np.interp(np.log(r), np.log(self.ranges_m), np.log(self.target_ratio)))

    def column_factor(self, time_s):
        """MC / MULS water-column power at ``time_s`` [s] after emission (any shape)."""
        return np.interp(np.asarray(time_s, float), self.time_s, self.column_ratio)

    def column_power_w(self, time_s):
        """The Monte Carlo column [W] at ``time_s``, with MULS's beta_pi (0 beyond the tabulated time)."""
        return np.interp(np.asarray(time_s, float), self.time_s, self.column_w, right=0.0)
