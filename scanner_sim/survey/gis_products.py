"""The GIS products of a pass over a scene with a CRS (docs/outputs.md#gis-products), in its map coordinates.

- Rasters (Cloud-Optimized GeoTIFF) of the pass's coverage tally, one per entry of :data:`COVERAGE_RASTERS`:
  ``coverage.tif`` (each cell's state: covered or the cause of its gap), ``density.tif`` (valid points per
  m²) and ``s44_orders.tif`` (the strictest IHO S-44 order each cell meets), cut to the cells the pass
  reached. They are the grids the coverage already holds (no second count).
- ``gaps.geojson``: each gap (a 4-connected region of missed cells, the summary's ``holes``) as a polygon with the
  cause that failed most of the pulses aimed into it.
- ``trajectory.geojson`` (the true track, one LineString per leg) and ``lines.geojson`` (the planned legs).

A scene without a CRS gets none of them: its frame is local, and a GIS would place such files nowhere or
wrongly; its coverage stays in coverage_grid.npz and coverage_map.png.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

from scanner_sim.io.gis import write_cog, write_geojson
from scanner_sim.metrics.coverage import COVERED, GAP_CAUSES, NOT_REACHED, OTHER_SURFACE, CoverageAccumulator
from scanner_sim.metrics.s44 import NO_ORDER, ORDER_NAMES

#: Decimals of the GeoJSON files' coordinates [m]: millimetres, the LAS files' scale.
GEOJSON_DECIMALS = 3


class RasterBand(NamedTuple):
    """A plan grid as one raster band: ``values`` (ny, nx), row 0 the southern row as the coverage grid holds it;
    ``nodata``; its ``name`` and metadata ``tags`` (units, codes)."""

    values: np.ndarray
    nodata: float
    name: str
    tags: dict[str, str]


def coverage_state_band(coverage: CoverageAccumulator) -> RasterBand:
    """int16 cell states: -1 covered, k >= 0 a gap whose cause is GAP_CAUSES[k], nodata -2 (not reached)."""
    codes = {str(COVERED): "covered", **{str(k): cause for k, cause in enumerate(GAP_CAUSES)}}
    return RasterBand(coverage.cell_states(), NOT_REACHED, "coverage state",
                      {"codes": ", ".join(f"{k}={v}" for k, v in codes.items()), "not_reached": str(NOT_REACHED),
                       "min_points": str(coverage.settings.min_points),
                       "tolerance_m": f"{coverage.settings.tolerance_m:g}"})


def density_band(coverage: CoverageAccumulator) -> RasterBand:
    """float32 valid points per m² of each reached cell; nodata NaN (not reached)."""
    cell_area = coverage.grid.cell_m ** 2
    valid = coverage.cells.valid.reshape(coverage.grid.shape) / cell_area
    reached = coverage.cell_states() != NOT_REACHED
    return RasterBand(np.where(reached, valid, np.nan).astype(np.float32), np.nan, "valid points density",
                      {"units": "points/m2", "tolerance_m": f"{coverage.settings.tolerance_m:g}"})


def s44_order_band(coverage: CoverageAccumulator) -> RasterBand:
    """int16 strictest IHO S-44 order each reached cell complies with: k >= 0 is ORDER_NAMES[k] (0 the strictest),
    NO_ORDER (-1) none; nodata -2 (not reached). The same cells as s44_map.png; each order was judged on its own
    grid (tags ``order_cells_m``, ``min_soundings``) and is drawn on the plan cells."""
    orders = np.where(coverage.cell_states() == NOT_REACHED, NOT_REACHED, coverage.strictest_orders()).astype(np.int16)
    codes = {str(NO_ORDER): "none", **{str(k): name for k, name in enumerate(ORDER_NAMES)}}
    return RasterBand(orders, NOT_REACHED, "strictest IHO S-44 order (Ed. 6.0.0)",
                      {"codes": ", ".join(f"{k}={v}" for k, v in codes.items()), "not_reached": str(NOT_REACHED),
                       "order_cells_m": ", ".join(f"{sc.order.name}={sc.cell_m:g}" for sc in coverage.order_scales),
                       "min_soundings": ", ".join(f"{sc.order.name}={sc.rule.min_soundings}"
                                                  for sc in coverage.order_scales)})


#: The rasters a pass writes from its coverage: file name -> the band. Another grid of the coverage is one more line.
COVERAGE_RASTERS: dict[str, Callable[[CoverageAccumulator], RasterBand]] = {
    "coverage.tif": coverage_state_band,
    "density.tif": density_band,
    "s44_orders.tif": s44_order_band,
}

#: The vector files of a pass: gaps (with coverage), and always the track and the planned lines.
GAPS_FILE, TRAJECTORY_FILE, LINES_FILE = "gaps.geojson", "trajectory.geojson", "lines.geojson"


def gis_files(measures_coverage: bool) -> list[str]:
    """The names of the GIS products a pass over a scene with a CRS writes (its plan lists them)."""
    return [*COVERAGE_RASTERS, GAPS_FILE] * measures_coverage + [TRAJECTORY_FILE, LINES_FILE]


def reached_window(state: np.ndarray) -> tuple[slice, slice]:
    """(rows, columns) of the smallest block of a (ny, nx) state grid holding every reached cell (the whole grid
    when none is)."""
    rows, cols = np.flatnonzero((state != NOT_REACHED).any(axis=1)), np.flatnonzero((state != NOT_REACHED).any(axis=0))
    if rows.size == 0:
        return slice(None), slice(None)
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)


def write_coverage_rasters(out: Path, coverage: CoverageAccumulator, crs) -> None:
    """Every raster of :data:`COVERAGE_RASTERS` into ``out``, cut to the reached cells, georeferenced in ``crs``."""
    grid = coverage.grid
    rows, cols = reached_window(coverage.cell_states())
    x0 = grid.origin_m[0] + (cols.start or 0) * grid.cell_m
    y0 = grid.origin_m[1] + (rows.start or 0) * grid.cell_m
    for name, band_of in COVERAGE_RASTERS.items():
        band = band_of(coverage)
        write_cog(out / name, np.ascontiguousarray(band.values[rows, cols]), x0, y0, grid.cell_m, crs,
                  nodata=band.nodata, name=band.name, tags=band.tags)


def gap_features(coverage: CoverageAccumulator) -> list[dict]:
    """One GeoJSON Feature per gap: the polygon of its cells (rasterio's polygonising of the labelled grid, in map
    coordinates) and its properties: ``gap`` (1, 2, ...), ``cause`` (the GAP_CAUSES entry that failed most of the
    pulses aimed into it, ``other_surface`` when none failed), ``cause_share`` (that cause's part of the failed
    pulses), ``area_m2``, ``cells``, ``reaching_pulses`` and ``failed_pulses``."""
    from rasterio.features import shapes
    from rasterio.transform import Affine
    from scipy import ndimage
    from shapely.geometry import MultiPolygon, mapping, shape
    from shapely.geometry.polygon import orient

    grid = coverage.grid
    state = coverage.cell_states()
    labels, n = ndimage.label(state >= 0)  # 4-connected, as the summary counts holes
    if n == 0:
        return []
    flat = labels.ravel()
    failed = np.stack([np.bincount(flat, coverage.cells.failed[:, k], n + 1)[1:]
                       for k in range(coverage.cells.failed.shape[1])], axis=1)
    reaching = np.bincount(flat, coverage.cells.reaching, n + 1)[1:]
    cells = np.bincount(flat, minlength=n + 1)[1:]
    total = failed.sum(axis=1)
    cause = np.where(total > 0, failed.argmax(axis=1), OTHER_SURFACE)
    transform = Affine(grid.cell_m, 0.0, grid.origin_m[0], 0.0, grid.cell_m, grid.origin_m[1])  # row 0 south
    rings: dict[int, list] = {}
    for geometry, value in shapes(labels.astype(np.int32), mask=labels > 0, connectivity=4, transform=transform):
        rings.setdefault(int(value), []).append(orient(shape(geometry)))  # exterior counter-clockwise
    features = []
    for gap in range(1, n + 1):
        parts = rings[gap]
        polygon = parts[0] if len(parts) == 1 else MultiPolygon(parts)
        i = gap - 1
        features.append(_feature(mapping(polygon), {
            "gap": gap, "cause": GAP_CAUSES[cause[i]],
            "cause_share": float(failed[i, cause[i]] / total[i]) if total[i] else None,
            "area_m2": float(cells[i] * grid.cell_m ** 2), "cells": int(cells[i]),
            "reaching_pulses": int(reaching[i]), "failed_pulses": int(total[i])}))
    return features


def track_features(table: dict[str, np.ndarray]) -> list[dict]:
    """One Feature per leg of a trajectory table (:meth:`~scanner_sim.motion.trajectory.Trajectory.table`): the
    true positions (x, y, z) as a LineString (a Point when the platform does not move), with ``leg``, ``start_s``,
    ``stop_s`` and ``length_m`` (plan length)."""
    features = []
    for leg in np.unique(table["leg"]):
        rows = table["leg"] == leg
        xyz, t = table["position_m"][rows], table["time_s"][rows]
        length = float(np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1).sum())
        features.append(_feature(_line(xyz), {"leg": int(leg), "start_s": float(t[0]), "stop_s": float(t[-1]),
                                              "length_m": round(length, 3)}))
    return features


def line_features(waypoints_xy_m: np.ndarray) -> list[dict]:
    """One Feature per planned leg (leg k from waypoint k to k + 1, as the pass numbers them) with ``leg``,
    ``length_m`` and ``heading_deg`` (compass); a static platform's station as one Point."""
    points = np.asarray(waypoints_xy_m, float)
    if len(points) == 1:
        return [_feature(_line(points), {"leg": 1, "length_m": 0.0, "heading_deg": None})]
    features = []
    for k in range(len(points) - 1):
        dx, dy = points[k + 1] - points[k]
        features.append(_feature(_line(points[k:k + 2]), {
            "leg": k + 1, "length_m": round(math.hypot(dx, dy), 3),
            "heading_deg": round(math.degrees(math.atan2(dx, dy)) % 360.0, 3)}))
    return features


def _line(points: np.ndarray) -> dict:
    """A LineString through ``points`` (n, 2 or 3), or a Point when they are all one."""
    rounded = np.round(np.asarray(points, float), GEOJSON_DECIMALS)
    if len(np.unique(rounded, axis=0)) == 1:
        return {"type": "Point", "coordinates": rounded[0].tolist()}
    return {"type": "LineString", "coordinates": rounded.tolist()}


def _feature(geometry: dict, properties: dict) -> dict:
    return {"type": "Feature", "properties": properties, "geometry": geometry}


def write_gis_products(out: Path, crs, coverage: CoverageAccumulator | None, table: dict[str, np.ndarray],
                       waypoints_xy_m: np.ndarray) -> None:
    """The GIS products (:func:`gis_files`) of a pass into ``out``, in ``crs`` (a :class:`pyproj.CRS`):
    ``coverage`` its tally (None without a seabed), ``table`` its trajectory table, ``waypoints_xy_m`` (m, 2) the
    plan its legs join [m]."""
    if coverage is not None:
        write_coverage_rasters(out, coverage, crs)
        write_geojson(out / GAPS_FILE, "gaps", crs, gap_features(coverage))
    write_geojson(out / TRAJECTORY_FILE, "trajectory", crs, track_features(table))
    write_geojson(out / LINES_FILE, "lines", crs, line_features(waypoints_xy_m))
