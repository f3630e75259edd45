"""Total propagated uncertainty (TPU) of every point: THU and TVU at 95 %, propagated term by term.

A point is X = p + R(roll, pitch, yaw) (m + rho u): the platform position p, its attitude R, the beam's exit m on
the vehicle (the mounting) and the measured range rho along the beam's direction u at the mirror's scan angle. Each
independent error source k moves X by J_k e_k, its Jacobian times its error, and the covariance of X is the sum of
their variances times J_k J_k^T (the propagation of variances of Hare 1995 for multibeam sounders and of Eren et al.
2019 for bathymetric lidar; ``docs/uncertainty.md`` states every term and its source):

- ranging: rho's error per channel, SNR and clipping, measured from the instrument's own ranging
  (:mod:`scanner_sim.survey.ranging_precision`): a mean b (its systematic part) and a standard deviation, along the
  beam: J = u;
- footprint on the surface: the beam's disc of diameter w = D + 2 rho tan(gamma / 2) met at incidence theta spreads
  the echo over ranges of standard deviation sigma_f = (w / 4) tan(theta) centred on the axis's, which moves the
  ranged echo not at all to first order but widens it from the pulse's rms length sigma_L to
  sqrt(sigma_L^2 + sigma_f^2); the timing's noise grows with the echo's width, so the ranging's standard deviation s
  becomes s sqrt(1 + (sigma_f / sigma_L)^2), along the beam: J = u;
- navigation position (east, north) and depth: J = unit axes;
- attitude: a small turn e about axis a moves X by e (a x v), v = X - p the lever from the vehicle's reference
  point (mounting and range together): heading turns about the vertical, pitch about the yawed pitch axis
  -Rz(yaw) y, roll about the vehicle's forward axis R x.

TVU is the 95 % quantile of |vertical error| for a normal error of mean u_z b and standard deviation sigma_z (the
folded normal's; 1.96 sigma_z when b = 0, the one-dimensional 95 % factor, about |u_z b| + 1.645 sigma_z when the
bias dominates). THU = 2.45 sigma_h
with sigma_h^2 = (sigma_x^2 + sigma_y^2 + |u_xy b|^2) / 2: the 95 % radius of a circular bivariate normal,
sqrt(-2 ln 0.05) = 2.4477 sigma, of the same mean square horizontal error.

The surface reading, ``tvu_surface_m``, is the same quantile of d = a . e, the point's height above the surface under
its own (x, y), with a = (-g_x, -g_y, 1) and g the slope of the facet it ranged (:func:`surface_axis`). Its
variance is sum_k sigma_k^2 (a . J_k)^2, so it carries the horizontal errors times the slope.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from muls.infra.borrowed import borrowed
from muls.infra.runtime import kernel
from scanner_sim.survey.folded_normal import rounded_folded_normal_quantile
from scanner_sim.survey.georeference import GRAZING_COS
from scanner_sim.survey.ranging_precision import RangingPrecision, look_up_one

#: The confidence of THU and TVU.
CONFIDENCE = 0.95
#: THU and TVU are reported to the millimetre [decimals of a metre], the resolution of the points' LAS coordinates
#: (which keeps points.laz compact: noise in the low bits would not compress).
REPORTED_DECIMALS = 3
#: 95 % factor of a circular bivariate normal error (horizontal): sqrt(-2 ln 0.05) = 2.4477.
K95_HORIZONTAL = 2.45
#: Column of the predicted error's mean and variances (:meth:`TpuModel.error_model`) along the surface reading's
#: axis (:func:`surface_axis`), after x, y and z.
SURFACE = 3


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
    """What the propagation needs of a pass: its measured ranging precision, its navigation's noise, its beam
    (exit diameter [m], full divergence in the water [rad]) and its pulse's rms length in range [m] (the emitted
    pulse's standard deviation in time, as digitised, times half the speed of light in the water)."""

    ranging: RangingPrecision
    navigation: NavigationSigmas
    beam_diameter_m: float
    divergence_full_rad: float
    pulse_sigma_m: float

    def footprint_sigma_m(self, range_m: np.ndarray, incidence_deg: np.ndarray) -> np.ndarray:
        """(n,) range spread [m] of the beam's footprint on a surface met at ``incidence_deg`` (n,) at ``range_m``
        (n,): (w / 4) tan(theta), the standard deviation of x tan(theta) over a uniformly lit disc of diameter w
        (the pass's ``top_hat`` beam; a Gaussian beam cut at its 1/e^2 radius has 0.21 w, less); 0 where the
        incidence is unknown (NaN)."""
        width = self.beam_diameter_m + 2.0 * range_m * math.tan(0.5 * self.divergence_full_rad)
        return 0.25 * width * _incidence_tan(incidence_deg)

    def variances(self, lever_m, direction, attitude_rad, range_sigma_m, axes=None) -> np.ndarray:
        """(n, m) variances [m^2] of the point's error along each of m ``axes`` (n, m, 3) (sum over the sources of
        sigma_k^2 (a . J_k)^2; None: x, y and z, the covariance's diagonal) of points whose lever from the vehicle's
        reference point is ``lever_m`` (n, 3) [m], along beam ``direction`` (n, 3) unit, the vehicle at
        ``attitude_rad`` (n, 3) roll, pitch, yaw, with range standard uncertainty ``range_sigma_m`` (n,) [m]
        (ranging and footprint together). An axis need not be a unit vector: the surface reading's is not
        (:func:`surface_axis`)."""
        return self._propagated(lever_m, direction, attitude_rad, range_sigma_m, axes, np.zeros(0))[1]

    def _propagated(self, lever_m, direction, attitude_rad, range_sigma_m, axes, bias) -> tuple[np.ndarray, np.ndarray]:
        """(mean (n, m) [m], variances (n, m) [m^2]) along ``axes``, the mean the ranging's ``bias`` (n,) [m] along the
        beam (an empty ``bias``: no mean, (0, m)); the rest as :meth:`variances`, whose sums :func:`_propagate` does
        point by point. The turns' sines and cosines are numpy's (its own vectorised routines, whose last bits a compiled
        call to the C library need not share)."""
        nav = self.navigation
        u = np.ascontiguousarray(direction, np.float64)
        n = len(u)
        a = np.ascontiguousarray(np.broadcast_to(np.eye(3), (n, 3, 3)) if axes is None else axes, np.float64)
        turns = self._turns(attitude_rad)
        mean, var = np.empty((n if bias.size else 0, a.shape[1])), np.empty((n, a.shape[1]))
        _propagate(np.ascontiguousarray(lever_m, np.float64), u, a, np.ascontiguousarray(range_sigma_m, np.float64),
                   np.ascontiguousarray(bias, np.float64), nav.position_m**2, nav.depth_m**2, nav.heading_rad,
                   nav.attitude_rad, turns, mean, var)
        return mean, var

    def _turns(self, attitude_rad) -> np.ndarray:
        """(n, 4) sin and cos of the yaw and of the pitch of ``attitude_rad`` (n, 3) roll, pitch, yaw, as
        :func:`_propagate_point` takes them; (0, 4) where the navigation has no attitude error (none are read)."""
        if not self.navigation.attitude_rad:
            return np.zeros((0, 4))
        yaw, pitch = attitude_rad[:, 2], attitude_rad[:, 1]
        return np.stack([np.sin(yaw), np.cos(yaw), np.sin(pitch), np.cos(pitch)], axis=1)

    def error_model(self, lever_m, direction, attitude_rad, channel, snr, saturated, later, range_m, incidence_deg,
                    normal=None) -> tuple[np.ndarray, np.ndarray]:
        """The predicted error of n points: its mean (n, 4) [m] (the ranging's bias along the beam) and variances
        (n, 4) [m^2], along x, y, z and the surface reading's axis (:func:`surface_axis` of the ranged facet's
        ``normal`` (n, 3); None or NaN rows: z). Arguments as :meth:`variances` and :meth:`RangingPrecision.of`;
        ``range_m`` (n,) the measured range [m], ``incidence_deg`` (n,). The numpy form of the model: a pass runs
        :meth:`predict`'s kernel, which a test holds to this bit for bit."""
        bias, std = self.ranging.of(channel, snr, saturated, later, range_m)
        sigma_range = std * np.hypot(1.0, self.footprint_sigma_m(range_m, incidence_deg) / self.pulse_sigma_m)
        n = len(bias)
        axes = np.empty((n, 4, 3))
        axes[:, :3] = np.eye(3)
        axes[:, SURFACE] = surface_axis(np.full((n, 3), np.nan) if normal is None else normal)
        return self._propagated(lever_m, direction, attitude_rad, sigma_range, axes, bias)

    def predict(self, points, sight, normal=None) -> tuple[np.ndarray, np.ndarray]:
        """The predicted error (:meth:`error_model`) of a chunk's ``points`` (:class:`PointRecords`) from its lines of
        sight ``sight`` (:class:`~scanner_sim.survey.georeference.LinesOfSight`: each pulse's estimated beam and
        pose) and the unit normals (n, 3) of the facets they ranged (NaN rows for noise); the measured range is the
        point's distance from its beam's origin. Point by point in one kernel (:func:`_predict`), the same bits as
        :meth:`error_model` on the gathered arrays; the turns' sines and cosines and the incidence's tangent (in float32,
        as the points hold it) are numpy's, taken per pulse and per point before it."""
        nav = self.navigation
        n = len(points.xyz)
        if n and (not sight.slot.size or points.pulse_index.max() > sight.slot[-1]):
            raise IndexError("a point's pulse lies past the last line of sight of its chunk")
        mean, var = np.empty((n, 4)), np.empty((n, 4))
        _predict(points.xyz, points.pulse_index, points.channel, points.snr, points.saturated, points.return_number,
                 _incidence_tan(points.incidence_deg),
                 np.empty((0, 3)) if normal is None else np.ascontiguousarray(normal, np.float64),
                 sight.slot, sight.origin_m, sight.direction, sight.platform_m, self._turns(sight.attitude_rad),
                 *self.ranging.flat_tables(),
                 (self.beam_diameter_m, math.tan(0.5 * self.divergence_full_rad), self.pulse_sigma_m, GRAZING_COS),
                 (nav.position_m**2, nav.depth_m**2, nav.heading_rad, nav.attitude_rad), mean, var,
                 (np.empty(len(self.ranging.ranges_m)), np.empty((4, 3))))
        return mean, var


@kernel(nogil=True, error_model="numpy")
def _predict(xyz, pulse_index, channel, snr, saturated, return_number, tan_incidence, normal, slot, origin, direction,
             platform, turns, bias_m, std_m, channels, bins, ranges_m, edges, beam, nav, mean, var, scratch):
    """:meth:`TpuModel.predict` point by point into ``mean`` and ``var`` (n, 4): each point's pulse found in the sorted
    ``slot`` (as ``np.searchsorted``), its lever, beam and measured range (as the einsum of :meth:`TpuModel.predict`'s
    numpy form), its ranging's bias and spread (:func:`~scanner_sim.survey.ranging_precision.look_up_one` of the flat
    tables), the footprint's widening, its axes (x, y, z and :func:`surface_axis`'s of ``normal``, (n, 3) or (0, 3):
    none) and the propagation (:func:`_propagate_point`). ``beam``: (exit diameter [m], tan of half the divergence,
    the pulse's rms length [m], :data:`GRAZING_COS`); ``nav``: (position and depth variances [m^2], heading and
    attitude sigmas [rad]); ``turns`` (pulses, 4) as :func:`_propagate`'s, per pulse, or (0, 4) without attitude;
    ``scratch``: the look-up's (panels,) and the axes' (4, 3). Its arguments borrowed (:mod:`muls.infra.borrowed`)."""
    (xyz, pulse_index, channel, snr, saturated, return_number, tan_incidence, normal, slot, origin, direction, platform,
     turns, bias_m, std_m, ranges_m, edges, mean, var, scratch) = borrowed(
        (xyz, pulse_index, channel, snr, saturated, return_number, tan_incidence, normal, slot, origin, direction,
         platform, turns, bias_m, std_m, ranges_m, edges, mean, var, scratch))
    beam_diameter, tan_half_divergence, pulse_sigma, grazing_cos = beam
    position_var, depth_var, heading, attitude = nav
    measured, axes = scratch
    axes[:] = 0.0
    axes[0, 0] = axes[1, 1] = axes[2, 2] = 1.0
    known = normal.shape[0] > 0
    if not known:  # every point's surface axis that of an unknown normal
        axes[3, 0], axes[3, 1], axes[3, 2] = _surface_axis_of(np.nan, np.nan, np.nan, grazing_cos)
    row = 0
    for i in range(xyz.shape[0]):
        row = _first_not_below(slot, pulse_index[i], row)
        u = (direction[row, 0], direction[row, 1], direction[row, 2])
        range_m = _dot((xyz[i, 0] - origin[row, 0], xyz[i, 1] - origin[row, 1], xyz[i, 2] - origin[row, 2]), u)
        bias, std = look_up_one(bias_m, std_m, channels, bins, ranges_m, edges, np.int64(channel[i]),
                                np.float64(snr[i]), np.int64(saturated[i]), np.int64(return_number[i] > 1), range_m,
                                measured)
        footprint = 0.25 * (beam_diameter + 2.0 * range_m * tan_half_divergence) * np.float64(tan_incidence[i])
        sigma = std * math.hypot(1.0, footprint / pulse_sigma)
        if known:
            axes[3, 0], axes[3, 1], axes[3, 2] = _surface_axis_of(normal[i, 0], normal[i, 1], normal[i, 2], grazing_cos)
        turn = (turns[row, 0], turns[row, 1], turns[row, 2], turns[row, 3]) if attitude else (0.0, 1.0, 0.0, 1.0)
        lever = (xyz[i, 0] - platform[row, 0], xyz[i, 1] - platform[row, 1], xyz[i, 2] - platform[row, 2])
        _propagate_point(i, lever, u, axes, sigma, bias, True, position_var, depth_var, heading, attitude, turn, mean,
                         var)


@kernel(nogil=True)
def _propagate(lever, u, axes, range_sigma, bias, position_var, depth_var, heading, attitude, turns, mean, var):
    """Fill ``mean`` (n, m) with bias . (a . u) (unless ``bias`` is empty) and ``var`` (n, m) with the variances of
    :meth:`TpuModel.variances`, point by point (:func:`_propagate_point`): the ranging along the beam, the
    navigation's position (``position_var``, ``depth_var`` [m^2]) along the unit axes, and each turn (``heading``,
    ``attitude`` [rad], 0: none) through a x v, v the ``lever``. ``turns`` (n, 4): sin and cos of yaw, sin and cos of
    pitch (when ``attitude``). The figures equal numpy's evaluation of the same formulas, bit for bit."""
    with_bias = bias.shape[0] > 0
    for i in range(axes.shape[0]):
        turn = (turns[i, 0], turns[i, 1], turns[i, 2], turns[i, 3]) if attitude else (0.0, 1.0, 0.0, 1.0)
        _propagate_point(i, (lever[i, 0], lever[i, 1], lever[i, 2]), (u[i, 0], u[i, 1], u[i, 2]), axes[i],
                         range_sigma[i], bias[i] if with_bias else 0.0, with_bias, position_var, depth_var, heading,
                         attitude, turn, mean, var)


@kernel(inline="always")
def _propagate_point(i, lever, u, axes, range_sigma, bias, with_bias, position_var, depth_var, heading, attitude, turn,
                     mean, var):
    """Row i of ``mean`` (bias . (a . u), when ``with_bias``) and ``var`` (n, m) along each of the m ``axes`` (m, 3) of
    one point: its ``lever`` and beam direction ``u`` as 3-tuples, its ``range_sigma`` and ``bias`` [m], and ``turn``,
    the sin and cos of its yaw and of its pitch. Each sum is taken in the order numpy takes it over arrays, each a . J
    as numpy's einsum adds its three terms, (a_0 J_0 + a_2 J_2) + a_1 J_1 onto 0: the figures equal numpy's evaluation
    of :meth:`TpuModel.variances`, bit for bit."""
    l0, l1, l2 = lever
    heading_v = (0.0 * l2 - 1.0 * l1, 1.0 * l0 - 0.0 * l2, 0.0 * l1 - 0.0 * l0)  # z x v
    pitch_v, roll_v = heading_v, heading_v
    if attitude:
        sin_yaw, cos_yaw, sin_pitch, cos_pitch = turn
        pitch_v = _cross(sin_yaw, -cos_yaw, 0.0, l0, l1, l2)  # pitch: about -Rz(yaw) y
        roll_v = _cross(cos_yaw * cos_pitch, sin_yaw * cos_pitch, sin_pitch, l0, l1, l2)  # roll: about R x
    for j in range(axes.shape[0]):
        a = (axes[j, 0], axes[j, 1], axes[j, 2])
        along = _dot(a, u)
        if with_bias:
            mean[i, j] = bias * along
        s = range_sigma * along
        v = s * s
        v += position_var * (a[0] * a[0] + a[1] * a[1]) + depth_var * (a[2] * a[2])
        if heading:
            s = heading * _dot(a, heading_v)
            v += s * s
        if attitude:
            s = attitude * _dot(a, pitch_v)
            v += s * s
            s = attitude * _dot(a, roll_v)
            v += s * s
        var[i, j] = v


@kernel(inline="always")
def _first_not_below(slot, value, guess):
    """The first index of the sorted ``slot`` (n,) whose value is not below ``value`` (``np.searchsorted``'s left
    side): ``guess`` or the one after it where either is (a chunk's points come in pulse order, so the previous
    point's row nearly always is), else a binary search."""
    n = slot.shape[0]
    for row in (guess, guess + 1):
        if row <= n and (row == n or slot[row] >= value) and (row == 0 or slot[row - 1] < value):
            return row
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if slot[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@kernel(inline="always")
def _dot(a, b):
    """a . b of two 3-tuples, its terms added as numpy's einsum adds them (and so the same bits)."""
    return 0.0 + ((a[0] * b[0] + a[2] * b[2]) + a[1] * b[1])


@kernel(inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    """a x b of two vectors given by their components, term for term."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


def _incidence_tan(incidence_deg) -> np.ndarray:
    """(n,) tan of ``incidence_deg`` (n,), numpy's in the angles' own precision (the points hold float32), 0 where the
    incidence is unknown (NaN)."""
    return np.tan(np.radians(np.nan_to_num(incidence_deg, nan=0.0)))


def surface_axis(normal) -> np.ndarray:
    """(n, 3) the axis a = (-g_x, -g_y, 1) whose product with a point's error e is its vertical error against the
    surface under its own (x, y): on the plane z = z0 + g . (x - x0, y - y0) through the true point, the surface
    under X = P + e lies at z0 + g . e_xy, so X_z minus it is e_z - g . e_xy = a . e, with g = -n_xy / n_z the
    slope of a facet of unit ``normal`` (n, 3). A normal unknown (NaN) gives (0, 0, 1), the plain vertical; a facet
    within :data:`~scanner_sim.survey.georeference.GRAZING_COS` of vertical has no surface under (x, y) to read, and
    gives NaN."""
    normal = np.ascontiguousarray(normal, np.float64)
    axis = np.empty_like(normal)
    _surface_axis(normal, GRAZING_COS, axis)
    return axis


@kernel(nogil=True, error_model="numpy")
def _surface_axis(normal, grazing_cos, axis):
    """:func:`surface_axis` of each row of ``normal`` (n, 3) into ``axis`` (n, 3)."""
    for i in range(normal.shape[0]):
        axis[i, 0], axis[i, 1], axis[i, 2] = _surface_axis_of(normal[i, 0], normal[i, 1], normal[i, 2], grazing_cos)


@kernel(inline="always")
def _surface_axis_of(n0, n1, n2, grazing_cos):
    """:func:`surface_axis` of one unit normal (n0, n1, n2), as a 3-tuple (with numpy's error model: a facet's
    n_z of 0 divides to infinities, then the grazing test gives NaN)."""
    known = np.isfinite(n0) and np.isfinite(n1) and np.isfinite(n2)
    nz = n2 if known else 1.0
    g0, g1 = (-n0 / nz, -n1 / nz) if known else (0.0, 0.0)
    if abs(nz) < grazing_cos:
        return np.nan, np.nan, np.nan
    return -g0, -g1, 1.0


def with_uncertainty(points, mean, var):
    """``points`` (:class:`PointRecords`) with ``thu_m``, ``tvu_m`` and ``tvu_surface_m`` (95 %, to the millimetre)
    of their predicted error of ``mean`` (n, 4) and variances ``var`` (n, 4) (:meth:`TpuModel.error_model`)."""
    return dataclasses.replace(points, thu_m=np.round(thu_of(mean, var), REPORTED_DECIMALS),
                               tvu_m=tvu_of(mean, var), tvu_surface_m=tvu_of(mean, var, SURFACE))


def horizontal_sigma(mean, var) -> np.ndarray:
    """(n,) sigma_h [m]: the per-axis standard deviation of the circular bivariate normal of the same mean square
    horizontal error as errors of ``mean`` (n, 3) and variances ``var`` (n, 3)."""
    return np.sqrt(0.5 * (var[:, 0] + var[:, 1] + mean[:, 0] ** 2 + mean[:, 1] ** 2))


def thu_of(mean, var) -> np.ndarray:
    """(n,) THU [m]: 2.45 sigma_h (:func:`horizontal_sigma`)."""
    return K95_HORIZONTAL * horizontal_sigma(mean, var)


def tvu_of(mean, var, axis: int = 2) -> np.ndarray:
    """(n,) TVU [m] to the millimetre (:data:`REPORTED_DECIMALS`): the 95 % quantile of |vertical error| of errors of
    ``mean`` (n, m) and variances ``var`` (n, m), along the true beam (``axis`` 2, z) or against the surface under the
    point (:data:`SURFACE`) (:mod:`scanner_sim.survey.folded_normal`); NaN where the figure is unknown."""
    return rounded_folded_normal_quantile(mean[:, axis], np.sqrt(var[:, axis]), CONFIDENCE, REPORTED_DECIMALS)


def coverage_levels(mean, var, vertical_m, horizontal_m) -> tuple[np.ndarray, np.ndarray]:
    """The coverage level at which each of n true errors lies on its predicted distribution, each (n,) in [0, 1]:
    P(|Z| <= |vertical|) for Z normal of the predicted vertical mean and variance, and P(R <= horizontal) for R the
    radius of the circular bivariate normal of :func:`horizontal_sigma`, 1 - exp(-h^2 / (2 sigma_h^2)). A model
    that is right gives levels spread uniformly: the share of levels <= q is q (the calibration curve). The
    definition over arrays: a pass takes the same figures point by point in
    :func:`~scanner_sim.survey.tpu_calibration.checked_errors`' kernel, which tests/scanner_sim/survey/test_tpu_calibration.py
    holds to this, bit for bit."""
    mu, sigma = mean[:, 2], np.maximum(np.sqrt(var[:, 2]), 1e-6)
    e = np.abs(vertical_m)
    level_z = ndtr((e - mu) / sigma) - ndtr((-e - mu) / sigma)
    level_h = -np.expm1(-0.5 * (horizontal_m / np.maximum(horizontal_sigma(mean, var), 1e-6)) ** 2)
    return level_z, level_h
