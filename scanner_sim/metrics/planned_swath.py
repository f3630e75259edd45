"""The swath a survey plan promises: the plan area the scan would sweep along the flown stretch of the planned
track, whatever the pulses actually reach (docs/coverage.md, *Share of the planned swath*).

Coverage over the cells some pulse reached reads 100 % when the vehicle flies so fast that its scan lines fall
apart and most of the seabed between them never gets a pulse. A planner's question is the share of the swath
the plan promised: the track flown, widened on either side by altitude · tan(half the scan sector) over a flat
seabed. Only a moving platform with cross-track scan lines (scanner mounted along the track) and a sector
centred on nadir that stays under the horizon has one; otherwise :func:`planned_swath` returns None.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Largest half sector [deg] whose swath edge a flat-seabed plan can draw (beyond, the edge runs off to the horizon).
MAX_HALF_SECTOR_DEG = 80.0  # assumption: flat-seabed edge (docs/assumptions.md)


@dataclass(frozen=True)
class PlannedSwath:
    """The planned track: arc length (k,) [m] and plan points (k, 2) [m], the platform speed [m/s], the half
    width [m] of the swath on either side, and the pulse rate [Hz] (pulse slot k fires at k / rate)."""

    path_s_m: np.ndarray
    path_xy_m: np.ndarray
    speed_m_s: float
    half_width_m: float
    pulse_rate_hz: float

    def polygon(self, t0_s: float, t1_s: float):
        """The swath (a shapely polygon) of the stretch flown between t0 and t1 [s]."""
        import shapely

        s0, s1 = (float(np.clip(t * self.speed_m_s, 0.0, self.path_s_m[-1])) for t in (t0_s, t1_s))
        inside = (self.path_s_m > s0) & (self.path_s_m < s1)
        xy = np.r_[[_at(self.path_s_m, self.path_xy_m, s0)], self.path_xy_m[inside], [_at(self.path_s_m, self.path_xy_m, s1)]]
        if s1 - s0 <= 1e-9:
            return shapely.Point(xy[0]).buffer(0.0)
        return shapely.LineString(xy).buffer(self.half_width_m, cap_style="flat")

    def cell_mask(self, grid, first_slot: int, last_slot: int) -> np.ndarray:
        """(grid.size,) bool: cells of ``grid`` (:class:`~scanner_sim.metrics.coverage.PlanGrid`) whose centre lies in
        the swath flown from pulse slot ``first_slot`` to ``last_slot``."""
        import shapely

        ny, nx = grid.shape
        x0, y0 = grid.origin_m
        cx = x0 + (np.arange(nx) + 0.5) * grid.cell_m
        cy = y0 + (np.arange(ny) + 0.5) * grid.cell_m
        gx, gy = np.meshgrid(cx, cy)
        swath = self.polygon(first_slot / self.pulse_rate_hz, last_slot / self.pulse_rate_hz)
        return shapely.contains_xy(swath, gx.ravel(), gy.ravel())


def _at(s, xy, where):
    return np.array([np.interp(where, s, xy[:, 0]), np.interp(where, s, xy[:, 1])])


def planned_swath(config, trajectory, pulse_rate_hz: float) -> PlannedSwath | None:
    """The planned swath of a pass of ``config`` (a SceneConfig) flying ``trajectory`` at ``pulse_rate_hz``, or
    None when the plan has no swath of its own (static platform or scanner, fore-aft profile, sector off nadir or
    past MAX_HALF_SECTOR_DEG, no seabed)."""
    sc, p = config.scanner, config.platform
    half_deg = sc.sector_deg / 2.0
    if (trajectory.static or sc.mode == "static" or sc.mounting != "along_track" or sc.center_deg != 0.0
            or half_deg > MAX_HALF_SECTOR_DEG or config.seabed is None):
        return None
    s, xyz = trajectory.path()
    height = p.altitude_m if p.altitude_m is not None else _height_at_depth(config, trajectory, xyz)
    if not height > 0:
        return None
    return PlannedSwath(np.asarray(s, float), np.asarray(xyz[:, :2], float), trajectory.speed_m_s,
                        height * math.tan(math.radians(half_deg)), float(pulse_rate_hz))


def _height_at_depth(config, trajectory, xyz: np.ndarray) -> float:
    """[m] How far above the seabed a vehicle at constant depth flies: below the procedural seabed's mean level
    (``seabed.depth_m``), or over a raster's, the median height over the seabed under the track ``xyz`` (k, 3)."""
    if hasattr(config.seabed, "depth_m"):
        return config.seabed.depth_m - config.platform.depth_m
    hf = trajectory.heightfield
    over = hf.covers(xyz[:, 0], xyz[:, 1])
    return float(np.median(xyz[over, 2] - hf.height(xyz[over, 0], xyz[over, 1]))) if over.any() else math.nan
