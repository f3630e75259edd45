"""Scattering phase functions of sea water for the Monte Carlo reference (:mod:`muls.montecarlo`).

A phase function p(theta) [1/sr] is the volume scattering function over b, normalised so that
2 pi int_0^pi p(theta) sin(theta) d theta = 1. Each one here is tabulated once on a fine grid, uniform in
ln(theta) from 1e-8 rad to pi, normalised numerically on that grid, and turned into two tables the compiled
kernels use: p on the ln(theta) grid (for local estimates) and the inverse cumulative distribution on a
uniform grid of probability (for sampling a scattering angle).

- ``petzold``: Petzold's measured average particle phase function (San Diego harbour, 514 nm), the table
  below; log-log interpolation, a power law below 0.1 deg.
- ``fournier_forand``: the Fournier-Forand analytic form; by default n = 1.10, mu = 3.5835, whose
  backscatter fraction 0.0183 matches Petzold's average.
- ``henyey_greenstein``: the one-parameter analytic form; by default g = 0.924, the value MULS Eq. 5 uses.
- ``rayleigh``: 3/(16 pi) (1 + cos^2 theta), the phase function of problem 1 of Mobley et al. (1993).
- ``mobley1993_particle``: the particle phase function of problem 2 of Mobley et al. (1993), Petzold's average
  as that paper tabulates and interpolates it (linear between its Table 2 values, a power law below 0.12589 deg).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..infra.errors import ParameterError

# Petzold's average particle phase function [1/sr], the values published in Mobley (1994), Light and Water,
# Table 3.10, derived from Petzold (1972), SIO Ref. 72-78. Angles 10^(-1 + 0.1 i) deg for i = 0..20 (0.1 to
# 10 deg), then 15 to 180 deg in 5 deg steps. Mobley et al. (1993) Table 2 gives the same values to six digits
# (MOBLEY1993_PARTICLE_PER_SR below), except at 0.50119 deg, where it prints 218.839 (here 201.2).
PETZOLD_ANGLES_DEG = np.concatenate([10.0 ** (-1.0 + 0.1 * np.arange(21)), np.arange(15.0, 181.0, 5.0)])
PETZOLD_VALUES_PER_SR = np.array([
    1.767e3, 1.296e3, 9.502e2, 6.991e2, 5.140e2, 3.764e2, 2.763e2, 2.012e2, 1.444e2, 1.022e2,
    7.161e1, 4.958e1, 3.395e1, 2.281e1, 1.516e1, 1.002e1, 6.580, 4.295, 2.807, 1.819,
    1.153, 4.893e-1, 2.444e-1, 1.472e-1, 8.609e-2, 5.931e-2, 4.210e-2, 3.067e-2, 2.275e-2, 1.699e-2,
    1.313e-2, 1.046e-2, 8.488e-3, 6.976e-3, 5.842e-3, 4.953e-3, 4.292e-3, 3.782e-3, 3.404e-3, 3.116e-3,
    2.912e-3, 2.797e-3, 2.686e-3, 2.571e-3, 2.476e-3, 2.377e-3, 2.329e-3, 2.313e-3, 2.365e-3, 2.506e-3,
    2.662e-3, 2.835e-3, 3.031e-3, 3.092e-3, 3.154e-3,
])
PETZOLD_SOURCE = ("Petzold (1972) average particle phase function, Mobley (1994) Light and Water Table 3.10; "
                  "below 0.1 deg a power law with the slope of the first two values (-1.346), as Mobley does")

#: Fournier-Forand parameters whose backscatter fraction is Petzold's 0.0183 (Mobley, Sundman and Boss
#: 2002, Appl. Opt. 41, 1035): particle refractive index n relative to water, and the Junge slope mu.
FF_PETZOLD_N = 1.10
FF_PETZOLD_MU = 3.5835

#: The particle phase function of problem 2 of Mobley et al. (1993), Appl. Opt. 32, 7484, Table 2 [1/sr], at
#: PETZOLD_ANGLES_DEG. The paper derived it from Petzold's three San Diego harbour VSFs less pure sea water,
#: averaged, and divided by 1.006449 so that the trapezoidal rule over the table plus the power law below 0.1 deg
#: integrates to 1 (its Section 3). One printed value is corrected: at 0.50119 deg the paper prints 218.839,
#: out of line with its neighbours; with it that same rule gives 1.0019, with Light and Water's 201.2 it gives
#: 1.0000 (tests/muls/validation/test_mobley1993.py checks both sums), so 201.2 is used.
MOBLEY1993_PARTICLE_PER_SR = np.array([
    1.76661e3, 1.29564e3, 9.50172e2, 6.99092e2, 5.13687e2, 3.76373e2, 2.76318e2,
    2.01200e2,  # 0.50119 deg: printed 2.18839e2 (see above); Mobley (1994) Light and Water Table 3.10: 2.012e2
    1.44369e2, 1.02241e2,
    7.16082e1, 4.95803e1, 3.39511e1, 2.28129e1, 1.51622e1, 1.00154e1, 6.57957, 4.29530, 2.80690, 1.81927,
    1.15257, 4.89344e-1, 2.44424e-1, 1.47151e-1, 8.60848e-2, 5.93075e-2, 4.20985e-2, 3.06722e-2, 2.27533e-2,
    1.69904e-2, 1.31254e-2, 1.04625e-2, 8.48826e-3, 6.97601e-3, 5.84232e-3, 4.95306e-3, 4.29232e-3, 3.78161e-3,
    3.40405e-3, 3.11591e-3, 2.91222e-3, 2.79696e-3, 2.68568e-3, 2.57142e-3, 2.47603e-3, 2.37667e-3, 2.32898e-3,
    2.31308e-3, 2.36475e-3, 2.50584e-3, 2.66183e-3, 2.83472e-3, 3.03046e-3, 3.09206e-3, 3.15366e-3,
])
#: The value Mobley et al. (1993) Table 2 prints at 0.50119 deg (index 7), kept for the test of the correction.
MOBLEY1993_PRINTED_0_50119_PER_SR = 2.18839e2
#: The power law of MOBLEY1993_PARTICLE_PER_SR below its second angle (Mobley et al. 1993, Section 3: the
#: negative slope of log p against log theta between 0.1 and 0.12589 deg).
MOBLEY1993_SMALL_ANGLE_SLOPE = 1.346

#: Grid of the tables: ln(theta) uniform from THETA_MIN_RAD to pi, and the inverse CDF on SAMPLE_TABLE_SIZE
#: equal steps of probability.
THETA_MIN_RAD = 1e-8
THETA_GRID_SIZE = 12001
SAMPLE_TABLE_SIZE = 1 << 16

PHASE_FUNCTIONS = ("petzold", "fournier_forand", "henyey_greenstein", "rayleigh", "mobley1993_particle")


@dataclass(frozen=True)
class PhaseFunction:
    """A normalised phase function and its tables.

    theta_rad, value_per_sr: (n,) the fine grid (uniform in ln theta) and p on it, normalised;
    raw_integral: 2 pi int p sin(theta) d theta of the formula or table before normalisation (1 for an
    exact analytic form; Petzold's published table gives 0.991); sample_theta_rad: (SAMPLE_TABLE_SIZE + 1,)
    the angle whose cumulative probability is i / SAMPLE_TABLE_SIZE.
    """

    name: str
    theta_rad: np.ndarray
    value_per_sr: np.ndarray
    raw_integral: float
    sample_theta_rad: np.ndarray
    source: str

    def __call__(self, theta_rad):
        """p(theta) [1/sr] at scattering angles ``theta_rad`` (any shape), log-log interpolated."""
        th = np.clip(np.asarray(theta_rad, float), self.theta_rad[0], math.pi)
        return np.exp(np.interp(np.log(th), np.log(self.theta_rad), np.log(self.value_per_sr)))

    @property
    def value_at_pi_per_sr(self) -> float:
        """p(pi) [1/sr]: beta_pi / b of a water with this phase function (MULS Eq. 4's backscatter)."""
        return float(self.value_per_sr[-1])

    def _fraction(self, weight) -> float:
        th = self.theta_rad
        f = 2.0 * math.pi * self.value_per_sr * np.sin(th) * th * weight  # integrand in d ln(theta)
        return float(np.trapezoid(f, np.log(th)))

    @property
    def backscatter_fraction(self) -> float:
        """b_b / b: the share scattered into the backward hemisphere."""
        return self._fraction(self.theta_rad >= 0.5 * math.pi)

    @property
    def mean_cosine(self) -> float:
        """g = <cos theta>, the asymmetry parameter."""
        return self._fraction(np.cos(self.theta_rad))

    def forward_fraction(self, theta_rad: float) -> float:
        """The share of scattering within ``theta_rad`` of the forward direction."""
        if theta_rad <= self.theta_rad[0]:
            return 0.0
        cdf = np.linspace(0.0, 1.0, self.sample_theta_rad.shape[0])
        return float(np.interp(math.log(theta_rad), np.log(self.sample_theta_rad), cdf))

    def truncated(self, theta_rad: float) -> PhaseFunction:
        """This phase function without its forward peak below ``theta_rad``, renormalised (delta-truncation).

        Scattering by less than ``theta_rad`` is then treated as no scattering: a water (a, b) with p
        behaves as (a, b (1 - f)) with the truncated p, f = ``forward_fraction(theta_rad)``.
        """
        if not (0.0 < theta_rad < 0.5 * math.pi):
            raise ParameterError(f"truncation angle = {theta_rad!r}: must lie in (0, pi/2) rad")
        keep = self.theta_rad >= theta_rad
        p = np.where(keep, self.value_per_sr, 0.0)
        th = self.theta_rad
        f = 2.0 * math.pi * p * np.sin(th) * th
        ln_th = np.log(th)
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(ln_th))])
        integral = float(cdf[-1])
        u = np.arange(SAMPLE_TABLE_SIZE + 1) / SAMPLE_TABLE_SIZE
        first = int(np.argmax(keep))
        sample = np.exp(np.interp(u, cdf[first - 1:] / integral, ln_th[first - 1:]))
        sample = np.maximum(sample, theta_rad)
        sample[-1] = math.pi
        # below the cut p is 0 (a floor of 1e-300 keeps its logarithm finite): that light goes straight on
        value = np.where(keep, self.value_per_sr / integral, 1e-300)
        return PhaseFunction(f"{self.name} (truncated at {theta_rad:g} rad)", th, value, self.raw_integral,
                             sample, self.source)

    @property
    def log_table(self) -> tuple[np.ndarray, float, float]:
        """(ln p on the grid, ln theta of its first point, 1 / grid step in ln theta) for the kernels."""
        ln_th = np.log(self.theta_rad)
        return np.log(self.value_per_sr), float(ln_th[0]), float(1.0 / (ln_th[1] - ln_th[0]))


def _tabulate(name: str, raw, source: str) -> PhaseFunction:
    """Normalise ``raw(theta)`` on the fine grid and build the sampling table."""
    ln_th = np.linspace(math.log(THETA_MIN_RAD), math.log(math.pi), THETA_GRID_SIZE)
    th = np.exp(ln_th)
    p = np.asarray(raw(th), float)
    if np.any(~np.isfinite(p)) or np.any(p <= 0.0):
        raise ParameterError(f"phase function '{name}': its values must be finite and > 0 on (0, pi]")
    # 2 pi int p sin(theta) d theta, integrated in ln(theta); below THETA_MIN_RAD p follows the power law
    # of the first grid step (p ~ theta^-s), whose cone holds 2 pi p0 theta0^2 / (2 - s).
    f = 2.0 * math.pi * p * np.sin(th) * th
    slope = -(math.log(p[1]) - math.log(p[0])) / (ln_th[1] - ln_th[0])
    cone = 2.0 * math.pi * p[0] * th[0] ** 2 / (2.0 - slope)
    cdf = cone + np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(ln_th))])
    integral = float(cdf[-1])
    u = np.arange(SAMPLE_TABLE_SIZE + 1) / SAMPLE_TABLE_SIZE
    sample = np.exp(np.interp(u, cdf / integral, ln_th))
    sample[-1] = math.pi
    return PhaseFunction(name, th, p / integral, integral, sample, source)


@lru_cache(maxsize=8)
def petzold() -> PhaseFunction:
    """Petzold's average particle phase function (table above), normalised on the fine grid."""
    ln_a = np.log(np.radians(PETZOLD_ANGLES_DEG))
    ln_v = np.log(PETZOLD_VALUES_PER_SR)
    slope = (ln_v[0] - ln_v[1]) / (ln_a[1] - ln_a[0])  # 1.346: the small-angle power law

    def raw(th):
        x = np.log(th)
        return np.exp(np.where(x < ln_a[0], ln_v[0] - slope * (x - ln_a[0]), np.interp(x, ln_a, ln_v)))

    return _tabulate("petzold", raw, PETZOLD_SOURCE)


@lru_cache(maxsize=8)
def fournier_forand(n: float = FF_PETZOLD_N, mu: float = FF_PETZOLD_MU) -> PhaseFunction:
    """Fournier-Forand phase function for relative refractive index ``n`` > 1 and Junge slope 3 < ``mu`` < 5."""
    if not (1.0 < n < 1.5):
        raise ParameterError(f"fournier_forand n = {n!r}: must lie in (1, 1.5) (particle index relative to water)")
    if not (3.0 < mu < 5.0):
        raise ParameterError(f"fournier_forand mu = {mu!r}: must lie in (3, 5) (Junge slope)")
    nu = 0.5 * (3.0 - mu)
    d180 = 4.0 / (3.0 * (n - 1.0) ** 2)

    def raw(th):
        s2 = np.sin(0.5 * th) ** 2
        d = d180 * s2
        dn = d**nu
        # Fournier and Forand (1994), as written by Mobley, Sundman and Boss (2002), Eq. 2.
        main = (nu * (1.0 - d) - (1.0 - dn) + (d * (1.0 - dn) - nu * (1.0 - d)) / s2) / (
            4.0 * math.pi * (1.0 - d) ** 2 * dn)
        back = (1.0 - d180**nu) / (16.0 * math.pi * (d180 - 1.0) * d180**nu) * (3.0 * np.cos(th) ** 2 - 1.0)
        return main + back

    return _tabulate("fournier_forand", raw, f"Fournier and Forand (1994) with n = {n}, mu = {mu} "
                     "(Mobley, Sundman and Boss 2002: b_b/b = 0.0183 for n 1.10, mu 3.5835)")


@lru_cache(maxsize=8)
def henyey_greenstein(g: float = 0.924) -> PhaseFunction:
    """Henyey-Greenstein phase function of asymmetry ``g`` in (-1, 1)."""
    if not (-1.0 < g < 1.0):
        raise ParameterError(f"henyey_greenstein g = {g!r}: must lie in (-1, 1)")

    def raw(th):
        return (1.0 - g * g) / (4.0 * math.pi * (1.0 + g * g - 2.0 * g * np.cos(th)) ** 1.5)  # Henyey & Greenstein (1941)

    return _tabulate("henyey_greenstein", raw, f"Henyey and Greenstein (1941), g = {g}")


@lru_cache(maxsize=1)
def rayleigh() -> PhaseFunction:
    """The Rayleigh phase function 3/(16 pi) (1 + cos^2 theta) (Mobley et al. 1993, Eq. 3: their problem 1)."""

    def raw(th):
        return 3.0 / (16.0 * math.pi) * (1.0 + np.cos(th) ** 2)  # Mobley et al. (1993) Eq. 3

    return _tabulate("rayleigh", raw, "Rayleigh, 3/(16 pi) (1 + cos^2 theta): Mobley et al. (1993) Eq. 3")


@lru_cache(maxsize=1)
def mobley1993_particle() -> PhaseFunction:
    """The particle phase function of problem 2 of Mobley et al. (1993): their Table 2, with the power law
    theta^-1.346 through its 0.12589 deg value below that angle (their Section 3).

    Between the tabulated angles p sin(theta) is linear in theta: the trapezoidal rule the paper normalised the
    table with is then the exact integral, and the table integrates to 1 as the paper states (p itself linear,
    the paper's wording, would integrate to 1.018 over the forward peak's log-spaced angles).
    """
    angles = np.radians(PETZOLD_ANGLES_DEG)
    values = MOBLEY1993_PARTICLE_PER_SR
    weighted = values * np.sin(angles)

    def raw(th):
        small = values[1] * (angles[1] / np.minimum(th, angles[1])) ** MOBLEY1993_SMALL_ANGLE_SLOPE
        # at theta = pi sin vanishes: the last interval is p linear, ending at the tabulated p(pi)
        inner = np.interp(th, angles, weighted) / np.maximum(np.sin(th), 1e-300)
        last = values[-2] + (values[-1] - values[-2]) * (th - angles[-2]) / (angles[-1] - angles[-2])
        return np.where(th < angles[1], small, np.where(th < angles[-2], inner, last))

    return _tabulate("mobley1993_particle", raw, "Mobley et al. (1993) Appl. Opt. 32, 7484, Table 2 (Petzold's "
                     "average particle phase function), p sin(theta) linear between its angles, theta^-1.346 "
                     "below 0.12589 deg")


def phase_function(name: str, **params) -> PhaseFunction:
    """The named phase function (one of :data:`PHASE_FUNCTIONS`) with its parameters."""
    if name in ("petzold", "rayleigh", "mobley1993_particle"):
        if params:
            raise ParameterError(f"phase function {name!r} takes no parameters, got {sorted(params)}")
        return {"petzold": petzold, "rayleigh": rayleigh, "mobley1993_particle": mobley1993_particle}[name]()
    if name == "fournier_forand":
        return fournier_forand(**params)
    if name == "henyey_greenstein":
        return henyey_greenstein(**params)
    raise ParameterError(f"phase function = {name!r}: must be one of {', '.join(PHASE_FUNCTIONS)}")


def check_phase(phase) -> PhaseFunction:
    """Accept a PhaseFunction or a name."""
    if isinstance(phase, PhaseFunction):
        return phase
    if isinstance(phase, str):
        return phase_function(phase)
    raise ParameterError(f"phase = {phase!r}: must be a PhaseFunction or one of {', '.join(PHASE_FUNCTIONS)}")


__all__ = ["MOBLEY1993_PARTICLE_PER_SR", "PHASE_FUNCTIONS", "PETZOLD_ANGLES_DEG", "PETZOLD_VALUES_PER_SR",
           "PhaseFunction", "check_phase", "fournier_forand", "henyey_greenstein",
           "mobley1993_particle", "petzold", "phase_function", "rayleigh"]
