"""Mapping coverage against the truth meshes (docs/coverage.md).

One arithmetic (:class:`BinTally`) serves three kinds of bin: plan cells of the seabed, stretches of cable
length and whole objects. Per bin it counts

- *reaching* pulses: the nominal beam axis (true pose, the scan pattern alone, no water) first meets the
  truth meshes in the bin;
- *valid* points: points whose |range error| is within the tolerance, in the bin of the truth surface they
  measured: for plan cells, the cell of their pulse's nominal footprint (navigation error shifts the map, it
  does not uncover the seabed); for objects, the object whose echo made them (``object_id``); for cable
  stretches, the stretch nearest to those of them on the cable;
- *failed* pulses by cause: pulses reaching the bin that gave no valid point, by their dropout cause, or
  ``out_of_tolerance`` when they gave points but none within the tolerance.

A bin is *reached* when at least N pulses reach it, *covered* when it is reached and holds at least N valid
points, and *missed* otherwise. A missed bin takes the cause that failed most of its reaching pulses, or
``other_surface`` when none failed: the pulses aimed at it gave valid points from another surface (a cable or
mine whose footprint's echo came from the seabed around it). A plan cell cannot miss that way, since its
reaching pulses' valid points count in it. So every gap has a cause.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from muls.infra.errors import ParameterError
from muls.ranging.causes import DROPOUT_CAUSES
from scanner_sim.metrics import s44

#: Why a pulse reaching a bin gave no valid point (index = failure code).
FAILURE_CAUSES = DROPOUT_CAUSES + ("out_of_tolerance",)
#: Why a reached bin is missed: a failure cause, or ``other_surface`` (no reaching pulse failed).
GAP_CAUSES = FAILURE_CAUSES + ("other_surface",)
OTHER_SURFACE = len(FAILURE_CAUSES)
#: Why an object the valid points reach is not detected: fewer than s44.FEATURE_MIN_SOUNDINGS of them.
FEW_SOUNDINGS = "few_soundings"
#: Why an object no pulse reached is not detected: beams continued past another object's surface pass through its
#: box (SHADOWED: that object hides it), or none does (NOT_REACHED_OBJECT: the scan does not aim there).
SHADOWED, NOT_REACHED_OBJECT = "shadowed", "not_reached"
#: Bin states besides a gap cause index.
NOT_REACHED = -2
COVERED = -1
#: Per-pulse outcome of a valid point.
VALID = -1
#: Scene object kinds that are not targets of their own (the seabed and its rock field).
BACKGROUND_KINDS = ("seabed", "rocks")


@dataclass(frozen=True)
class CoverageSettings:
    """cell_m: plan cell and cable stretch [m]; min_points: N; tolerance_m: largest |range error| [m];
    order_min_soundings: soundings a cell of an S-44 order that must detect features needs to comply with it, on
    that order's own grid (:func:`scanner_sim.metrics.s44.order_scales`)."""

    cell_m: float = 0.25
    min_points: int = 1
    tolerance_m: float = 0.15  # IHO S-44 (6th ed., 2020) Exclusive Order, the constant part a of the TVU
    order_min_soundings: int = s44.DEFAULT_MIN_SOUNDINGS

    def __post_init__(self):
        if not (isinstance(self.cell_m, (int, float)) and math.isfinite(self.cell_m) and self.cell_m > 0):
            raise ParameterError(f"cell_m = {self.cell_m!r}: must be a finite number > 0 [m]")
        if not (isinstance(self.min_points, (int, np.integer)) and self.min_points >= 1):
            raise ParameterError(f"min_points = {self.min_points!r}: must be an integer >= 1")
        if not (isinstance(self.tolerance_m, (int, float)) and math.isfinite(self.tolerance_m)
                and self.tolerance_m > 0):
            raise ParameterError(f"tolerance_m = {self.tolerance_m!r}: must be a finite number > 0 [m]")
        s44.ComplianceRule(self.order_min_soundings)


#: Counts per plan cell (a cell sees at most a few thousand pulses a pass): the coverage and S-44 tallies' dtype.
COUNT_DTYPE = np.int32


class BinTally:
    """Reaching pulses, valid points and failures by cause over ``n_bins`` bins (streamed, chunk by chunk)."""

    def __init__(self, n_bins: int):
        # int32 counts (a cell sees at most a few thousand pulses a pass): the pages of these site-sized arrays become
        # resident as the survey first reaches their cells, so their width is the memory a long pass grows by.
        self.reaching = np.zeros(n_bins, COUNT_DTYPE)
        self.valid = np.zeros(n_bins, COUNT_DTYPE)
        self.failed = np.zeros((n_bins, len(FAILURE_CAUSES)), COUNT_DTYPE)

    @property
    def n_bins(self) -> int:
        return self.reaching.size

    def add(self, reaching_bin, outcome, valid_bin) -> None:
        """reaching_bin (n,) and outcome (n,) per pulse (bin -1: none; outcome VALID or a failure code);
        valid_bin (m,) per valid point (-1: outside every bin)."""
        reaching_bin, outcome, valid_bin = np.asarray(reaching_bin), np.asarray(outcome), np.asarray(valid_bin)
        inside = reaching_bin >= 0
        # Added where the chunk's pulses are, not as counts over every bin: a site's grid has millions of cells.
        # The count as the tallies' own dtype: np.add.at of a Python int casts on a slow path (35x slower here).
        one = COUNT_DTYPE(1)
        np.add.at(self.reaching, reaching_bin[inside], one)
        np.add.at(self.valid, valid_bin[valid_bin >= 0], one)
        fail = inside & (outcome >= 0)
        np.add.at(self.failed, (reaching_bin[fail], outcome[fail]), one)

    def states(self, min_points: int) -> np.ndarray:
        """(n_bins,) int16: NOT_REACHED, COVERED, or the GAP_CAUSES index of a missed bin."""
        state = np.full(self.n_bins, NOT_REACHED, np.int16)
        reached = self.reaching >= min_points
        covered = reached & (self.valid >= min_points)
        missed = reached & ~covered
        cause = np.where(self.failed.sum(axis=1) > 0, np.argmax(self.failed, axis=1), OTHER_SURFACE)
        state[covered] = COVERED
        state[missed] = cause[missed]
        return state


@dataclass(frozen=True)
class PlanGrid:
    """Square cells over a plan rectangle: ``origin_m`` (2,) lower-left corner [m], ``shape`` (ny, nx)."""

    origin_m: tuple[float, float]
    cell_m: float
    shape: tuple[int, int]

    @classmethod
    def over(cls, x_range_m, y_range_m, cell_m: float) -> PlanGrid:
        nx = max(1, math.ceil((x_range_m[1] - x_range_m[0]) / cell_m - 1e-9))
        ny = max(1, math.ceil((y_range_m[1] - y_range_m[0]) / cell_m - 1e-9))
        return cls((float(x_range_m[0]), float(y_range_m[0])), float(cell_m), (ny, nx))

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) [m]."""
        ny, nx = self.shape
        x0, y0 = self.origin_m
        return x0, x0 + nx * self.cell_m, y0, y0 + ny * self.cell_m

    def index(self, xy) -> np.ndarray:
        """(n,) int64 flat cell index (row y, column x) of plan points (n, >=2) [m]; -1 outside or NaN."""
        xy = np.atleast_2d(np.asarray(xy, float))
        ny, nx = self.shape
        with np.errstate(invalid="ignore"):
            fx = np.floor((xy[:, 0] - self.origin_m[0]) / self.cell_m)
            fy = np.floor((xy[:, 1] - self.origin_m[1]) / self.cell_m)
            inside = (fx >= 0) & (fx < nx) & (fy >= 0) & (fy < ny)
        flat = np.full(xy.shape[0], -1, np.int64)
        flat[inside] = fy[inside].astype(np.int64) * nx + fx[inside].astype(np.int64)
        return flat


class CableBins:
    """Stretches of ``bin_m`` along a centreline (n, 3) [m]: a point belongs to the stretch of its nearest
    centreline vertex (the centreline is sampled far finer than a stretch)."""

    def __init__(self, centreline: np.ndarray, bin_m: float):
        from scipy.spatial import cKDTree

        line = np.asarray(centreline, float)
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))]
        self.length_m = float(s[-1])
        self.n_bins = max(1, math.ceil(self.length_m / bin_m - 1e-9))
        self.stretch_length_m = np.minimum(bin_m, self.length_m - bin_m * np.arange(self.n_bins))
        self._vertex_bin = np.minimum((s / bin_m).astype(np.int64), self.n_bins - 1)
        self._tree = cKDTree(line)

    def index(self, xyz) -> np.ndarray:
        xyz = np.asarray(xyz, float).reshape(-1, 3)
        if xyz.shape[0] == 0:
            return np.zeros(0, np.int64)
        _, vertex = self._tree.query(xyz)
        return self._vertex_bin[vertex]


@dataclass(frozen=True)
class Footprint:
    """Where each pulse's nominal beam axis first meets the truth meshes: ``xyz`` (n, 3) world [m] (NaN
    without a hit), ``object_id`` (n,) int (-1 without a hit); ``direction`` (n, 3) unit, the axis's direction, or
    None (then no object is judged shadowed)."""

    xyz: np.ndarray
    object_id: np.ndarray
    direction: np.ndarray | None = None


def nominal_footprint(hits, direction: np.ndarray | None = None) -> Footprint:
    """Where each beam axis first meets the truth meshes, from the beam cast itself: sub-ray 0 of every beam
    pattern is the axis (:func:`scanner_sim.rays.beams.beam_pattern`), so its hit, if any, is the axis hit;
    ``hits``: the chunk's :class:`scanner_sim.rays.cast.Hits`; ``direction`` (n, 3): the axes' directions."""
    axis = hits.subray_index == 0
    pulse = hits.pulse_index[axis]
    xyz = np.full((hits.n_pulses, 3), np.nan)
    xyz[pulse] = hits.point[axis]
    object_id = np.full(hits.n_pulses, -1, np.int64)
    object_id[pulse] = hits.object_id[axis]
    return Footprint(xyz, object_id, direction)


def pulse_outcomes(slots: np.ndarray, points, dropouts, tolerance_m: float,
                   point_pulse: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pulse (n,) int: VALID or a FAILURE_CAUSES code; per point (m,) bool: |range error| <= tolerance.

    slots: the chunk's pulse slots, ascending; points / dropouts carry ``pulse_index`` in those slots;
    point_pulse (m,): each point's pulse (its index in ``slots``).
    """
    valid_point = np.abs(points.range_error_m) <= tolerance_m  # NaN (no truth along the line) is not valid
    outcome = np.full(slots.size, FAILURE_CAUSES.index("out_of_tolerance"), np.int64)
    outcome[point_pulse[valid_point]] = VALID
    outcome[np.searchsorted(slots, dropouts.pulse_index)] = dropouts.cause
    return outcome, valid_point


class CoverageAccumulator:
    """Coverage of one pass, accumulated chunk by chunk: plan cells over the seabed, cable stretches, objects."""

    def __init__(self, scene, settings: CoverageSettings = CoverageSettings(), planned=None):
        """planned: the pass's :class:`~scanner_sim.metrics.planned_swath.PlannedSwath`, or None."""
        if scene.heightfield is None:
            raise ParameterError("coverage: the scene has no seabed section; coverage is measured over the "
                                 "seabed's plan area")
        self.scene = scene
        self.settings = settings
        x0, x1, y0, y1 = scene.heightfield.extent_m
        self.grid = PlanGrid.over((x0, x1), (y0, y1), settings.cell_m)
        cx0, cx1, cy0, cy1 = self.grid.extent_m
        ny, nx = self.grid.shape
        gx, gy = np.meshgrid(np.linspace(cx0, cx1, nx + 1)[:-1] + 0.5 * settings.cell_m,
                             np.linspace(cy0, cy1, ny + 1)[:-1] + 0.5 * settings.cell_m)
        #: (ny, nx) bool: plan cells whose centre has no seabed (a raster's nodata, a mesh seabed's holes).
        self.no_seabed = ~scene.heightfield.covers(gx, gy)
        self.cells = BinTally(self.grid.size)
        self.objects = BinTally(len(scene.objects))
        self.cables = [(obj, CableBins(obj.centreline, settings.cell_m)) for obj in scene.objects
                       if obj.centreline is not None]
        self.cable_tallies = [BinTally(bins.n_bins) for _, bins in self.cables]
        #: Each S-44 order's grid and rule, and its tally on that grid (over the same origin as the plan cells).
        self.order_scales = s44.order_scales(settings.order_min_soundings)
        self._targets = np.array([o.object_id for o in scene.objects
                                  if o.kind not in BACKGROUND_KINDS and o.centreline is None], np.int64)
        self._target_boxes = np.array([_box(scene, scene.objects[i]) for i in self._targets]).reshape(-1, 2, 3)
        #: Per object, beams whose axis, continued past another object's surface, passes through its box.
        self.shadowing = np.zeros(len(scene.objects), COUNT_DTYPE)
        self.orders = s44.OrderTally([PlanGrid.over((x0, x1), (y0, y1), scale.cell_m) for scale in self.order_scales],
                                     self.order_scales)
        self.planned = planned
        self.slot_span = [None, None]  # first and last pulse slot seen

    def add(self, slots: np.ndarray, footprint: Footprint, points, dropouts) -> None:
        """One chunk: its slots (n,) ascending, the nominal footprint of those pulses, their points and dropouts."""
        point_pulse = np.searchsorted(slots, points.pulse_index)  # each point's pulse in the chunk
        outcome, valid = pulse_outcomes(slots, points, dropouts, self.settings.tolerance_m, point_pulse)
        xyz, obj = points.xyz[valid], points.object_id[valid]
        pulse_cell = self.grid.index(footprint.xyz)
        self.cells.add(pulse_cell, outcome, pulse_cell[point_pulse[valid]])
        self.objects.add(footprint.object_id, outcome, obj)
        self._add_shadowing(footprint)
        self._add_soundings(footprint, points, point_pulse)
        if slots.size:
            lo, hi = self.slot_span
            self.slot_span = [int(slots[0]) if lo is None else min(lo, int(slots[0])), max(hi or 0, int(slots[-1]))]
        for (cable, bins), tally in zip(self.cables, self.cable_tallies):
            on_cable = footprint.object_id == cable.object_id
            reaching = np.full(slots.size, -1, np.int64)
            reaching[on_cable] = bins.index(footprint.xyz[on_cable])
            mine = obj == cable.object_id
            valid_bin = np.full(obj.size, -1, np.int64)
            valid_bin[mine] = bins.index(xyz[mine])
            tally.add(reaching, outcome, valid_bin)

    def _add_shadowing(self, footprint: Footprint) -> None:
        """Count, per target object, the beams whose axis met another object (not the seabed) first and, continued
        past it, passes through the target's box: the beams that object hides it from."""
        if footprint.direction is None or not self._targets.size:
            return
        kinds = np.array([o.kind for o in self.scene.objects])
        hit = footprint.object_id
        blocked = (hit >= 0) & (kinds[np.maximum(hit, 0)] != "seabed")
        if not blocked.any():
            return
        start, direction, by = footprint.xyz[blocked], footprint.direction[blocked], hit[blocked]
        with np.errstate(divide="ignore", invalid="ignore"):
            inverse = 1.0 / direction  # (m, 3): inf along an axis the beam does not move on
            t0 = (self._target_boxes[None, :, 0, :] - start[:, None, :]) * inverse[:, None, :]
            t1 = (self._target_boxes[None, :, 1, :] - start[:, None, :]) * inverse[:, None, :]
            enter = np.nanmax(np.minimum(t0, t1), axis=2)
            leave = np.nanmin(np.maximum(t0, t1), axis=2)
        through = (leave >= np.maximum(enter, 0.0)) & (self._targets[None, :] != by[:, None])
        np.add.at(self.shadowing, self._targets[np.nonzero(through)[1]], COUNT_DTYPE(1))

    def _add_soundings(self, footprint: Footprint, points, point_pulse: np.ndarray) -> None:
        """Every point is a sounding where its pulse's nominal beam axis meets the truth (in each order's cell
        there); its true errors are its offset from that point (navigation, ranging and footprint errors together).
        point_pulse (m,): each point's pulse (row of ``footprint``)."""
        truth = footprint.xyz[point_pulse]
        self.orders.add(truth, points.xyz, getattr(points, "tvu_m", None), getattr(points, "thu_m", None))

    def order_compliance(self) -> np.ndarray:
        """(len(s44.ORDERS), cells) bool: the reached plan cells lying in a complying cell of each S-44 order's own
        grid (or of a stricter order's: the limits nest)."""
        reached = self.cell_states().ravel() != NOT_REACHED
        return self.orders.on_grid(self.grid) & reached

    def order_reading(self) -> dict:
        """Per S-44 order, how it is judged and what complies (JSON-ready): its ``cell_m``, ``min_soundings``,
        ``confidence``, ``cell_basis`` and ``rules`` (:func:`s44.order_scales`), its ``compliant_area_m2`` and
        ``compliant_fraction`` of the surveyed area (``area``: ``planned_swath`` or ``reached``)."""
        area_name, area = self._surveyed_area()
        figures = s44.order_figures(self.order_compliance(), area, self.settings.cell_m ** 2, self.order_scales)
        return {scale.order.name: {**scale.as_json(), **figures[scale.order.name], "area": area_name}
                for scale in self.order_scales}

    def _surveyed_area(self) -> tuple[str, np.ndarray]:
        """What the orders' shares are of: the planned swath's cells where the plan has one, else the reached."""
        planned = self.planned_cells()
        if planned is not None and planned.any():
            return "planned_swath", planned
        return "reached", self.cell_states().ravel() != NOT_REACHED

    def strictest_orders(self) -> np.ndarray:
        """(ny, nx) int16: the strictest S-44 order each cell complies with (index into s44.ORDERS), or s44.NO_ORDER."""
        return s44.strictest_order(self.order_compliance()).reshape(self.grid.shape)

    def planned_cells(self) -> np.ndarray | None:
        """(cells,) bool: cells in the swath the plan promised over the stretch flown, or None without a plan swath."""
        if self.planned is None or self.slot_span[0] is None:
            return None
        return self.planned.cell_mask(self.grid, *self.slot_span)

    def cell_states(self) -> np.ndarray:
        """(ny, nx) int16 plan-cell states: NOT_REACHED, COVERED or a GAP_CAUSES index."""
        return self.cells.states(self.settings.min_points).reshape(self.grid.shape)

    def figures(self) -> dict:
        """The coverage figures of the pass (JSON-ready): area, density, holes, gaps by cause, per object."""
        from scipy import ndimage

        s = self.settings
        cell_area = s.cell_m ** 2
        state = self.cell_states()
        reached = state != NOT_REACHED
        covered = state == COVERED
        missed = reached & ~covered
        reached_area = float(reached.sum() * cell_area)
        valid = self.cells.valid.reshape(self.grid.shape)
        holes, n_holes = ndimage.label(missed)  # 4-connected regions of missed cells
        hole_cells = np.bincount(holes.ravel(), minlength=n_holes + 1)[1:]
        return {
            "cell_m": s.cell_m,
            "min_points": s.min_points,
            "tolerance_m": s.tolerance_m,
            "reached_area_m2": reached_area,
            "covered_area_m2": float(covered.sum() * cell_area),
            "covered_fraction": float(covered.sum() / reached.sum()) if reached.any() else None,
            "valid_points_in_reach": int(valid[reached].sum()),
            "density_pts_per_m2": float(valid[reached].sum() / reached_area) if reached.any() else None,
            "median_density_covered_pts_per_m2": float(np.median(valid[covered]) / cell_area) if covered.any()
            else None,
            "holes": {"count": int(n_holes), "largest_m2": float(hole_cells.max() * cell_area) if n_holes else 0.0,
                      "total_m2": float(hole_cells.sum() * cell_area)},
            "gaps_m2": _by_cause(state[missed], cell_area),
            "no_seabed_data_m2": float(self.no_seabed.sum() * cell_area),
            "cables": [self._cable_figures(cable, bins, tally) for (cable, bins), tally in
                       zip(self.cables, self.cable_tallies)],
            "objects": self._object_figures(),
            **self._plan_figures(reached.ravel(), covered.ravel(), cell_area),
        }

    def _plan_figures(self, reached, covered, cell_area: float) -> dict:
        """The share of the planned swath reached and covered, and the S-44 orders' compliant share of the surveyed
        area: the planned swath when the plan has one, else the reached cells."""
        planned = self.planned_cells()
        swath = None
        if planned is not None and planned.any():
            n = planned.sum()
            swath = {"area_m2": float(n * cell_area), "reached_fraction": float((reached & planned).sum() / n),
                     "covered_fraction": float((covered & planned).sum() / n),
                     "never_reached_fraction": float((planned & ~reached).sum() / n)}
        reading = self.order_reading()
        return {"planned_swath": swath, "order_min_soundings": self.settings.order_min_soundings,
                "orders_area": "planned_swath" if swath is not None else "reached",
                "orders": {name: {key: value for key, value in r.items() if key not in ("area", "confidence", "cell_basis")}
                           for name, r in reading.items()}}

    def _cable_figures(self, cable, bins: CableBins, tally: BinTally) -> dict:
        state = tally.states(self.settings.min_points)
        reached, covered = state != NOT_REACHED, state == COVERED
        length = bins.stretch_length_m
        missed = reached & ~covered
        return {
            "name": cable.name,
            "length_m": bins.length_m,
            "reached_m": float(length[reached].sum()),
            "covered_m": float(length[covered].sum()),
            "covered_fraction": float(length[covered].sum() / length[reached].sum()) if reached.any() else None,
            "valid_points": int(tally.valid.sum()),
            "gaps_m": _by_cause(state[missed], length[missed]),
        }

    def _object_figures(self) -> list[dict]:
        state = self.objects.states(self.settings.min_points)
        out = []
        for obj in self.scene.objects:
            if obj.kind in BACKGROUND_KINDS or obj.centreline is not None:  # cables are counted by length
                continue
            i = obj.object_id
            detected = bool(self.objects.valid[i] >= s44.FEATURE_MIN_SOUNDINGS)
            if state[i] >= 0:
                cause = GAP_CAUSES[state[i]]
            elif state[i] == NOT_REACHED:
                cause = SHADOWED if self.shadowing[i] > 0 else NOT_REACHED_OBJECT
            else:
                cause = None if detected else FEW_SOUNDINGS
            out.append({
                "name": obj.name,
                "kind": obj.kind,
                "reaching_pulses": int(self.objects.reaching[i]),
                "shadowing_pulses": int(self.shadowing[i]),
                "valid_points": int(self.objects.valid[i]),
                "detected": detected,
                "gap_cause": cause,
            })
        return out


def _box(scene, obj) -> np.ndarray:
    """(2, 3) lower and upper corners [m] of an object's axis-aligned box, from its faces' vertices."""
    vertices = scene.vertices[np.unique(scene.faces[obj.face_start:obj.face_stop])]
    return np.array([vertices.min(axis=0), vertices.max(axis=0)])


def _by_cause(codes: np.ndarray, weight) -> dict:
    """Gap cause name -> summed weight (scalar or per code) of an array of GAP_CAUSES codes; every cause present."""
    codes = codes.astype(np.int64)
    sums = np.bincount(codes, weights=np.broadcast_to(np.asarray(weight, float), codes.shape),
                       minlength=len(GAP_CAUSES))
    return {cause: float(sums[i]) for i, cause in enumerate(GAP_CAUSES)}
