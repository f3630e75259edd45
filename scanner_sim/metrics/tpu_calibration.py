"""The uncertainty checked against the truth: how many points' true errors lie within their THU and TVU.

The pass knows where each point truly belongs: the true beam (the vehicle's true pose, the pulse's scan angle)
meets the truth mesh at the true point P. The point's true error is X - P, X the point as the instrument and its
navigation place it, so it holds the ranging error and the navigation's pose error together, as the TPU predicts
them. Points judged: every return the scene's surfaces explain (not noise) whose true beam's first surface is the
surface ranged (its range along the true beam within :data:`SAME_SURFACE_M` of the truth along the point's own line
of sight; another surface there is a return behind an edge, whose true point the first hit is not).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scanner_sim.survey.point_records import PointRecords
from scanner_sim.survey.uncertainty import K95_HORIZONTAL, thu_of, tvu_of
from scanner_sim.world.materials import NOISE_CLASS

#: [m] A true beam whose first hit lies further than this along it from the truth of the point's own line of sight
#: met another surface than the one ranged (an edge between them): the point is not judged.
SAME_SURFACE_M = 0.5
#: Incidence bands [deg] of the calibration table.
INCIDENCE_BANDS_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 90.0)
#: Nominal coverages of the calibration chart: for each, the share of points within that quantile of their
#: predicted error distribution.
CHART_LEVELS = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99])


@dataclass(frozen=True)
class TrueErrors:
    """Per judged point (k of them): vertical error (k,) [m] signed, horizontal error (k,) [m] >= 0, the points
    themselves (their THU, TVU, channel and incidence), and the error the pass's uncertainty model predicts for them
    (``predicted``: mean (k, 3) [m] and covariance (k, 3, 3) [m^2]); ``skipped`` the points not judged, by reason."""

    vertical_m: np.ndarray
    horizontal_m: np.ndarray
    points: PointRecords
    predicted: tuple[np.ndarray, np.ndarray]
    skipped: dict


def true_errors(setup, points: PointRecords) -> TrueErrors:
    """The true errors (module doc) of ``points`` of the pass of ``setup`` (a :class:`PassSetup`)."""
    poses = setup.trajectory.poses(points.gps_time_s)
    origin, direction = setup.scanner.beam_rays(poses)
    scene = setup.scene
    ray, _, dist = setup.target.caster.first_hits((origin - scene.local_origin).astype(np.float32),
                                                  direction.astype(np.float32))
    true_range = np.full(len(points), np.nan)
    true_range[ray] = dist
    noise = points.classification == NOISE_CLASS
    met = np.isfinite(true_range)
    same = met & (np.abs(true_range - points.true_range_m) <= SAME_SURFACE_M)
    judged = ~noise & same
    truth = origin[judged] + true_range[judged, None] * direction[judged]
    error = points.xyz[judged] - truth
    skipped = {"noise": int(noise.sum()), "true_beam_meets_nothing": int((~noise & ~met).sum()),
               "other_surface": int((~noise & met & ~same).sum())}
    mine = points.select(judged)
    return TrueErrors(error[:, 2], np.hypot(error[:, 0], error[:, 1]), mine, predicted_error(setup, mine), skipped)


def predicted_error(setup, points: PointRecords) -> tuple[np.ndarray, np.ndarray]:
    """The mean (n, 3) and covariance (n, 3, 3) of the error the pass's model (``setup.tpu``) predicts for
    ``points``, from the navigation's estimated poses at their times, as the pass computed their THU and TVU."""
    estimate = setup.trajectory.poses(points.gps_time_s, estimated=True)
    _, direction = setup.scanner.beam_rays(estimate)
    attitude = np.c_[estimate.roll_rad, estimate.pitch_rad, estimate.yaw_rad]
    return setup.tpu.error_model(points.xyz - estimate.position, direction, attitude, points.channel, points.snr,
                                 points.saturated, points.return_number > 1,
                                 points.true_range_m.astype(np.float64) + points.range_error_m, points.incidence_deg)


def _fractions(errors: TrueErrors, mask: np.ndarray) -> dict:
    p = errors.points
    return {"points": int(mask.sum()),
            "vertical_within_tvu": _share(np.abs(errors.vertical_m[mask]) <= p.tvu_m[mask]),
            "horizontal_within_thu": _share(errors.horizontal_m[mask] <= p.thu_m[mask])}


def _share(inside: np.ndarray) -> float | None:
    return round(float(inside.mean()), 4) if inside.size else None


def calibration(errors: TrueErrors) -> dict:
    """The calibration of a pass: the shares of judged points whose |true vertical error| <= TVU and horizontal
    error <= THU, over all, per channel and per incidence band; the chart's observed coverages at
    :data:`CHART_LEVELS`; the judged and skipped counts."""
    p = errors.points
    every = np.ones(len(p), bool)
    channels = {f"ch{c}": _fractions(errors, p.channel == c) for c in np.unique(p.channel)}
    lo, hi = np.array(INCIDENCE_BANDS_DEG[:-1]), np.array(INCIDENCE_BANDS_DEG[1:])
    bands = {f"{a:g}-{b:g}": _fractions(errors, (p.incidence_deg >= a) & (p.incidence_deg < b)) for a, b in zip(lo, hi)}
    return {**_fractions(errors, every), "per_channel": channels, "per_incidence_deg": bands,
            "chart": coverage_curve(errors), "skipped": errors.skipped,
            "true_vertical_error_m": _quantiles(errors.vertical_m), "tvu_m": _quantiles(p.tvu_m),
            "true_horizontal_error_m": _quantiles(errors.horizontal_m), "thu_m": _quantiles(p.thu_m)}


def _quantiles(values: np.ndarray) -> dict:
    if values.size == 0:
        return {"median": None, "p95": None}
    return {"median": round(float(np.median(values)), 5), "p95": round(float(np.percentile(values, 95)), 5)}


def coverage_curve(errors: TrueErrors) -> dict:
    """Predicted against observed coverage: for each level q of :data:`CHART_LEVELS`, the share of points whose
    |vertical error| is within the q quantile of its predicted distribution (a normal of the predicted mean and
    variance, folded), and whose horizontal error is within the q radius of a circular bivariate normal of the
    predicted mean square (sqrt(-2 ln(1 - q)) sigma_h, as THU takes 2.45 for q = 0.95)."""
    mean, cov = errors.predicted
    sigma_h = thu_of(mean, cov) / K95_HORIZONTAL
    observed_z, observed_h = [], []
    for q in CHART_LEVELS:
        observed_z.append(_share(np.abs(errors.vertical_m) <= tvu_of(mean, cov, float(q))))
        observed_h.append(_share(errors.horizontal_m <= np.sqrt(-2.0 * np.log(1.0 - q)) * sigma_h))
    return {"levels": CHART_LEVELS.tolist(), "vertical": observed_z, "horizontal": observed_h}
