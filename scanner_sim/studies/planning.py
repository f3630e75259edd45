"""Survey planning (docs/planning.md): the plan of least survey time that meets an IHO S-44 order over a site, per
water type.

The method, in four steps:

1. *Sample passes.* Short straight lines along the survey's heading, placed over the survey area where the seabed
   has data across the whole swath, chosen nearest the depth quantiles of the area (the site's dominant depth
   range), one pass per water x altitude x speed x line, run as Dask tasks like a campaign.
2. *Profiles.* Each pass's per-order S-44 tally (coverage_grid.npz's strictest order per plan cell), binned by the
   cell centre's across-track offset from its line over the line's central stretch, pooled over the lines: per
   offset, the share of cells complying with the order, the share covered, and the gap causes.
3. *Candidates.* For each water x altitude x speed, the line spacings that span the area's width with one line
   fewer at each step (:func:`spacing_ladder`); a spacing's
   predicted compliance is the mean share over the offsets a cell can have from its lines (:func:`predicted_share`);
   the widest spacing whose prediction holds the required share is that altitude and speed's candidate, the next
   wider one is kept rejected. Survey time = (lines x line length + turns) / speed, a turn being the lawnmower's
   leg across to the next line (:func:`survey_time_s`).
4. *Confirmation.* Per water, the least-time candidate flown as a lawnmower over the area (or a centred sample of
   it when the whole would exceed ``max_confirm_pulses``) and judged on the area's cells with seabed data; a
   candidate confirmed short is replaced by the next one in time order.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from muls.infra.errors import ParameterError
from muls.presets import water_preset
from scanner_sim.config import SceneConfig
from scanner_sim.metrics import s44
from scanner_sim.metrics.coverage import COVERED, GAP_CAUSES, NOT_REACHED, CoverageSettings
from scanner_sim.metrics.feature_cubes import with_cubes
from scanner_sim.runs.cluster import maybe_client
from scanner_sim.runs.jobs import PassOutcome, run_jobs
from scanner_sim.runs.tasks import PassJob, cached_scene
from scanner_sim.studies.coverage_study import combination_config
from scanner_sim.survey.feature_placement import cube_positions
from scanner_sim.survey.setup import PassOptions

#: Share of the planned area on which the order must hold, by default.
DEFAULT_REQUIRED_SHARE = 0.95  # assumption: S-44's 95 % confidence read over the area (docs/assumptions.md)
#: Across-track bins of the profiles [m]: the coverage grid's plan cell.
BIN_M = CoverageSettings().cell_m
#: Altitudes and speeds tried by default, as multiples of the scene's own.
DEFAULT_ALTITUDE_FACTORS = (0.5, 1.0, 1.5)
DEFAULT_SPEED_FACTORS = (0.5, 1.0)
#: Cubes of the order's feature size placed in a confirmation, by default: 19 of 20 detected is the 95 % share.
DEFAULT_FEATURE_CUBES = 20
#: Fewest cubes a confirmation places.
MIN_FEATURE_CUBES = 5
#: Seed of the cubes' positions.
CUBE_SEED = 0
#: Confirmations tried per water (each a pass over the area) before the water is declared not achievable.
MAX_CONFIRMATIONS = 3


@dataclass(frozen=True)
class SiteArea:
    """The survey area: a rectangle of ``size_m`` (along the lines, across them) [m] around ``center_m`` [m], lines
    heading ``heading_deg`` (compass)."""

    center_m: tuple[float, float]
    size_m: tuple[float, float]
    heading_deg: float

    @property
    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit vectors (2,) along the lines and to their left."""
        yaw = math.radians(90.0 - self.heading_deg)
        return np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])

    def local(self, xy) -> tuple[np.ndarray, np.ndarray]:
        """(along, left) [m] of plan points (n, 2) from the area's centre."""
        along, left = self.axes
        d = np.asarray(xy, float) - np.asarray(self.center_m)
        return d @ along, d @ left

    def world(self, along_m, left_m) -> np.ndarray:
        """(n, 2) plan points of (along, left) offsets [m] from the centre."""
        along, left = self.axes
        return np.asarray(self.center_m) + np.outer(along_m, along) + np.outer(left_m, left)


@dataclass(frozen=True)
class Profile:
    """What the sample passes of one water x altitude x speed measured, pooled over the sample lines, per
    across-track bin (k,) centred at ``offset_m`` [m]: ``cells``, ``compliant`` (with the order), ``covered``,
    ``soundings`` (valid points); and
    ``gaps_m2`` per gap cause over the bins; ``by_order`` (len(s44.ORDERS), k) the compliant cells of every order.
    """

    water: str
    altitude_m: float
    speed_m_s: float
    offset_m: np.ndarray
    cells: np.ndarray
    compliant: np.ndarray
    covered: np.ndarray
    gaps_m2: dict
    by_order: np.ndarray
    soundings: np.ndarray

    def for_order(self, j: int) -> Profile:
        """This profile judged against order index ``j``."""
        return replace(self, compliant=self.by_order[j])

    def share(self, offsets_m) -> np.ndarray:
        """Compliant share of the cells at across-track offsets [m] (0 beyond the measured bins)."""
        i = np.round((np.abs(np.asarray(offsets_m, float)) + 0.5 * BIN_M) / BIN_M).astype(int) - 1
        by_distance = self._by_distance()
        return np.where(i < by_distance.size, by_distance[np.minimum(i, by_distance.size - 1)], 0.0)

    def soundings_at(self, offsets_m) -> np.ndarray:
        """Mean soundings per cell the line gives at across-track offsets [m] (0 beyond the measured bins)."""
        i = np.round((np.abs(np.asarray(offsets_m, float)) + 0.5 * BIN_M) / BIN_M).astype(int) - 1
        k = np.round((np.abs(self.offset_m) + 0.5 * BIN_M) / BIN_M).astype(int) - 1
        per_cell = np.bincount(k, self.soundings) / np.maximum(np.bincount(k, self.cells), 1)
        return np.where(i < per_cell.size, per_cell[np.minimum(i, per_cell.size - 1)], 0.0)

    def _by_distance(self) -> np.ndarray:
        """Compliant share per |offset| bin (left and right pooled), nearest the line first."""
        d = np.abs(self.offset_m)
        k = np.round((d + 0.5 * BIN_M) / BIN_M).astype(int) - 1
        cells = np.bincount(k, self.cells)
        compliant = np.bincount(k, self.compliant)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(cells > 0, compliant / cells, 0.0)

    def swath_m(self, required: float) -> float:
        """Width [m] of the band around the line whose every bin (left and right pooled) complies on at least
        ``required`` of its cells: the measured swath that meets the order."""
        ok = self._by_distance() >= required
        return 2.0 * BIN_M * (int(np.argmin(ok)) if not ok.all() else ok.size)

    def as_json(self) -> dict:
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.where(self.cells > 0, self.compliant / np.maximum(self.cells, 1), None)
        return {"water": self.water, "altitude_m": self.altitude_m, "speed_m_s": self.speed_m_s,
                "offset_m": self.offset_m.round(3).tolist(), "cells": self.cells.tolist(),
                "compliant_share": [None if s is None else round(float(s), 4) for s in share],
                "gaps_m2": self.gaps_m2}


def predicted_share(profile: Profile, spacing_m: float, coverage_factor: float) -> float:
    """Share of the planned area predicted to comply with lines ``spacing_m`` apart. A cell lies at offset d from its
    nearest line, d uniform over [-s/2, s/2], and at d + j s from the others; its soundings come from every line whose
    scan reaches it, as many from each as the profile's cells at that offset hold, and a line's soundings at an
    offset are taken to be good with that offset's compliant share. The cell's prediction is that share weighted by
    the soundings of each line (a far line's many poor soundings spoil a cell its near line alone would make comply).
    At 200 % coverage a cell a second line does not reach counts as failing."""
    d = (np.arange(max(1, round(spacing_m / BIN_M))) + 0.5) * BIN_M - 0.5 * spacing_m
    reach = np.abs(profile.offset_m).max()
    good, soundings = np.zeros(d.size), np.zeros(d.size)
    lines = np.zeros(d.size, int)
    for j in range(-int(reach // spacing_m) - 1, int(reach // spacing_m) + 2):
        offset = d + j * spacing_m
        n = profile.soundings_at(offset)
        good += n * profile.share(offset)
        soundings += n
        lines += n > 0
    share = np.where(soundings > 0, good / np.maximum(soundings, 1e-12), 0.0)
    if coverage_factor > 1.0:
        share = np.where(lines >= 2, share, 0.0)
    return float(share.mean())


def line_count(width_m: float, spacing_m: float) -> int:
    """Lines of a lawnmower ``width_m`` across at ``spacing_m`` (as :func:`lawnmower_waypoints` lays them)."""
    return int(math.floor(width_m / spacing_m + 1e-9)) + 1


def survey_time_s(area: SiteArea, spacing_m: float, speed_m_s: float) -> float:
    """Vehicle time [s] of the lawnmower: every line's length plus a turn between lines, the turn being the leg
    across to the next line (``spacing_m``) flown at the survey speed, as the pass flies it (corners rounded)."""
    n = line_count(area.size_m[1], spacing_m)
    return (n * area.size_m[0] + (n - 1) * spacing_m) / speed_m_s


@dataclass(frozen=True)
class Candidate:
    """One plan tried: altitude [m], speed [m/s], line spacing [m], its measured swath [m], predicted compliant share,
    survey time [s], line length [m] (all lines), and ``status`` (chosen, rejected) with ``reason``."""

    altitude_m: float
    speed_m_s: float
    spacing_m: float
    swath_m: float
    predicted_share: float
    survey_time_s: float
    line_length_m: float
    lines: int
    status: str = "rejected"
    reason: str = ""
    confirmed: dict | None = None

    def as_json(self) -> dict:
        return {"altitude_m": self.altitude_m, "speed_m_s": self.speed_m_s, "spacing_m": round(self.spacing_m, 4),
                "swath_m": self.swath_m, "predicted_share": round(self.predicted_share, 4),
                "survey_time_s": round(self.survey_time_s, 1), "survey_time_h": round(self.survey_time_s / 3600, 3),
                "line_length_m": round(self.line_length_m, 1), "lines": self.lines, "status": self.status,
                "reason": self.reason, "confirmed": self.confirmed}


@dataclass(frozen=True)
class WaterPlan:
    """The outcome for one water: ``chosen`` (None: not achievable), every candidate tried, and, when not achievable,
    the best order the sample passes predict it meets and the cause that limits it."""

    water: str
    chosen: Candidate | None
    candidates: tuple[Candidate, ...]
    confirmation: dict | None
    best_order: str | None = None
    limiting_cause: str | None = None

    @property
    def achievable(self) -> bool:
        return self.chosen is not None

    def as_json(self) -> dict:
        return {"water": self.water, "achievable": self.achievable,
                "chosen": None if self.chosen is None else self.chosen.as_json(),
                "confirmation": self.confirmation, "best_order": self.best_order,
                "limiting_cause": self.limiting_cause, "candidates": [c.as_json() for c in self.candidates]}


@dataclass(frozen=True)
class SurveyPlan:
    """The planner's answer (``plan.json``): per water a :class:`WaterPlan`, the site, the settings, the sample lines,
    the profiles measured and the passes run; ``config`` the scene planned, ``confirm_configs`` by water the scene
    of the chosen plan's confirmation pass."""

    scene: str
    order: str
    area: SiteArea
    required_share: float
    sample_lines: tuple[tuple[tuple[float, float], tuple[float, float]], ...]
    waters: tuple[WaterPlan, ...]
    profiles: tuple[Profile, ...]
    sample_passes: int
    confirmation_passes: int
    config: SceneConfig = field(compare=False)
    confirm_configs: dict = field(default_factory=dict, compare=False)

    def as_json(self) -> dict:
        order = next(o for o in s44.ORDERS if o.name == self.order)
        return {"scene": self.scene, "order": self.order, "order_figures": order.as_json(),
                "required_share": self.required_share,
                "area": {"center_m": list(self.area.center_m), "size_m": list(self.area.size_m),
                         "heading_deg": self.area.heading_deg},
                "sample_lines_m": [[list(a), list(b)] for a, b in self.sample_lines],
                "sample_passes": self.sample_passes, "confirmation_passes": self.confirmation_passes,
                "waters": [w.as_json() for w in self.waters], "profiles": [p.as_json() for p in self.profiles]}


def duration(seconds: float) -> str:
    """A survey time in words: minutes below two hours, else hours."""
    return f"{seconds / 60:.1f} min" if seconds < 7200 else f"{seconds / 3600:.2f} h"


def order_index(order: str) -> int:
    """Index of ``order`` in s44.ORDERS; a ParameterError naming the allowed ones otherwise."""
    if order not in s44.ORDER_NAMES:
        raise ParameterError(f"order = {order!r}: no such IHO S-44 order; must be one of {', '.join(s44.ORDER_NAMES)}")
    return s44.ORDER_NAMES.index(order)


def site_area(config: SceneConfig, scene) -> SiteArea:
    """The survey area: the scene's lawnmower rectangle (a raster's valid extent when it names none), else the
    seabed's plan extent with lines heading east."""
    from scanner_sim.world.raster import lawnmower_area

    lm = config.platform.lawnmower
    if config.platform.mode == "lawnmower" and lm is not None:
        center, size = lawnmower_area(lm, config.seabed)
        return SiteArea(tuple(map(float, center)), tuple(map(float, size)), float(lm.heading_deg))
    x0, x1, y0, y1 = scene.heightfield.extent_m
    return SiteArea((0.5 * (x0 + x1), 0.5 * (y0 + y1)), (x1 - x0, y1 - y0), 90.0)


def half_reach_m(config: SceneConfig, altitude_m: float) -> float:
    """Half width [m] of the band a sample line's profile covers: the scan's flat-seabed half swath at
    ``altitude_m``, plus one metre."""
    half_sector = min(0.5 * config.scanner.sector_deg, 80.0)
    return altitude_m * math.tan(math.radians(half_sector)) + 1.0


def choose_sample_lines(scene, area: SiteArea, length_m: float, half_band_m: float, count: int
                        ) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` sample lines (start, end (2,) [m]) along the area's heading, ``length_m`` long, each with seabed
    data over its whole band (``half_band_m`` either side): of a 7 x 7 grid of positions over the area, those
    whose mean depth is nearest the 1/(2n), 3/(2n)... quantiles of the area's depths (its dominant depth range)."""
    hf = scene.heightfield
    la, lw = area.size_m
    if la < length_m or lw < 2 * half_band_m:
        raise ParameterError(f"survey area {la:g} x {lw:g} m: too small for a {length_m:g} m sample line with its "
                             f"{2 * half_band_m:g} m band; give a larger area or lower altitudes_m")
    along_c = np.linspace(-0.5 * (la - length_m), 0.5 * (la - length_m), 7)
    left_c = np.linspace(-0.5 * lw + half_band_m, 0.5 * lw - half_band_m, 7)
    ga, gl = np.meshgrid(np.arange(-0.5 * length_m, 0.5 * length_m + 1e-9, 1.0),
                         np.arange(-half_band_m, half_band_m + 1e-9, 1.0))
    options = []
    for a in along_c:
        for off in left_c:
            pts = area.world((ga + a).ravel(), (gl + off).ravel())
            if hf.covers(pts[:, 0], pts[:, 1]).all():
                line = area.world(a + np.linspace(-0.5 * length_m, 0.5 * length_m, 21), np.full(21, off))
                options.append((a, off, float(-hf.height(line[:, 0], line[:, 1]).mean())))
    if not options:
        raise ParameterError(f"survey area: no {length_m:g} m sample line with {2 * half_band_m:g} m of seabed data "
                             "across it fits; give lower altitudes_m or a site with more valid seabed")
    sa, sl = np.meshgrid(np.linspace(-0.5 * la, 0.5 * la, 41), np.linspace(-0.5 * lw, 0.5 * lw, 41))
    pts = area.world(sa.ravel(), sl.ravel())
    inside = hf.covers(pts[:, 0], pts[:, 1])
    depths = -hf.height(pts[inside, 0], pts[inside, 1])
    chosen: list[int] = []
    for q in (np.arange(count) + 0.5) / count:
        target = float(np.quantile(depths, q))
        free = [i for i in range(len(options)) if i not in chosen] or list(range(len(options)))
        chosen.append(min(free, key=lambda i: abs(options[i][2] - target)))
    lines = []
    for i in dict.fromkeys(chosen):
        a, off, _ = options[i]
        ends = area.world([a - 0.5 * length_m, a + 0.5 * length_m], [off, off])
        lines.append((ends[0], ends[1]))
    return lines


def _at(config: SceneConfig, water: str, altitude_m: float, speed_m_s: float, platform: dict) -> SceneConfig:
    """The scene in ``water`` at ``altitude_m`` (gate following the altitude) and ``speed_m_s``, flying ``platform``."""
    flown = combination_config(config, water, altitude_m, config.instrument.preset)
    changes = {f"platform.{k}": v for k, v in platform.items()} | {"platform.speed_m_s": float(speed_m_s)}
    return flown.with_overrides(changes)


def sample_config(config, water, altitude_m, speed_m_s, line) -> SceneConfig:
    """One sample pass: a straight line (start, end) [m] in ``water`` at ``altitude_m`` and ``speed_m_s``."""
    return _at(config, water, altitude_m, speed_m_s,
               {"mode": "waypoints", "lawnmower": None, "waypoints_m": [list(map(float, p)) for p in line]}
               ).with_overrides({"output.las": False})


def plan_config(config, water, area: SiteArea, candidate: Candidate) -> SceneConfig:
    """The lawnmower of ``candidate`` over ``area`` in ``water``."""
    return _at(config, water, candidate.altitude_m, candidate.speed_m_s,
               {"mode": "lawnmower", "waypoints_m": None,
                "lawnmower": {"center_m": list(area.center_m), "size_m": list(area.size_m),
                              "heading_deg": area.heading_deg, "line_spacing_m": candidate.spacing_m}})


def confirm_area(area: SiteArea, candidate: Candidate, pulse_rate_hz: float, max_pulses: int) -> SiteArea:
    """The area the confirmation flies: the whole ``area`` when its pulses fit ``max_pulses``, else a centred sample:
    the lines cut shorter, then fewer lines (at least 3), until they fit."""
    def pulses(a: SiteArea) -> float:
        return survey_time_s(a, candidate.spacing_m, candidate.speed_m_s) * pulse_rate_hz

    if pulses(area) <= max_pulses:
        return area
    length, width = area.size_m
    n = line_count(width, candidate.spacing_m)
    short = max(20.0, length * max_pulses / pulses(area))
    while n > 3 and (n * short + (n - 1) * candidate.spacing_m) / candidate.speed_m_s * pulse_rate_hz > max_pulses:
        n -= 1
    return replace(area, size_m=(min(length, short), min(width, (n - 1) * candidate.spacing_m)))


def area_cells(grid: dict, area: SiteArea, spacing_m: float, scene) -> np.ndarray:
    """(ny, nx) bool: the coverage grid's cells (``grid``: coverage_grid.npz's arrays) whose centre lies in the
    planned area (the area's lines with half a spacing either side, within the area) and has seabed data."""
    ny, nx = grid["state"].shape
    cell, (x0, y0) = float(grid["cell_m"]), grid["origin_m"]
    gx, gy = np.meshgrid(x0 + (np.arange(nx) + 0.5) * cell, y0 + (np.arange(ny) + 0.5) * cell)
    along, left = area.local(np.c_[gx.ravel(), gy.ravel()])
    n = line_count(area.size_m[1], spacing_m)
    half_across = min(0.5 * area.size_m[1], 0.5 * (n - 1) * spacing_m + 0.5 * spacing_m)
    inside = (np.abs(along) <= 0.5 * area.size_m[0]) & (np.abs(left) <= half_across)
    return (inside & scene.heightfield.covers(gx.ravel(), gy.ravel())).reshape(ny, nx)


def judged(grid: dict, cells: np.ndarray, k: int) -> dict:
    """Compliance with order index ``k`` (or a stricter one) and coverage over ``cells``: shares and gap causes."""
    n = int(cells.sum())
    order = grid["s44_order"][cells]
    state = grid["state"][cells]
    area = float(grid["cell_m"]) ** 2
    gaps = np.bincount(state[state >= 0].astype(int), minlength=len(GAP_CAUSES)) * area
    return {"cells": n, "area_m2": n * area,
            "compliant_share": float(((order >= 0) & (order <= k)).sum() / n) if n else 0.0,
            "covered_share": float((state == COVERED).sum() / n) if n else 0.0,
            "not_reached_share": float((state == NOT_REACHED).sum() / n) if n else 0.0,
            "gaps_m2": {c: float(g) for c, g in zip(GAP_CAUSES, gaps) if g}}


def profile_of(grid: dict, line, half_band_m: float, trim_m: float) -> tuple[np.ndarray, ...]:
    """Per across-track bin of ``BIN_M`` within ``half_band_m`` of the sample ``line`` (start, end), over its stretch
    ``trim_m`` in from either end: cells, compliant (len(s44.ORDERS), bins) with each order (or a stricter one),
    covered; gap area by cause; valid points."""
    start, end = (np.asarray(p, float) for p in line)
    length = float(np.linalg.norm(end - start))
    along = (end - start) / length
    left = np.array([-along[1], along[0]])
    ny, nx = grid["state"].shape
    cell, (x0, y0) = float(grid["cell_m"]), grid["origin_m"]
    gx, gy = np.meshgrid(x0 + (np.arange(nx) + 0.5) * cell, y0 + (np.arange(ny) + 0.5) * cell)
    d = np.c_[gx.ravel(), gy.ravel()] - start
    a, o = d @ along, d @ left
    n_bins = int(round(half_band_m / BIN_M))
    b = np.floor(o / BIN_M).astype(int) + n_bins
    sel = (a >= trim_m) & (a <= length - trim_m) & (b >= 0) & (b < 2 * n_bins)
    order, state = grid["s44_order"].ravel()[sel], grid["state"].ravel()[sel]
    cells = np.bincount(b[sel], minlength=2 * n_bins)
    by_order = np.array([np.bincount(b[sel], (order >= 0) & (order <= j), minlength=2 * n_bins)
                         for j in range(len(s44.ORDERS))])
    covered = np.bincount(b[sel], state == COVERED, minlength=2 * n_bins)
    soundings = np.bincount(b[sel], grid["valid"].ravel()[sel], minlength=2 * n_bins)
    gaps = np.bincount(state[state >= 0].astype(int), minlength=len(GAP_CAUSES)) * cell ** 2
    return cells, by_order, covered, gaps, soundings


def plan_survey(scene, order: str = "special", waters=("clean_ocean", "coastal_ocean", "turbid_harbor"),
                altitudes_m=None, speeds_m_s=None, *, required_share: float = DEFAULT_REQUIRED_SHARE,
                sample_lines: int = 3, sample_length_m: float = 20.0, min_spacing_m: float = 0.5,
                max_confirm_pulses: int = 2_000_000, feature_cubes: int = DEFAULT_FEATURE_CUBES,
                out_dir: str | Path | None = None, client=None, workers: int | None = None,
                scheduler: str | None = None, redo: bool = False, render: bool = True,
                progress: bool = False) -> SurveyPlan:
    """The plan of least survey time meeting ``order`` over ``scene``'s site, per water (module docstring,
    docs/planning.md). ``scene``: a SceneConfig or a shipped scene's name or file; ``altitudes_m`` and
    ``speeds_m_s`` default to the scene's times :data:`DEFAULT_ALTITUDE_FACTORS` and :data:`DEFAULT_SPEED_FACTORS`.
    The passes (``sample-*``, ``confirm-*``) run into ``out_dir`` (a temporary folder when None) as Dask tasks on
    ``client``, ``scheduler`` or a local cluster of ``workers``; complete ones are kept on a re-run (unless ``redo``).
    ``feature_cubes``: cubes of the order's feature size placed in each confirmation pass, where the order asks
    feature detection (0: none, the density rule alone judges it). With ``out_dir``, the plan's files are written
    there too (:func:`~scanner_sim.studies.plan_files.write_plan_files`; ``render``: the chart and plan.html).
    Every input is checked before anything is written."""
    config = _scene_config(scene)
    k = order_index(order)
    factor = s44.ORDERS[k].coverage_percent / 100.0
    need = required_share * min(1.0, factor)
    waters, altitudes, speeds = _checked_inputs(config, waters, altitudes_m, speeds_m_s, required_share,
                                                 sample_lines, sample_length_m, min_spacing_m)
    built = cached_scene(config)
    area = site_area(config, built)
    _check_reach(config, waters, altitudes, area.world([-0.5 * sample_length_m, 0.5 * sample_length_m], [0.0, 0.0]))
    half_band = half_reach_m(config, max(altitudes))
    lines = choose_sample_lines(built, area, sample_length_m, half_band, sample_lines)
    trim = max(2.0, 2.0 * s44.order_scales()[k].cell_m)  # the line's ends: the scan's run-in and whole order cells
    combos = [(w, a, v) for w in waters for a in altitudes for v in speeds]
    jobs = [PassJob(f"sample-{w}-{a:g}m-{v:g}mps-{i + 1}", sample_config(config, w, a, v, line),
                    PassOptions(progress=False, render=False, write_scene=False))
            for w, a, v in combos for i, line in enumerate(lines)]
    from scanner_sim.io.run_dir import hold_output

    with _folder(out_dir) as out, hold_output(out), maybe_client(client, scheduler, workers, announce=progress) as dask:
        outcomes = _ran(run_jobs(jobs, out, dask, redo=redo, progress=progress))
        profiles = []
        for j, (w, a, v) in enumerate(combos):
            parts = [profile_of(_grid(out / o.job.name), line, half_band, trim)
                     for o, line in zip(outcomes[j * len(lines):(j + 1) * len(lines)], lines)]
            cells, by_order, covered, gaps, soundings = (np.sum(x, axis=0) for x in zip(*parts))
            offsets = (np.arange(cells.size) + 0.5) * BIN_M - half_band
            profiles.append(Profile(w, a, v, offsets, cells, by_order[k], covered,
                                    {c: float(g) for c, g in zip(GAP_CAUSES, gaps) if g}, by_order, soundings))
        ladders = {w: _candidates([p for p in profiles if p.water == w], area, factor, need, min_spacing_m)
                   for w in waters}
        # the pulses a second the scanner fires, as the first sample pass counted them over its line's time
        rate = outcomes[0].summary["pulses"] / (sample_length_m / combos[0][2])
        by_combo = {(p.water, p.altitude_m, p.speed_m_s): p for p in profiles}
        results, configs, n_confirm = _confirm(config, out, dask, area, ladders, by_combo, k, factor, need, built,
                                               max_confirm_pulses, progress, redo, rate, feature_cubes)
        plans = []
        for w in waters:
            chosen, confirmation = results[w]
            if chosen is None:
                best, cause = _best_and_cause([p for p in profiles if p.water == w], k, required_share,
                                              min_spacing_m, area)
                cause = _confirmed_cause(confirmation, need) or cause
                plans.append(WaterPlan(w, None, tuple(ladders[w]), confirmation, best, cause))
            else:
                plans.append(WaterPlan(w, chosen, tuple(ladders[w]), confirmation))
        plan = SurveyPlan(config.name, order, area, required_share,
                          tuple((tuple(map(float, a)), tuple(map(float, b))) for a, b in lines),
                          tuple(plans), tuple(profiles), len(jobs), n_confirm, config, configs)
        if out_dir is not None:
            from scanner_sim.studies.plan_files import write_plan_files

            write_plan_files(plan, out, render=render)
    return plan


def _scene_config(scene) -> SceneConfig:
    from scanner_sim.config import load_scene

    config = scene if isinstance(scene, SceneConfig) else load_scene(scene)
    if not config.has_seabed or config.seabed is None:
        raise ParameterError(f"scene '{config.name}': a plan is measured over the site's seabed; the scene has no "
                             "seabed section (a raster or a procedural seabed)")
    if config.platform.altitude_m is None:
        raise ParameterError(f"scene '{config.name}': platform.altitude_m is not set; the planner varies the altitude "
                             "above the seabed")
    return config


def _checked_inputs(config, waters, altitudes_m, speeds_m_s, required_share, sample_lines, sample_length_m,
                    min_spacing_m):
    waters = tuple(waters)
    if not waters or len(set(waters)) != len(waters):
        raise ParameterError(f"waters = {list(waters)}: give one or more distinct water presets")
    for w in waters:
        water_preset(w)
    altitudes = tuple(float(a) for a in (altitudes_m or [config.platform.altitude_m * f
                                                           for f in DEFAULT_ALTITUDE_FACTORS]))
    speeds = tuple(float(v) for v in (speeds_m_s or [config.platform.speed_m_s * f for f in DEFAULT_SPEED_FACTORS]))
    for name, values in (("altitudes_m", altitudes), ("speeds_m_s", speeds)):
        if len(set(values)) != len(values) or not all(math.isfinite(x) and x > 0 for x in values):
            raise ParameterError(f"{name} = {list(values)}: each must be a distinct finite number > 0")
    if not (isinstance(required_share, float) and 0.0 < required_share <= 1.0):
        raise ParameterError(f"required_share = {required_share!r}: must be a number in (0, 1]")
    if not (isinstance(sample_lines, int) and sample_lines >= 1):
        raise ParameterError(f"sample_lines = {sample_lines!r}: must be an integer >= 1")
    for name, value in (("sample_length_m", sample_length_m), ("min_spacing_m", min_spacing_m)):
        if not (math.isfinite(value) and value > 0):
            raise ParameterError(f"{name} = {value!r}: must be a finite number > 0 [m]")
    return waters, altitudes, speeds


def _check_reach(config, waters, altitudes, line) -> None:
    """Before anything is written: a probe of 400 pulses at the start of a sample line per water x altitude, in
    memory; one that gives no valid point reaches nothing, and the altitude is refused in that water."""
    from scanner_sim.survey.pipeline import simulate_pass

    for w in waters:
        for a in altitudes:
            probe = sample_config(config, w, a, config.platform.speed_m_s, line)
            result = simulate_pass(probe, PassOptions(max_pulses=400, progress=False, render=False, write_scene=False),
                                   scene=cached_scene(config))
            if not result.summary["coverage"]["covered_area_m2"]:
                raise ParameterError(f"altitudes_m: {a:g} m in water {w}: no pulse reaches the seabed with a valid "
                                     "sounding (a 400-pulse probe); give lower altitudes for this water")


class _folder:
    """``out_dir`` as a Path, created; a temporary folder, removed afterwards, when None."""

    def __init__(self, out_dir):
        self.out_dir, self._tmp = out_dir, None

    def __enter__(self) -> Path:
        if self.out_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="muls-plan-")
            return Path(self._tmp.name)
        Path(self.out_dir).mkdir(parents=True, exist_ok=True)
        return Path(self.out_dir)

    def __exit__(self, *exc):
        if self._tmp is not None:
            self._tmp.cleanup()


def _ran(outcomes: list[PassOutcome]) -> list[PassOutcome]:
    failed = [o for o in outcomes if o.status == "failed"]
    if failed:
        raise RuntimeError(f"{len(failed)} of {len(outcomes)} planning passes failed ({failed[0].job.name}: "
                           f"{failed[0].error}); the others are complete: run the plan again to redo only these")
    return outcomes


def _grid(folder: Path) -> dict:
    from scanner_sim.io.tables import read_coverage_grid_npz

    return read_coverage_grid_npz(folder / "coverage_grid.npz")


def spacing_ladder(width_m: float, min_spacing_m: float) -> np.ndarray:
    """Spacings tried, ascending [m]: width / (n - 1) for n lines spanning the area's width exactly,
    from the most lines with a spacing of at least ``min_spacing_m`` down to two: each step one line fewer, so each
    wider spacing is a cheaper plan."""
    most = max(2, int(math.floor(width_m / min_spacing_m + 1e-9)) + 1)
    return np.array([width_m / (n - 1) for n in range(most, 1, -1)])


def _candidates(profiles, area: SiteArea, factor: float, need: float, step: float) -> list[Candidate]:
    """Per altitude x speed, the widest spacing on the ladder (:func:`spacing_ladder`) whose prediction holds ``need``
    (or, if none does, the narrowest, rejected) and the next wider one, a line fewer (rejected), sorted by time."""
    out = []
    ladder = spacing_ladder(area.size_m[1], step)
    for p in profiles:
        swath = p.swath_m(need)
        shares = np.array([predicted_share(p, s, factor) for s in ladder])
        ok = shares >= need
        last = int(np.flatnonzero(ok)[-1]) if ok.any() else -1

        def cand(i: int, reason: str, status: str = "rejected", p=p, swath=swath, shares=shares) -> Candidate:
            s = float(ladder[i])
            n = line_count(area.size_m[1], s)
            return Candidate(p.altitude_m, p.speed_m_s, s, swath, float(shares[i]),
                             survey_time_s(area, s, p.speed_m_s), n * area.size_m[0], n, status, reason)

        if last < 0:
            best = int(np.argmax(shares))
            out.append(cand(best, f"predicted compliance at most {100 * shares[best]:.1f} % < {100 * need:g} % at any "
                                  f"spacing of at least {ladder[0]:.2f} m"))
            continue
        out.append(cand(last, "", "feasible"))
        if last + 1 < ladder.size:
            out.append(cand(last + 1, "next wider spacing (one line fewer): predicted compliance "
                                      f"{100 * shares[last + 1]:.1f} % < {100 * need:g} %"))
    return sorted(out, key=lambda c: (c.status != "feasible", c.survey_time_s, c.altitude_m, c.speed_m_s))


#: Steps of one line fewer tried below a confirmed plan, per water.
MAX_DESCENT = 6


def make_candidate(p: Profile, area: SiteArea, spacing_m: float, factor: float, need: float) -> Candidate:
    """The candidate of profile ``p``'s altitude and speed at ``spacing_m`` over ``area``, with its prediction."""
    n = line_count(area.size_m[1], spacing_m)
    return Candidate(p.altitude_m, p.speed_m_s, spacing_m, p.swath_m(need),
                     predicted_share(p, spacing_m, factor), survey_time_s(area, spacing_m, p.speed_m_s),
                     n * area.size_m[0], n)


def _confirm(config, out: Path, dask, area, ladders, profiles, k, factor, need, built, max_pulses, progress, redo,
             rate, cubes):
    """Per water: confirm the cheapest feasible candidate by a pass, on a shortfall the next (up to
    MAX_CONFIRMATIONS); once one is confirmed, confirm the plan of one line fewer at its altitude and speed, and
    while that meets the order too, take it and go one line fewer again (the prediction errs on the safe side), up to
    MAX_DESCENT. ``rate``: the pulses a second the passes fire [Hz]; ``cubes``: feature cubes placed in each
    confirmation of an order that asks feature detection (:func:`_cubes`). Returns per water (chosen, confirmation), the
    chosen plans' confirmation configs by water, and the passes run."""
    results: dict = {w: (None, None) for w in ladders}
    configs: dict = {}
    mode = {w: "search" for w in ladders}
    steps = {w: 0 for w in ladders}
    chosen_at: dict = {}
    runs = 0
    while True:
        round_jobs = {}
        for w, cands in ladders.items():
            if mode[w] == "search":
                feasible = [i for i, c in enumerate(cands) if c.status == "feasible"]
                if not feasible or steps[w] >= MAX_CONFIRMATIONS:
                    mode[w] = "done"
                    continue
                i = feasible[0]
            elif mode[w] == "descend":
                c = cands[chosen_at[w]]
                if c.lines <= 2 or steps[w] >= MAX_DESCENT:
                    mode[w] = "done"
                    continue
                spacing = area.size_m[1] / (c.lines - 2)
                same = [j for j, d in enumerate(cands) if (d.altitude_m, d.speed_m_s, d.lines)
                        == (c.altitude_m, c.speed_m_s, c.lines - 1)]
                if same:
                    i = same[0]
                else:
                    cands.append(make_candidate(profiles[w, c.altitude_m, c.speed_m_s], area, spacing, factor, need))
                    i = len(cands) - 1
            else:
                continue
            c = cands[i]
            flown = confirm_area(area, c, rate, max_pulses)
            cfg = plan_config(config, w, flown, c).with_overrides({"output.las": True})
            placed = _cubes(cfg, k, cubes)
            if placed:
                cfg = with_cubes(cfg, placed)
            round_jobs[w] = (i, flown, placed, PassJob(f"confirm-{w}-{c.altitude_m:g}m-{c.speed_m_s:g}mps-{c.spacing_m:g}m", cfg,
                                               PassOptions(progress=False, render=False, write_scene=False)))
        if not round_jobs:
            break
        outcomes = _ran(run_jobs([j for *_, j in round_jobs.values()], out, dask, redo=redo, progress=progress))
        runs += len(outcomes)
        for (w, (i, flown, placed, job)), outcome in zip(round_jobs.items(), outcomes):
            steps[w] += 1
            c = ladders[w][i]
            grid = _grid(out / job.name)
            reading = judged(grid, area_cells(grid, flown, c.spacing_m, built), k)
            detection = _detection(outcome.summary, placed)
            met = (reading["compliant_share"] >= need and reading["covered_share"] >= need
                   and (detection is None or detection["detected_share"] >= need))
            confirmation = {"pass": job.name, "whole_area": flown == area,
                            "area": {"center_m": list(flown.center_m), "size_m": list(flown.size_m)},
                            "pulses": outcome.summary["pulses"], "met": met, **reading, "features": detection}
            short = (f"compliance {100 * reading['compliant_share']:.1f} %, coverage "
                     f"{100 * reading['covered_share']:.1f} %"
                     + (f", features detected {detection['detected']} of {detection['placed']}" if detection else "")
                     + f" (need {100 * need:g} %)")
            if met:
                if w in chosen_at:  # the one before, a line more, met too: costlier
                    before = ladders[w][chosen_at[w]]
                    ladders[w][chosen_at[w]] = replace(before, status="rejected", reason=(
                        f"costlier than the chosen plan, one line fewer, which also met the order "
                        f"({duration(before.survey_time_s)} against {duration(c.survey_time_s)})"))
                how = ("confirmed a line fewer than a confirmed plan (the prediction erred safe)" if w in chosen_at
                       else "the least-time candidate predicted to meet the order, confirmed")
                ladders[w][i] = replace(c, status="chosen", reason=f"chosen: {how}; one line fewer confirmed short or "
                                        "not possible", confirmed=confirmation)
                results[w], configs[w], chosen_at[w] = (ladders[w][i], confirmation), job.config, i
                if mode[w] == "search":
                    mode[w], steps[w] = "descend", 0
            else:
                prefix = "one line fewer than the chosen plan: " if mode[w] == "descend" else ""
                ladders[w][i] = replace(c, status="rejected", reason=f"{prefix}confirmed short: {short}",
                                        confirmed=confirmation)
                if mode[w] == "descend":
                    mode[w] = "done"
                else:
                    results[w] = (None, confirmation)
    for w, cands in ladders.items():
        chosen = results[w][0]
        for i, c in enumerate(cands):
            if c.status == "feasible":
                cands[i] = replace(c, status="rejected", reason=(
                    f"costlier than the chosen plan ({duration(c.survey_time_s)} against "
                    f"{duration(chosen.survey_time_s)})" if chosen else f"not confirmed: {MAX_CONFIRMATIONS} "
                    "cheaper candidates were confirmed short first"))
        cands.sort(key=lambda c: (c.status != "chosen", c.survey_time_s, c.altitude_m, c.speed_m_s))
    return results, configs, runs


def _cubes(config: SceneConfig, k: int, count: int) -> list[dict]:
    """``count`` cubes of order k's feature size placed across the swath of ``config``'s pass (half as many while they
    do not fit apart and in view, down to MIN_FEATURE_CUBES), or none when the order asks no feature detection, or
    when not even that many fit (then the density rule alone judges detection)."""
    size = s44.ORDERS[k].feature_m
    while size is not None and count >= MIN_FEATURE_CUBES:
        try:
            return cube_positions(config, [size], count, CUBE_SEED, None, "feature_cubes")
        except ParameterError:  # no room for them apart and in view: half as many
            count //= 2
    return []


def _detection(summary: dict, placed: list[dict]) -> dict | None:
    """The cubes ``placed`` in a confirmation: placed, detected (>= s44.FEATURE_MIN_SOUNDINGS valid soundings on
    it), their share, and the not-detected ones' causes; None without cubes."""
    if not placed:
        return None
    names = {p["name"] for p in placed}
    mine = [o for o in summary["coverage"]["objects"] if o["name"] in names]
    detected = sum(o["detected"] for o in mine)
    causes: dict = {}
    for o in mine:
        if not o["detected"]:
            causes[o["gap_cause"]] = causes.get(o["gap_cause"], 0) + 1
    return {"size_m": placed[0]["size_m"], "placed": len(placed), "detected": detected,
            "detected_share": detected / len(placed), "missed_by_cause": causes}


def _confirmed_cause(confirmation: dict | None, need: float) -> str | None:
    """What failed the last confirmation of a water that meets no plan: its undetected cubes and their causes when
    detection fell short, else its gap cause with the most area; None without a confirmation (or a gap)."""
    if confirmation is None:
        return None
    f = confirmation.get("features")
    if f and f["detected_share"] < need:
        causes = ", ".join(f"{c} {n}" for c, n in sorted(f["missed_by_cause"].items(), key=lambda item: -item[1]))
        return (f"feature detection: {f['detected']} of {f['placed']} {f['size_m']:g} m cubes detected in the "
                f"confirmation {confirmation['pass']} (missed: {causes})")
    gaps = confirmation["gaps_m2"]
    if gaps:
        cause = max(gaps, key=gaps.get)
        return f"{cause} ({gaps[cause]:.0f} m² of the confirmation {confirmation['pass']}'s planned area)"
    return None


def _best_and_cause(profiles, k, required, step, area) -> tuple[str | None, str]:
    """The strictest order the sample passes predict some altitude and speed meets, and what limits the asked one:
    the gap cause with most area in the sample passes, or, without gaps, soundings that miss the order's limits."""
    best = None
    for j in range(k + 1, len(s44.ORDERS)):
        f = s44.ORDERS[j].coverage_percent / 100.0
        need = required * min(1.0, f)
        ladder = spacing_ladder(area.size_m[1], step)
        if any(predicted_share(p.for_order(j), s, f) >= need for p in profiles for s in ladder):
            best = s44.ORDERS[j].name
            break
    gaps: dict = {}
    for p in profiles:
        for c, g in p.gaps_m2.items():
            gaps[c] = gaps.get(c, 0.0) + g
    if gaps:
        cause = max(gaps, key=gaps.get)
        return best, f"{cause} ({gaps[cause]:.0f} m² of the sample passes' gaps, of {sum(gaps.values()):.0f} m²)"
    return best, "covered cells whose soundings miss the order's TVU/THU or sample density"

