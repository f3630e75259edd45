"""The uncertainty checked against the truth: how many points' true errors lie within their THU and TVU.

The pass knows where each point truly belongs: the true beam (the vehicle's true pose, the pulse's scan angle)
meets the truth mesh at the true point P. The point's true error is X - P, X the point as the instrument and its
navigation place it, so it holds the ranging error and the navigation's pose error together, as the TPU predicts
them. Points judged: every return the scene's surfaces explain (not noise) whose true beam's first surface is the
surface ranged (its range along the true beam within :data:`SAME_SURFACE_M` of the truth along the point's own line
of sight; another surface there is a return behind an edge, whose true point the first hit is not).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scanner_sim.survey.point_records import PointRecords
from scanner_sim.survey.uncertainty import CONFIDENCE, K95_HORIZONTAL, thu_of, tvu_of
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


#: [m] Bin of the streaming histograms of THU, TVU and the true errors (their medians and 95th percentiles), and the
#: largest value binned (larger ones count in the last bin).
HISTOGRAM_BIN_M = 0.001
HISTOGRAM_MAX_M = 20.0


class UncertaintySink:
    """A pass's uncertainty figures, chunk by chunk (the summary's ``uncertainty``): THU and TVU quantiles over every
    point, and the calibration of the judged points (:func:`true_errors`): the shares within THU and TVU over all,
    per channel and per incidence band, the predicted-against-observed coverage curve, the true errors' quantiles.
    Counts and histograms only, whatever the pass's size. ``setup``: the pass's :class:`PassSetup`."""

    def __init__(self, setup):
        self.setup = setup
        bins = int(HISTOGRAM_MAX_M / HISTOGRAM_BIN_M) + 1
        self.histograms = {name: np.zeros(bins, np.int64) for name in
                           ("thu_m", "tvu_m", "true_vertical_error_m", "true_horizontal_error_m")}
        self.groups: dict[str, np.ndarray] = {}  # name -> [points, vertical within, horizontal within]
        self.chart = np.zeros((2, CHART_LEVELS.size), np.int64)
        self.judged = 0
        self.skipped = {"noise": 0, "true_beam_meets_nothing": 0, "other_surface": 0}

    def add(self, chunk) -> None:
        points = chunk.points
        self._count("thu_m", points.thu_m)
        self._count("tvu_m", points.tvu_m)
        self.add_errors(true_errors(self.setup, points))

    def add_errors(self, errors: TrueErrors) -> None:
        """Tally the judged points of ``errors``."""
        p = errors.points
        self.judged += len(p)
        for key, n in errors.skipped.items():
            self.skipped[key] += n
        self._count("true_vertical_error_m", np.abs(errors.vertical_m))
        self._count("true_horizontal_error_m", errors.horizontal_m)
        inside_z = np.abs(errors.vertical_m) <= p.tvu_m
        inside_h = errors.horizontal_m <= p.thu_m
        groups = {"all": np.ones(len(p), bool)}
        groups.update({f"ch{c}": p.channel == c for c in np.unique(p.channel)})
        for a, b in zip(INCIDENCE_BANDS_DEG[:-1], INCIDENCE_BANDS_DEG[1:]):
            groups[f"incidence {a:g}-{b:g}"] = (p.incidence_deg >= a) & (p.incidence_deg < b)
        for name, mask in groups.items():
            tally = np.array([mask.sum(), (inside_z & mask).sum(), (inside_h & mask).sum()], np.int64)
            self.groups[name] = self.groups.get(name, np.zeros(3, np.int64)) + tally
        mean, cov = errors.predicted
        sigma_h = thu_of(mean, cov) / K95_HORIZONTAL
        for i, q in enumerate(CHART_LEVELS):
            self.chart[0, i] += int((np.abs(errors.vertical_m) <= tvu_of(mean, cov, float(q))).sum())
            self.chart[1, i] += int((errors.horizontal_m <= math.sqrt(-2.0 * math.log(1.0 - q)) * sigma_h).sum())

    def _count(self, name: str, values: np.ndarray) -> None:
        v = values[np.isfinite(values)]
        hist = self.histograms[name]
        np.add.at(hist, np.minimum((v / HISTOGRAM_BIN_M).astype(np.int64), hist.size - 1), 1)

    def _quantiles(self, name: str) -> dict:
        hist = self.histograms[name]
        total = hist.sum()
        if total == 0:
            return {"median": None, "p95": None}
        cum = np.cumsum(hist)
        return {f"{k}": round((int(np.searchsorted(cum, q * total)) + 0.5) * HISTOGRAM_BIN_M, 4)
                for k, q in (("median", 0.5), ("p95", 0.95))}

    def figures(self) -> dict:
        """The summary's ``uncertainty`` (``docs/outputs.md``)."""

        def shares(tally):
            n, z, h = (int(v) for v in tally)
            return {"points": n, "vertical_within_tvu": round(z / n, 4) if n else None,
                    "horizontal_within_thu": round(h / n, 4) if n else None}

        every = self.groups.get("all", np.zeros(3, np.int64))
        return {
            "thu_m": self._quantiles("thu_m"), "tvu_m": self._quantiles("tvu_m"),
            "confidence": CONFIDENCE,
            "calibration": {
                **shares(every),
                "per_channel": {k: shares(v) for k, v in sorted(self.groups.items()) if k.startswith("ch")},
                "per_incidence_deg": {k.split()[1]: shares(v) for k, v in self.groups.items()
                                      if k.startswith("incidence")},
                "chart": {"levels": CHART_LEVELS.tolist(),
                          "vertical": [round(int(c) / self.judged, 4) if self.judged else None for c in self.chart[0]],
                          "horizontal": [round(int(c) / self.judged, 4) if self.judged else None
                                         for c in self.chart[1]]},
                "true_vertical_error_m": self._quantiles("true_vertical_error_m"),
                "true_horizontal_error_m": self._quantiles("true_horizontal_error_m"),
                "skipped": dict(self.skipped),
            },
            "ranging": self.setup.tpu.ranging.as_dict(),
            "navigation": self.setup.tpu.navigation.as_dict(),
        }
