"""Forward scattering kept by the receiver: the two-way transmission of the small-angle approximation.

MULS Eq. 6's k_lidar folds forward scattering into one number made for a narrow field of view. How much
forward-scattered light a lidar keeps depends on the receiver's footprint measured in free paths (Gordon
1982): a footprint much narrower than 1/c keeps none (attenuation c), one many free paths wide keeps nearly
all (attenuation near K_d). The ``small_angle`` attenuation rule computes it from the phase function and
the receiver's field of view in the small-angle approximation of radiative transfer (the approach of Wells
1973 and of Walker and McLean 1999's lidar equation): light scattered through small angles stays on its
line, displaced sideways, and counts when it stays inside the receiver's footprint.

For a target at range Z the echo is the overlap of two irradiance patterns on the target (docs/design.md,
"Attenuation"): the beam (a pencil) and, by reciprocity, the receiver's field (uniform over the footprint of
radius rho = r2(Z) of Eq. 11). Scattering through an angle theta at a distance s before the target moves
light by theta s, so in the Hankel domain each leg is multiplied by exp(-c Z + b int_0^Z P(k s) ds), with
P(nu) = 2 pi int p(theta) J0(nu theta) sin(theta) d theta the transform of the forward hemisphere of the
phase function p (backscattered light is lost). Overlapping the two patterns gives the two-way transmission

    T(Z) = exp(-2 c Z) [1 + int_0^inf J1(x) (exp(2 b rho Q(x Z / rho) / x) - 1) dx],   Q(v) = int_0^v P(nu) d nu

which replaces exp(-2 k Z) in Eqs. 4, 7, 9 and 10 through k = -ln T / (2 Z). To first order in b it keeps
the share of single scattering that lands inside the footprint, int_0^1 F(theta_r/2 / (1 - u)) du of b,
with F the cumulative phase function: 0.60 for the MUL's 100 mrad field and Petzold's phase function.
The phase function is Petzold's average particle phase function (:mod:`muls.water.phase`), the one whose
b_b / b = 0.0183 the K_d estimate already uses. The approximation neglects the longer paths of scattered
light (pulse stretching) and scattering back into the field from large angles; docs/design.md compares it
with the Monte Carlo reference (:mod:`muls.montecarlo`).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .phase import petzold

#: Ranges of the transmission table [m]: logarithmic from MIN to MAX (T is interpolated in between, held
#: at the ends), and the size of that grid.
TABLE_MIN_RANGE_M = 0.01
TABLE_MAX_RANGE_M = 400.0
TABLE_SIZE = 121
#: Grid of the Hankel integral over x = k rho: fine up to X_SPLIT (where J1 and the exponent change most),
#: then steps of X_STEP (16 per period of J1) up to X_MAX, beyond which the integrand is below 1e-6 of its
#: scale.
X_SPLIT = 60.0
X_FINE_SIZE = 6000
X_MAX = 20000.0
X_STEP = 0.4


@lru_cache(maxsize=1)
def _forward_transform() -> tuple[np.ndarray, np.ndarray]:
    """(nu (n,), Q (n,)): Q(v) = int_0^v P(nu) d nu of Petzold's forward hemisphere on a log grid of nu."""
    from scipy.special import j0  # here: a pass whose water needs no small-angle table never imports scipy.special

    phase = petzold()
    forward = phase.theta_rad <= 0.5 * math.pi
    th = phase.theta_rad[forward]
    weight = 2.0 * math.pi * phase.value_per_sr[forward] * np.sin(th) * th  # integrand in d ln(theta)
    ln_th = np.log(th)
    nu = np.concatenate([[0.0], np.logspace(-2.0, 7.0, 901)])
    p = np.array([np.trapezoid(weight * j0(n * th), ln_th) for n in nu])
    q = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(nu))])
    return nu, q


@lru_cache(maxsize=1)
def _x_grid() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, J1(x), trapezoid weights) of the Hankel integral."""
    from scipy.special import j1

    x = np.concatenate([np.linspace(1e-9, X_SPLIT, X_FINE_SIZE),
                        np.arange(X_SPLIT + X_STEP, X_MAX + 0.5 * X_STEP, X_STEP)])
    dx = np.diff(x)
    weight = np.zeros_like(x)
    weight[:-1] += 0.5 * dx
    weight[1:] += 0.5 * dx
    return x, j1(x), weight


def log_transmission(attenuation_per_m: float, scattering_per_m: float, range_m: float,
                     footprint_radius_m: float) -> float:
    """ln T(Z) of the module docstring: two-way transmission of a lidar echo at ``range_m`` [m] through
    water of beam attenuation c and scattering b [1/m], for a receiver footprint of radius rho [m] there."""
    c, b, z, rho = attenuation_per_m, scattering_per_m, range_m, footprint_radius_m
    if z <= 0.0:
        return 0.0
    nu, q = _forward_transform()
    x, bessel, weight = _x_grid()
    exponent = 2.0 * b * rho * np.interp(x * z / rho, nu, q) / x
    top = float(exponent.max())
    # int J1 (exp(E) - 1) dx with exp(top) taken out (E reaches 2 b Z, 70 in the pond at 30 m)
    scaled = float(np.sum(weight * bessel * (np.exp(exponent - top) - math.exp(-top))))
    return -2.0 * c * z + top + math.log(max(scaled, 0.0) + math.exp(-top))


@lru_cache(maxsize=64)
def _table(attenuation_per_m: float, scattering_per_m: float, footprint_radius0_m: float,
           footprint_slope: float) -> tuple[np.ndarray, np.ndarray]:
    """(ln Z (TABLE_SIZE,), k (TABLE_SIZE,)) of one water and receiver: k = -ln T / (2 Z)."""
    z = np.geomspace(TABLE_MIN_RANGE_M, TABLE_MAX_RANGE_M, TABLE_SIZE)
    k = np.array([-log_transmission(attenuation_per_m, scattering_per_m, zi, footprint_radius0_m + footprint_slope * zi)
                  / (2.0 * zi) for zi in z])
    return np.log(z), k


def lidar_attenuation_per_m(attenuation_per_m: float, scattering_per_m: float, footprint_radius0_m: float,
                      footprint_slope: float, range_m):
    """k [1/m] of the ``small_angle`` rule at ``range_m`` [m] (any shape) for a receiver whose footprint
    radius is r2(Z) = footprint_radius0_m + footprint_slope Z (Eq. 11's r2: aperture radius and
    tan(theta_r / 2)); from a table built once per water and receiver, interpolated in ln Z."""
    ln_z, k = _table(float(attenuation_per_m), float(scattering_per_m), float(footprint_radius0_m),
                     float(footprint_slope))
    r = np.asarray(range_m, dtype=float)
    return np.interp(np.log(np.clip(r, TABLE_MIN_RANGE_M, TABLE_MAX_RANGE_M)), ln_z, k)

