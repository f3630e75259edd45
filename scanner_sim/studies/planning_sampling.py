"""Survey planning, steps 1 and 2 (:mod:`scanner_sim.studies.planning`, docs/planning.md): the survey area, the
sample lines placed over it and the scenes of their passes, and the across-track profile each pass measures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from muls.infra.errors import ParameterError
from scanner_sim.config import SceneConfig
from scanner_sim.metrics import s44
from scanner_sim.metrics.coverage import COVERED, GAP_CAUSES, CoverageSettings
from scanner_sim.runs.jobs import PassOutcome
from scanner_sim.studies.coverage_study import combination_config
from scanner_sim.survey.setup import PassOptions
from scanner_sim.survey.setup_cache import cached_scene

#: Across-track bins of the profiles [m]: the coverage grid's plan cell.
BIN_M = CoverageSettings().cell_m


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


def flown_config(config: SceneConfig, water: str, altitude_m: float, speed_m_s: float, platform: dict) -> SceneConfig:
    """The scene in ``water`` at ``altitude_m`` (gate following the altitude) and ``speed_m_s``, flying ``platform``."""
    flown = combination_config(config, water, altitude_m, config.instrument.preset)
    changes = {f"platform.{k}": v for k, v in platform.items()} | {"platform.speed_m_s": float(speed_m_s)}
    return flown.with_overrides(changes)


def sample_config(config, water, altitude_m, speed_m_s, line) -> SceneConfig:
    """One sample pass: a straight line (start, end) [m] in ``water`` at ``altitude_m`` and ``speed_m_s``."""
    return flown_config(config, water, altitude_m, speed_m_s,
                        {"mode": "waypoints", "lawnmower": None, "waypoints_m": [list(map(float, p)) for p in line]}
                        ).with_overrides({"output.las": False})


def check_reach(config, waters, altitudes, line) -> None:
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


def all_ran(outcomes: list[PassOutcome]) -> list[PassOutcome]:
    failed = [o for o in outcomes if o.status == "failed"]
    if failed:
        raise RuntimeError(f"{len(failed)} of {len(outcomes)} planning passes failed ({failed[0].job.name}: "
                           f"{failed[0].error}); the others are complete: run the plan again to redo only these")
    return outcomes


def pass_grid(folder: Path) -> dict:
    from scanner_sim.io.tables import read_coverage_grid_npz

    return read_coverage_grid_npz(folder / "coverage_grid.npz")


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
