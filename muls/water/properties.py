"""Water optical properties at 532 nm: presets with sources, attenuation and backscatter options.

A water type is (a, b, group index, optional measured beta(pi) and K_d). The lidar sees it through two
numbers: the two-way attenuation coefficient k [1/m] (by default the ``monte_carlo`` rule: what the Monte Carlo
reference gives for the water and the receiver, range by range) and the volume scattering function at 180
degrees, beta_pi [1/(m sr)] (measured where known, docs/design.md#backscatter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..infra.errors import ParameterError, check_choice, check_non_negative
from .phase_family import parse_phase_spec, phase_from_spec

SPEED_OF_LIGHT_M_S = 299_792_458.0

#: Henyey-Greenstein asymmetry parameter used by MULS Eq. 5 (paper, below Eq. 5).
HG_ASYMMETRY = 0.924

#: Particle backscatter ratio b_b/b of Petzold's average phase function (Mobley 1994, Light and Water,
#: section 3.8); used only by the diffuse K_d estimate when a preset has no measured K_d.
PETZOLD_BACKSCATTER_RATIO = 0.0183

#: Group index of sea water (35 PSU, 20 degC) and fresh water at 532 nm (docs/design.md#speed-of-light, from the
#: Quan & Fry phase-index fit plus dispersion). Using the phase index ~1.34 instead biases ranges by ~1.7 %.
GROUP_INDEX_SEAWATER = 1.364
GROUP_INDEX_FRESHWATER = 1.357

#: Two-way attenuation exponent 2 k r beyond which no echo can return (e^-40 = 4e-18 of the light): the set-up's
#: warning of a seabed beyond any echo, and the farthest plate ``muls multiscatter`` traces.
MAX_ATTENUATION_EXPONENT = 40.0

#: Attenuation rules (docs/design.md#attenuation). ``monte_carlo`` (the default): the two-way transmission of the Monte Carlo
#: reference for this water and receiver, tabulated against range (muls.montecarlo.scattering_tables); ``small_angle``: forward
#: scattering kept by the receiver's field of view, from the small-angle approximation (muls.water.smallangle); both depend on
#: the range and the receiver. ``k_lidar``: MULS Eq. 6; ``c``: beam attenuation; ``kd``: diffuse.
ATTENUATION_MODELS = ("monte_carlo", "k_lidar", "c", "kd", "small_angle")
#: How an echo's multiple scattering is modelled: ``table`` (the Monte Carlo's column and spread in time, under the
#: ``monte_carlo`` attenuation rule) or ``none`` (single scattering: Eq. 4's column, the echo on its straight path).
MULTIPLE_SCATTERING = ("table", "none")
#: The rules that depend on the range and the receiver (muls.optics.radiometry.lidar_attenuation_per_m evaluates them).
RANGE_DEPENDENT_MODELS = ("monte_carlo", "small_angle")

#: The particle phase function of a water's scattering unless a study varies it (Water.phase_function): the Monte
#: Carlo's tables (muls.montecarlo.tables) integrate the water's; the small-angle rule (muls.water.smallangle) always
#: integrates Petzold's average (muls.water.phase).
PHASE_FUNCTION = "petzold"

#: Backscatter rules (docs/design.md#backscatter): ``measured`` (the default) takes beta(180 deg) measured in the water
#: where the preset has it, else ``petzold``'s; ``petzold``: b p(pi) of Petzold's average particle phase function, the
#: phase function of the Monte Carlo reference, its tables and the small-angle rule (twice the Henyey-Greenstein
#: value); ``hg``: b p(pi) of Henyey-Greenstein with MULS's g; ``eq5``: MULS Eq. 5 read literally.
BACKSCATTER_MODELS = ("measured", "petzold", "hg", "eq5")


def henyey_greenstein(cos_theta, g: float = HG_ASYMMETRY):
    """Henyey-Greenstein phase function [1/sr], normalised over the sphere."""
    return (1.0 - g * g) / (4.0 * math.pi * (1.0 + g * g - 2.0 * g * cos_theta) ** 1.5)


def hg_backward_fraction(g: float = HG_ASYMMETRY) -> float:
    """2 pi * integral over [pi/2, pi] of p_HG sin(theta) d theta (closed form)."""
    return (1.0 - g) / (2.0 * g) * ((1.0 + g) / math.sqrt(1.0 + g * g) - 1.0)


@dataclass(frozen=True)
class Water:
    """Inherent optical properties of one water type at 532 nm.

    absorption_per_m: a [1/m]; scattering_per_m: b [1/m]; beta_pi_measured_per_m_sr: beta(180 deg)
    [1/(m sr)] from measured volume scattering functions (Petzold's waters: measured in that water; Jerlov's
    types: pure water's and Petzold's average particle function, weighted by their shares of b) or None;
    kd_per_m: measured diffuse attenuation K_d [1/m] or None; group_index: n_g of the water (ranging speed c/n_g);
    phase_function: the particle phase function's spec (:mod:`muls.water.phase_family`), Petzold's average unless
    a study varies it: the Monte Carlo's tables are built with it, and beta_pi follows it where none is measured.
    """

    name: str
    absorption_per_m: float
    scattering_per_m: float
    group_index: float = GROUP_INDEX_SEAWATER
    beta_pi_measured_per_m_sr: float | None = None
    kd_per_m: float | None = None
    attenuation_model: str = "monte_carlo"
    backscatter_model: str = "measured"
    source: str = ""
    phase_function: str = PHASE_FUNCTION

    def __post_init__(self):
        check_non_negative(f"water '{self.name}': absorption_per_m", self.absorption_per_m)
        check_non_negative(f"water '{self.name}': scattering_per_m", self.scattering_per_m)
        if self.absorption_per_m + self.scattering_per_m <= 0.0:
            raise ParameterError(f"water '{self.name}': attenuation c = a + b must be > 0")
        if not (1.0 <= self.group_index <= 2.0):
            raise ParameterError(f"water '{self.name}': group_index = {self.group_index!r}: must lie in [1, 2]")
        if self.beta_pi_measured_per_m_sr is not None:
            check_non_negative(f"water '{self.name}': beta_pi_measured_per_m_sr", self.beta_pi_measured_per_m_sr)
        if self.kd_per_m is not None:
            check_non_negative(f"water '{self.name}': kd_per_m", self.kd_per_m)
        check_choice("attenuation_model", self.attenuation_model, ATTENUATION_MODELS)
        check_choice("backscatter_model", self.backscatter_model, BACKSCATTER_MODELS)
        parse_phase_spec(self.phase_function)

    @classmethod
    def from_attenuation(cls, name: str, attenuation_per_m: float, absorption_per_m: float, **kw) -> Water:
        """Build from measured c and a (as the paper's pool and pond were measured), b = c - a."""
        check_non_negative(f"water '{name}': attenuation_per_m", attenuation_per_m)
        check_non_negative(f"water '{name}': absorption_per_m", absorption_per_m)
        if absorption_per_m > attenuation_per_m:
            raise ParameterError(
                f"water '{name}': absorption_per_m = {absorption_per_m!r} exceeds attenuation_per_m = "
                f"{attenuation_per_m!r}: absorption a must not exceed attenuation c = a + b"
            )
        return cls(name, absorption_per_m, attenuation_per_m - absorption_per_m, **kw)

    @property
    def attenuation_per_m(self) -> float:
        """Beam attenuation c = a + b [1/m]."""
        return self.absorption_per_m + self.scattering_per_m

    @property
    def albedo(self) -> float:
        """Single-scattering albedo w0 = b / c."""
        return self.scattering_per_m / self.attenuation_per_m

    @property
    def k_lidar_per_m(self) -> float:
        """Lidar attenuation coefficient [1/m]."""
        w0 = self.albedo
        return self.attenuation_per_m * (0.19 * (1.0 - w0)) ** (w0 / 2.0)  # MULS Eq. 6

    @property
    def kd_estimate_per_m(self) -> float:
        """Diffuse attenuation K_d [1/m]: the measured value, else Gordon (1989) K_d = 1.0395 (a + b_b)."""
        if self.kd_per_m is not None:
            return self.kd_per_m
        return 1.0395 * (self.absorption_per_m + PETZOLD_BACKSCATTER_RATIO * self.scattering_per_m)

    @property
    def two_way_attenuation_per_m(self) -> float:
        """The k used in exp(-2 k z) of Eqs. 4, 7, 9, 10, per ``attenuation_model`` [1/m].

        The ``monte_carlo`` and ``small_angle`` rules depend on the range and the receiver
        (:func:`muls.optics.radiometry.lidar_attenuation_per_m` gives them); here they give K_d, about their value for a
        footprint many free paths wide.
        """
        if self.attenuation_model == "k_lidar":
            return self.k_lidar_per_m
        if self.attenuation_model == "c":
            return self.attenuation_per_m
        return self.kd_estimate_per_m

    @property
    def beta_pi_source(self) -> str:
        """Where :attr:`beta_pi_per_m_sr` comes from under ``backscatter_model``: ``measured`` (this water's
        measurement), ``petzold`` (Petzold's average particle phase function at pi), ``henyey_greenstein``
        (g = 0.924 at pi) or ``eq5`` (MULS Eq. 5 read literally)."""
        if self.backscatter_model == "measured":
            # Without a measurement, the phase function every other part of the model uses: the Monte Carlo's
            # column then needs no rescaling, and the column and the echo share one phase function.
            return "measured" if self.beta_pi_measured_per_m_sr is not None else self.phase_function
        return {"petzold": PHASE_FUNCTION, "hg": "henyey_greenstein", "eq5": "eq5"}[self.backscatter_model]

    @property
    def beta_pi_per_m_sr(self) -> float:
        """Volume scattering function at 180 degrees [1/(m sr)], per ``backscatter_model`` (:attr:`beta_pi_source`)."""
        b, source = self.scattering_per_m, self.beta_pi_source
        if source == "measured":
            return self.beta_pi_measured_per_m_sr
        if source == "eq5":
            # MULS Eq. 5 read literally: HG value at pi over the HG backward fraction.
            return b * henyey_greenstein(-1.0) / hg_backward_fraction()
        if source == "henyey_greenstein":
            return b * henyey_greenstein(-1.0)  # b * p_HG(pi), g = 0.924
        return b * phase_from_spec(source).value_at_pi_per_sr

    @property
    def speed_m_s(self) -> float:
        """Group velocity of light in this water [m/s] (used for all times of flight, Eq. 14)."""
        return SPEED_OF_LIGHT_M_S / self.group_index

    def with_models(self, attenuation_model: str | None = None, backscatter_model: str | None = None) -> Water:
        """Copy with other attenuation / backscatter options."""
        return replace(
            self,
            attenuation_model=attenuation_model or self.attenuation_model,
            backscatter_model=backscatter_model or self.backscatter_model,
        )
