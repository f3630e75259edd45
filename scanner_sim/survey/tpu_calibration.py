"""The uncertainty checked against the truth: how many points' true errors lie within their THU and TVU.

The pass knows where each point truly belongs: the true beam (the vehicle's true pose, the pulse's scan angle)
meets the truth mesh at the true point P. The point's true error is X - P, X the point as the instrument and its
navigation place it, so it holds the ranging error and the navigation's pose error together, as the TPU predicts
them. Points judged: every return the scene's surfaces explain (not noise) whose true beam's first surface is the
surface ranged (its range along the true beam within :data:`SAME_SURFACE_M` of the truth along the point's own line
of sight; another surface there is a return behind an edge, whose true point the first hit is not).

The surface reading is checked as a hydrographer checks a sounding: its height against the reference surface under
its own (x, y), here the seabed's height field (the truth mesh's own triangles) under X, against ``tvu_surface_m``.
Points judged so: the judged points on the seabed whose (x, y) lies over it (a rock or an object has no single
height under a point).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from muls.infra.normal_cdf import normal_cdf
from muls.infra.runtime import kernel
from scanner_sim.config.materials import NOISE_CLASS
from scanner_sim.records.point_records import PointRecords
from scanner_sim.survey.uncertainty import CONFIDENCE

#: [m] A true beam whose first hit lies further than this along it from the truth of the point's own line of sight
#: met another surface than the one ranged (an edge between them): the point is not judged.
SAME_SURFACE_M = 0.5
#: Incidence bands [deg] of the calibration table.
INCIDENCE_BANDS_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 90.0)
#: Nominal coverages of the calibration chart: for each, the share of points within that quantile of their
#: predicted error distribution.
CHART_LEVELS = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99])


class CheckedErrors(NamedTuple):
    """The judged points of a chunk (k of them) against their uncertainty: vertical error (k,) [m] signed, horizontal
    error (k,) [m], their TVU and THU (k,) [m], channel (k,), incidence (k,) [deg], and the coverage levels at which
    the errors lie on their predicted distributions (k,) (:func:`~scanner_sim.survey.uncertainty.coverage_levels`);
    ``skipped`` the points not judged, by reason; the surface reading (module doc) of the s judged points over the
    seabed: their height above the seabed under their (x, y) (s,) [m], their ``tvu_surface_m`` (s,) and incidence
    (s,) [deg]."""

    vertical_m: np.ndarray
    horizontal_m: np.ndarray
    tvu_m: np.ndarray
    thu_m: np.ndarray
    channel: np.ndarray
    incidence_deg: np.ndarray
    level_vertical: np.ndarray
    level_horizontal: np.ndarray
    skipped: dict
    surface_vertical_m: np.ndarray = np.zeros(0)
    tvu_surface_m: np.ndarray = np.zeros(0)
    surface_incidence_deg: np.ndarray = np.zeros(0)


def checked_errors(points: PointRecords, sight, mean: np.ndarray, var: np.ndarray, scene=None) -> CheckedErrors:
    """The true errors (module doc) of a chunk's ``points`` against their THU and TVU, from the chunk's lines of
    sight ``sight`` (:class:`~scanner_sim.survey.georeference.LinesOfSight`: the true beam axes and their first hits)
    and the points' predicted error, ``mean`` (n, m) and variances ``var`` (n, m)
    (:meth:`~scanner_sim.survey.uncertainty.TpuModel.predict`); ``scene`` (:class:`~scanner_sim.world.scene.Scene`)
    gives the seabed of the surface reading (None, or a scene without a height field: none)."""
    n = len(points)
    judged, error = np.empty(n, np.int64), np.empty((n, 2))
    level_z, horizontal_sigma = np.empty(n), np.empty(n)
    counts = np.zeros(4, np.int64)
    _judge(np.searchsorted(sight.slot, points.pulse_index), sight.axis_range_m, sight.true_origin_m,
           sight.true_direction, points.classification, points.true_range_m, points.xyz, mean, var, NOISE_CLASS,
           SAME_SURFACE_M, judged, error, level_z, horizontal_sigma, counts)
    k = counts[3]
    judged, vertical, horizontal = judged[:k], error[:k, 0], error[:k, 1]
    level_h = -np.expm1(-0.5 * (horizontal / horizontal_sigma[:k]) ** 2)  # as coverage_levels (numpy's expm1)
    skipped = {"noise": int(counts[0]), "true_beam_meets_nothing": int(counts[1]), "other_surface": int(counts[2])}
    on = judged[_over_seabed(points, judged, scene)]
    surface = (points.xyz[on, 2] - scene.surface_height(points.xyz[on, 0], points.xyz[on, 1]) if on.size
               else np.zeros(0))
    return CheckedErrors(vertical, horizontal, points.tvu_m[judged], points.thu_m[judged], points.channel[judged],
                         points.incidence_deg[judged], level_z[:k], level_h, skipped, surface, points.tvu_surface_m[on],
                         points.incidence_deg[on])


@kernel(nogil=True)
def _judge(row, axis_range, true_origin, true_direction, classification, true_range, xyz, mean, var, noise_class,
           same_surface_m, judged, error, level_z, horizontal_sigma, counts):
    """:func:`checked_errors`' judging, point by point: the judged points' indices into ``judged`` (k,), their
    true vertical and horizontal errors into ``error`` (k, 2) [m], the vertical coverage level and the horizontal
    sigma (at least 1 micrometre) of :func:`~scanner_sim.survey.uncertainty.coverage_levels` into ``level_z`` and
    ``horizontal_sigma`` (k,); ``counts`` (4,): noise, true beam meeting nothing, another surface, and k. Each figure
    in the operations numpy takes over the arrays (the normal CDF Cephes', :func:`~muls.infra.normal_cdf.normal_cdf`),
    the same bits. ``row`` (n,): each point's line of sight."""
    k = 0
    for i in range(row.shape[0]):
        r = row[i]
        tr = axis_range[r]
        if classification[i] == noise_class:
            counts[0] += 1
            continue
        if not np.isfinite(tr):
            counts[1] += 1
            continue
        if not abs(tr - np.float64(true_range[i])) <= same_surface_m:
            counts[2] += 1
            continue
        ex = xyz[i, 0] - (true_origin[r, 0] + tr * true_direction[r, 0])
        ey = xyz[i, 1] - (true_origin[r, 1] + tr * true_direction[r, 1])
        ez = xyz[i, 2] - (true_origin[r, 2] + tr * true_direction[r, 2])
        judged[k], error[k, 0], error[k, 1] = i, ez, math.hypot(ex, ey)
        mu, sigma = mean[i, 2], math.sqrt(var[i, 2])
        sigma = 1e-6 if sigma < 1e-6 else sigma  # np.maximum's: NaN stays NaN
        e = abs(ez)
        level_z[k] = normal_cdf((e - mu) / sigma) - normal_cdf((-e - mu) / sigma)
        h = math.sqrt(0.5 * (var[i, 0] + var[i, 1] + mean[i, 0] * mean[i, 0] + mean[i, 1] * mean[i, 1]))
        horizontal_sigma[k] = 1e-6 if h < 1e-6 else h
        k += 1
    counts[3] = k


def _over_seabed(points: PointRecords, judged: np.ndarray, scene) -> np.ndarray:
    """(k,) bool: which ``judged`` points (indices into ``points``) ranged the seabed's height field and lie over it."""
    if scene is None or scene.heightfield is None:
        return np.zeros(judged.size, bool)
    seabed = [o.object_id for o in scene.objects if o.kind == "seabed"]
    xyz = points.xyz[judged]
    return (np.isin(points.object_id[judged], seabed) & scene.heightfield.covers(xyz[:, 0], xyz[:, 1])
            & np.isfinite(points.tvu_surface_m[judged]))


#: [m] Bin of the streaming histograms of THU, TVU and the true errors (their medians and 95th percentiles), and the
#: largest value binned (larger ones count in the last bin).
HISTOGRAM_BIN_M = 0.001
HISTOGRAM_MAX_M = 20.0


def _at_or_under(levels: np.ndarray) -> np.ndarray:
    """(CHART_LEVELS.size,) int64: how many of ``levels`` (n,) are at or under each chart level (NaN: none), without
    sorting them: each level's first chart level at or over it, counted and summed up."""
    first = np.searchsorted(CHART_LEVELS, levels, side="left")
    return np.cumsum(np.bincount(first, minlength=CHART_LEVELS.size + 1)[:CHART_LEVELS.size])


class UncertaintySink:
    """A pass's uncertainty figures, chunk by chunk (the summary's ``uncertainty``): THU and TVU quantiles over every
    point, and the calibration of the judged points (:func:`checked_errors`): the shares within THU and TVU over all,
    per channel and per incidence band, the predicted-against-observed coverage curve, the true errors' quantiles.
    Counts and histograms only, whatever the pass's size: each chunk brings its points' checked errors
    (``Chunk.errors``). ``tpu``: the pass's TPU model (``PassSetup.tpu``, a
    :class:`~scanner_sim.survey.uncertainty.TpuModel`), whose ranging and navigation tables the figures state."""

    def __init__(self, tpu):
        self.tpu = tpu
        bins = int(HISTOGRAM_MAX_M / HISTOGRAM_BIN_M) + 1
        self.histograms = {name: np.zeros(bins, np.int64) for name in
                           ("thu_m", "tvu_m", "true_vertical_error_m", "true_horizontal_error_m")}
        self.groups: dict[str, np.ndarray] = {}  # name -> [points, vertical within, horizontal within,
        #                                                      points over the seabed, within the surface TVU]
        self.chart = np.zeros((2, CHART_LEVELS.size), np.int64)
        self.judged = 0
        self.skipped = {"noise": 0, "true_beam_meets_nothing": 0, "other_surface": 0}

    def add(self, chunk) -> None:
        points, errors = chunk.points, chunk.errors
        self._count("thu_m", points.thu_m)
        self._count("tvu_m", points.tvu_m)
        self.judged += errors.vertical_m.size
        for key, n in errors.skipped.items():
            self.skipped[key] += n
        self._count("true_vertical_error_m", np.abs(errors.vertical_m))
        self._count("true_horizontal_error_m", errors.horizontal_m)
        inside_z = np.abs(errors.vertical_m) <= errors.tvu_m
        inside_h = errors.horizontal_m <= errors.thu_m
        inside_s = np.abs(errors.surface_vertical_m) <= errors.tvu_surface_m
        groups = {"all": (np.ones(errors.vertical_m.size, bool), np.ones(inside_s.size, bool))}
        for a, b in zip(INCIDENCE_BANDS_DEG[:-1], INCIDENCE_BANDS_DEG[1:]):
            groups[f"incidence {a:g}-{b:g}"] = tuple((inc >= a) & (inc < b) for inc in
                                                     (errors.incidence_deg, errors.surface_incidence_deg))
        groups.update({f"ch{c}": (errors.channel == c, None) for c in np.unique(errors.channel)})
        for name, (mask, on) in groups.items():
            tally = np.array([mask.sum(), (inside_z & mask).sum(), (inside_h & mask).sum(),
                              0 if on is None else on.sum(), 0 if on is None else (inside_s & on).sum()], np.int64)
            self.groups[name] = self.groups.get(name, np.zeros(5, np.int64)) + tally
        self.chart[0] += _at_or_under(errors.level_vertical)
        self.chart[1] += _at_or_under(errors.level_horizontal)

    def _count(self, name: str, values: np.ndarray) -> None:
        v = values[np.isfinite(values)]
        hist = self.histograms[name]
        hist += np.bincount(np.minimum((v / HISTOGRAM_BIN_M).astype(np.int64), hist.size - 1), minlength=hist.size)

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

        def shares(tally, surface=True):
            n, z, h, m, s = (int(v) for v in tally)
            out = {"points": n, "vertical_within_tvu": round(z / n, 4) if n else None,
                   "horizontal_within_thu": round(h / n, 4) if n else None}
            if surface:
                out.update({"surface_points": m, "vertical_within_tvu_surface": round(s / m, 4) if m else None})
            return out

        every = self.groups.get("all", np.zeros(5, np.int64))
        return {
            "thu_m": self._quantiles("thu_m"), "tvu_m": self._quantiles("tvu_m"),
            "confidence": CONFIDENCE,
            "calibration": {
                **shares(every),
                "per_channel": {k: shares(v, surface=False) for k, v in sorted(self.groups.items()) if k.startswith("ch")},
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
            "ranging": self.tpu.ranging.as_dict(),
            "navigation": self.tpu.navigation.as_dict(),
        }


def single_pass_note(flown_s: float, navigation) -> str:
    """One line on what one pass's calibration can show, from the time it flew [s] and its navigation noise
    (:class:`scanner_sim.config.sections.NavigationNoiseConfig`): a drift correlated over tau is about one value
    over a pass shorter than tau, so such a pass's shares within THU and TVU are one draw of it (docs/uncertainty.md)."""
    n = navigation
    if not (n.position_sigma_m or n.depth_sigma_m or n.attitude_sigma_deg or n.heading_sigma_deg):
        return ("no navigation noise in this pass: its shares within THU and TVU judge the ranging and the footprint "
                "alone")
    tau, draws = n.correlation_time_s, flown_s / n.correlation_time_s
    how_many = "about one draw" if draws < 2 else f"about {draws:.0f} draws"
    return (f"one pass of {flown_s:.1f} s holds {how_many} of the navigation's drift (correlated over {tau:g} s): its "
            "shares within THU and TVU are those of its draws, not the TPU's calibration, which `scanner-sim "
            "uncertainty SCENE --seeds N` checks over N passes")
