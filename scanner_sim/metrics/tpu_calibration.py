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
from scanner_sim.survey.uncertainty import K95_HORIZONTAL, K95_VERTICAL
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
    """Per judged point (k of them): vertical error (k,) [m] signed, horizontal error (k,) [m] >= 0, and the
    points themselves (their THU, TVU, channel and incidence); ``skipped`` the points not judged, by reason."""

    vertical_m: np.ndarray
    horizontal_m: np.ndarray
    points: PointRecords
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
    return TrueErrors(error[:, 2], np.hypot(error[:, 0], error[:, 1]), points.select(judged), skipped)


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
    |vertical error| is within the q quantile of their predicted normal error (sigma = TVU / 1.96), and whose
    horizontal error is within the q quantile of their predicted circular bivariate normal (sigma = THU / 2.45)."""
    from scipy.stats import norm

    p = errors.points
    sigma_z = p.tvu_m / K95_VERTICAL
    sigma_h = p.thu_m / K95_HORIZONTAL
    k_z = norm.ppf(0.5 + 0.5 * CHART_LEVELS)  # |N(0,1)| <= k with probability q
    k_h = np.sqrt(-2.0 * np.log(1.0 - CHART_LEVELS))  # Rayleigh radius holding q
    observed_z = (np.abs(errors.vertical_m)[None, :] <= k_z[:, None] * sigma_z[None, :]).mean(axis=1)
    observed_h = (errors.horizontal_m[None, :] <= k_h[:, None] * sigma_h[None, :]).mean(axis=1)
    return {"levels": CHART_LEVELS.tolist(), "vertical": np.round(observed_z, 4).tolist(),
            "horizontal": np.round(observed_h, 4).tolist()}
