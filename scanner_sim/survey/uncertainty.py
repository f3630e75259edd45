"""Total propagated uncertainty (TPU) of every point: THU and TVU at 95 %, propagated term by term.

A point is X = p + R(roll, pitch, yaw) (m + rho u): the platform position p, its attitude R, the beam's exit m on
the vehicle (the mounting) and the measured range rho along the beam's direction u at the mirror's scan angle. Each
independent error source k moves X by J_k e_k, its Jacobian times its error, and the covariance of X is the sum of
their variances times J_k J_k^T (the propagation of Hare 1995 and Hare, Godin and Mayer 2011 for hydrographic
sounders, applied to a lidar beam; ``docs/uncertainty.md`` states every term and its source):

- ranging: rho's error per channel, SNR and clipping, measured from the instrument's own ranging
  (:mod:`scanner_sim.survey.ranging_precision`): a mean b (its systematic part) and a standard deviation, along the
  beam: J = u;
- footprint on the surface: the beam's disc of diameter w = D + 2 rho tan(gamma / 2) met at incidence theta spreads
  the echo over ranges of standard deviation (w / 4) tan(theta) about the axis's, along the beam: J = u;
- navigation position (east, north) and depth: J = unit axes;
- attitude: a small turn e about axis a moves X by e (a x v), v = X - p the lever from the vehicle's reference
  point (mounting and range together): heading turns about the vertical, pitch about the yawed pitch axis
  -Rz(yaw) y, roll about the vehicle's forward axis R x.

TVU is the 95 % quantile of |vertical error| for a normal error of mean u_z b and standard deviation sigma_z (the
folded normal's; 1.96 sigma_z when b = 0, about |u_z b| + 1.645 sigma_z when the bias dominates). THU = 2.45 sigma_h
with sigma_h^2 = (sigma_x^2 + sigma_y^2 + |u_xy b|^2) / 2: the 95 % radius of a circular bivariate normal,
sqrt(-2 ln 0.05) = 2.4477 sigma, of the same mean square horizontal error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from scanner_sim.survey.ranging_precision import RangingPrecision

#: 95 % factor of a one-dimensional normal error of zero mean (vertical).
K95_VERTICAL = 1.96
#: The confidence of THU and TVU.
CONFIDENCE = 0.95
#: Halvings of the bracket in :func:`folded_normal_quantile`: 2^-30 of a 1 m bracket is under a nanometre.
BISECTIONS = 30
#: THU and TVU are reported to the millimetre [decimals of a metre], the resolution of the points' LAS coordinates
#: (which keeps points.laz compact: noise in the low bits would not compress).
REPORTED_DECIMALS = 3
#: 95 % factor of a circular bivariate normal error (horizontal): sqrt(-2 ln 0.05) = 2.4477.
K95_HORIZONTAL = 2.45


@dataclass(frozen=True)
class NavigationSigmas:
    """Standard deviations of the navigation's errors (the pass's Gauss-Markov noise is stationary at these):
    position east and north [m], depth [m], roll and pitch [rad], heading [rad]."""

    position_m: float = 0.0
    depth_m: float = 0.0
    attitude_rad: float = 0.0
    heading_rad: float = 0.0

    @classmethod
    def of(cls, noise) -> NavigationSigmas:
        """From a :class:`scanner_sim.config.NavigationNoiseConfig`."""
        return cls(noise.position_sigma_m, noise.depth_sigma_m, math.radians(noise.attitude_sigma_deg),
                   math.radians(noise.heading_sigma_deg))

    def as_dict(self) -> dict:
        """The sigmas as the summary states them: position and depth [m], attitude and heading [deg]."""
        return {"position_sigma_m": self.position_m, "depth_sigma_m": self.depth_m,
                "attitude_sigma_deg": round(math.degrees(self.attitude_rad), 6),
                "heading_sigma_deg": round(math.degrees(self.heading_rad), 6)}


@dataclass(frozen=True)
class TpuModel:
    """What the propagation needs of a pass: its measured ranging precision, its navigation's noise, and its beam
    (exit diameter [m], full divergence in the water [rad])."""

    ranging: RangingPrecision
    navigation: NavigationSigmas
    beam_diameter_m: float
    divergence_full_rad: float

    def footprint_sigma_m(self, range_m: np.ndarray, incidence_deg: np.ndarray) -> np.ndarray:
        """(n,) range spread [m] of the beam's footprint on a surface met at ``incidence_deg`` (n,) at ``range_m``
        (n,): (w / 4) tan(theta), the standard deviation of x tan(theta) over a disc of diameter w (a uniform
        disc's, and a Gaussian beam's to its 1/e^2 radius); 0 where the incidence is unknown (NaN)."""
        width = self.beam_diameter_m + 2.0 * range_m * math.tan(0.5 * self.divergence_full_rad)
        tan = np.tan(np.radians(np.nan_to_num(incidence_deg, nan=0.0)))
        return 0.25 * width * tan

    def covariance(self, lever_m, direction, attitude_rad, range_sigma_m) -> np.ndarray:
        """(n, 3, 3) covariance [m^2] of points whose lever from the vehicle's reference point is ``lever_m`` (n, 3)
        [m], along beam ``direction`` (n, 3) unit, the vehicle at ``attitude_rad`` (n, 3) roll, pitch, yaw, with
        range standard uncertainty ``range_sigma_m`` (n,) [m] (ranging and footprint together)."""
        nav = self.navigation
        u = np.asarray(direction, np.float64)
        cov = (range_sigma_m**2)[:, None, None] * u[:, :, None] * u[:, None, :]
        cov[:, 0, 0] += nav.position_m**2
        cov[:, 1, 1] += nav.position_m**2
        cov[:, 2, 2] += nav.depth_m**2
        yaw, pitch = attitude_rad[:, 2], attitude_rad[:, 1]
        n = yaw.shape[0]
        axes = (
            (nav.heading_rad, np.tile([0.0, 0.0, 1.0], (n, 1))),
            (nav.attitude_rad, np.c_[np.sin(yaw), -np.cos(yaw), np.zeros(n)]),  # -Rz(yaw) y
            (nav.attitude_rad, np.c_[np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)]),  # R x
        )
        for sigma, axis in axes:
            if sigma:
                j = np.cross(axis, lever_m)
                cov += sigma**2 * j[:, :, None] * j[:, None, :]
        return cov

    def error_model(self, lever_m, direction, attitude_rad, channel, snr, saturated, later, range_m, incidence_deg
                    ) -> tuple[np.ndarray, np.ndarray]:
        """The predicted error of n points: its mean (n, 3) [m] (the ranging's bias along the beam) and covariance
        (n, 3, 3) [m^2]. Arguments as :meth:`covariance` and :meth:`RangingPrecision.of`; ``range_m`` (n,) the
        measured range [m], ``incidence_deg`` (n,)."""
        bias, std = self.ranging.of(channel, snr, saturated, later, range_m)
        sigma_range = np.hypot(std, self.footprint_sigma_m(range_m, incidence_deg))
        return bias[:, None] * direction, self.covariance(lever_m, direction, attitude_rad, sigma_range)

    def __call__(self, *point) -> tuple[np.ndarray, np.ndarray]:
        """(THU, TVU) [m] at 95 %, each (n,), of n points (arguments as :meth:`error_model`), to the millimetre."""
        mean, cov = self.error_model(*point)
        return np.round(thu_of(mean, cov), REPORTED_DECIMALS), np.round(tvu_of(mean, cov), REPORTED_DECIMALS)


def thu_of(mean, cov) -> np.ndarray:
    """(n,) THU [m]: 2.45 sigma_h, sigma_h^2 the mean square horizontal error over two, of errors of ``mean`` (n, 3)
    and covariance ``cov`` (n, 3, 3)."""
    return K95_HORIZONTAL * np.sqrt(0.5 * (cov[:, 0, 0] + cov[:, 1, 1] + mean[:, 0] ** 2 + mean[:, 1] ** 2))


def tvu_of(mean, cov, p: float = CONFIDENCE) -> np.ndarray:
    """(n,) TVU [m]: the ``p`` quantile of |vertical error| of errors of ``mean`` (n, 3) and covariance ``cov``."""
    return folded_normal_quantile(mean[:, 2], np.sqrt(cov[:, 2, 2]), p)


def folded_normal_quantile(mean, sigma, p: float) -> np.ndarray:
    """(n,) the T with P(|Z| <= T) = ``p`` for Z normal of ``mean`` (n,) and ``sigma`` (n,) [m]: bisection of
    Phi((T - mean) / sigma) - Phi((-T - mean) / sigma) = p, which rises with T, between 0 and |mean| + 6 sigma, to
    2^-:data:`BISECTIONS` of that bracket. A sigma under 1 micrometre is taken as 1 micrometre."""
    mean, sigma = np.abs(np.asarray(mean, np.float64)), np.maximum(np.asarray(sigma, np.float64), 1e-6)
    lo, hi = np.zeros_like(mean), mean + 6.0 * sigma
    for _ in range(BISECTIONS):
        t = 0.5 * (lo + hi)
        inside = ndtr((t - mean) / sigma) - ndtr((-t - mean) / sigma) >= p
        hi = np.where(inside, t, hi)
        lo = np.where(inside, lo, t)
    return 0.5 * (lo + hi)
