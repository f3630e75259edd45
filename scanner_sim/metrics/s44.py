"""IHO S-44 survey orders: the Edition 6.0.0 (2020) table as data, and where a pass's soundings meet each order,
each order judged on a grid of its own scale.

Source of every number in :data:`ORDERS`: IHO S-44 Edition 6.0.0 (2020), *Standards for Hydrographic Surveys*,
Table 1 "Minimum Bathymetry Standards for Safety of Navigation Hydrographic Surveys" (THU, TVU a and b, feature
detection, bathymetric coverage), all uncertainties at 95 % confidence; the maximum allowable TVU is the formula
of its section 3.2.3, Maximum Allowable Vertical Uncertainty (below). The density default is the example of its
Annex D ("Sample Density"): at least five samples per grid node. docs/coverage.md tabulates them.

A sounding *meets* an order when its true vertical error is within the order's TVU at its depth and its true
horizontal error within the THU at its depth, and, when the pass predicts them, its own 95 % uncertainties
(``tvu_m``, ``thu_m``) are within those limits too. Each order is judged on square cells of its own size
(:func:`order_scales`): the cube it must detect where Table 1 gives one, its fixed THU where it gives none. A
cell of an order *complies* when at least 95 % of its soundings meet the order (the standard's 95 % confidence
read over the cell's soundings) and, for an order that must detect features, when it holds at least
``min_soundings`` of them (Annex D's density example, which it ties to the grid that depicts the features).
Orders 1b and 2 ask no feature detection, so no density: one sounding is enough for their cell to be judged.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from muls.infra.errors import ParameterError

#: Share of a cell's soundings that must meet an order (S-44's uncertainties are at 95 % confidence).
CONFIDENCE = 0.95  # assumption: 95 % of a cell's soundings (docs/assumptions.md)
#: Soundings a cell of an order that must detect features needs by default, on that order's own grid (S-44 Ed.
#: 6.0.0 Annex D, Sample Density: ">= five samples per node", on the grid that depicts the features).
DEFAULT_MIN_SOUNDINGS = 5  # assumption: S-44 Annex D's example (docs/assumptions.md)
#: Valid soundings on a feature for it to count as detected: the same five samples, over the feature taken as one
#: grid node (Annex D asks a grid cell no larger than the feature it must depict).
FEATURE_MIN_SOUNDINGS = 5  # assumption: one Annex D node on the feature (docs/assumptions.md)
SOURCE = ("IHO S-44 Edition 6.0.0 (2020), Standards for Hydrographic Surveys, Table 1 (Minimum Bathymetry "
          "Standards for Safety of Navigation Hydrographic Surveys); TVU_max(d) = sqrt(a^2 + (b d)^2), section 3.2.3 "
          "(Maximum Allowable Vertical Uncertainty)")


@dataclass(frozen=True)
class Order:
    """One S-44 order: TVU = sqrt(a² + (b·d)²) [m]; THU = thu_m + thu_depth_fraction·d [m] (95 %); feature_m:
    the cube edge it must detect (None: not specified); coverage_percent: the bathymetric coverage it asks."""

    name: str
    tvu_a_m: float
    tvu_b: float
    thu_m: float
    thu_depth_fraction: float
    feature_m: float | None
    coverage_percent: float

    def tvu_max_m(self, depth_m) -> np.ndarray:
        """Largest allowed vertical uncertainty [m] at ``depth_m`` (S-44 Ed. 6.0.0 section 3.2.3)."""
        d = np.asarray(depth_m, float)
        return np.sqrt(self.tvu_a_m**2 + (self.tvu_b * d) ** 2)

    def thu_max_m(self, depth_m) -> np.ndarray:
        """Largest allowed horizontal uncertainty [m] at ``depth_m``."""
        return self.thu_m + self.thu_depth_fraction * np.asarray(depth_m, float)

    def as_json(self) -> dict:
        out = asdict(self)
        del out["name"]
        return out


#: Table 1 of S-44 Ed. 6.0.0, strictest first. Order 1a's feature size holds to 40 m depth (10 % of the depth
#: beyond); every shipped scene is shallower.
ORDERS: tuple[Order, ...] = (
    Order("exclusive", 0.15, 0.0075, 1.0, 0.0, 0.5, 200.0),
    Order("special", 0.25, 0.0075, 2.0, 0.0, 1.0, 100.0),
    Order("1a", 0.5, 0.013, 5.0, 0.05, 2.0, 100.0),
    Order("1b", 0.5, 0.013, 5.0, 0.05, None, 5.0),
    Order("2", 1.0, 0.023, 20.0, 0.10, None, 5.0),
)
ORDER_NAMES = tuple(o.name for o in ORDERS)
#: Cell value of the strictest-order map where a cell meets none.
NO_ORDER = -1


def orders_table() -> dict:
    """The table as JSON: order name -> its figures (``coverage.json`` → ``s44_orders``)."""
    return {o.name: o.as_json() for o in ORDERS}


def soundings_meeting(depth_m, vertical_error_m, horizontal_error_m, tvu_m=None, thu_m=None) -> np.ndarray:
    """(len(ORDERS), n) bool: which orders each of n soundings meets.

    depth_m (n,): true depth below the surface [m]; vertical_error_m, horizontal_error_m (n,): the sounding's
    true errors [m] (NaN: unknown, meets none); tvu_m, thu_m (n,) or None: its predicted 95 % uncertainties [m]
    (NaN where the pass predicts none).
    """
    d = np.asarray(depth_m, float)
    dz = np.abs(np.asarray(vertical_error_m, float))
    dh = np.abs(np.asarray(horizontal_error_m, float))
    out = np.zeros((len(ORDERS), d.size), bool)
    with np.errstate(invalid="ignore"):
        for k, order in enumerate(ORDERS):
            tvu, thu = order.tvu_max_m(d), order.thu_max_m(d)
            ok = (dz <= tvu) & (dh <= thu)
            for predicted, limit in ((tvu_m, tvu), (thu_m, thu)):
                if predicted is not None:  # NaN: not predicted for this sounding, its true error decides
                    predicted = np.asarray(predicted, float)
                    ok &= np.isnan(predicted) | (predicted <= limit)
            out[k] = ok
    return out


@dataclass(frozen=True)
class ComplianceRule:
    """min_soundings: soundings a cell needs; confidence: share of them that must meet the order."""

    min_soundings: int = DEFAULT_MIN_SOUNDINGS
    confidence: float = CONFIDENCE

    def __post_init__(self):
        if not (isinstance(self.min_soundings, (int, np.integer)) and self.min_soundings >= 1):
            raise ParameterError(f"min_soundings = {self.min_soundings!r}: must be an integer >= 1")
        if not (isinstance(self.confidence, float) and 0.0 < self.confidence <= 1.0):
            raise ParameterError(f"confidence = {self.confidence!r}: must be a number in (0, 1]")

    def complies(self, soundings, meeting) -> np.ndarray:
        """(len(ORDERS), cells) bool from per-cell counts: soundings (cells,), meeting (len(ORDERS), cells)."""
        n = np.asarray(soundings)
        need = np.maximum(self.min_soundings, np.ceil(self.confidence * n - 1e-9))
        return (n >= self.min_soundings) & (np.asarray(meeting) >= need)


def strictest_order(complies: np.ndarray) -> np.ndarray:
    """(cells,) int16: index into ORDERS of the strictest order each cell complies with, or NO_ORDER."""
    c = np.asarray(complies, bool)
    first = np.argmax(c, axis=0).astype(np.int16)
    return np.where(c.any(axis=0), first, np.int16(NO_ORDER)).astype(np.int16)


@dataclass(frozen=True)
class OrderScale:
    """How one order is judged: on square cells of ``cell_m`` [m] under ``rule``; ``cell_basis`` says why that size."""

    order: Order
    cell_m: float
    rule: ComplianceRule
    cell_basis: str

    @property
    def rules(self) -> tuple[str, ...]:
        """The checks a cell of this order passes to comply, in words."""
        out = [f"at least {100 * self.rule.confidence:g} % of the cell's soundings within the order's TVU and THU "
               "(true errors and predicted 95 % uncertainties)"]
        if self.rule.min_soundings > 1:
            out.append(f"at least {self.rule.min_soundings} soundings in the cell (Annex D's sample density)")
        return tuple(out)

    def as_json(self) -> dict:
        return {"cell_m": self.cell_m, "min_soundings": self.rule.min_soundings, "confidence": self.rule.confidence,
                "cell_basis": self.cell_basis, "rules": list(self.rules)}


def order_scales(min_soundings: int = DEFAULT_MIN_SOUNDINGS) -> tuple[OrderScale, ...]:
    """Each order's grid and rule, as in :data:`ORDERS`: the cell is the feature the order must detect (Table 1),
    each cell needing ``min_soundings`` soundings; an order without feature detection (1b, 2) is judged on cells of
    its fixed THU, the scale to which it positions a sounding, with no density rule (one sounding suffices)."""
    out = []
    for order in ORDERS:
        # assumption: the feature's cell, else the fixed THU's (docs/assumptions.md, docs/coverage.md)
        if order.feature_m is not None:
            out.append(OrderScale(order, order.feature_m, ComplianceRule(min_soundings),
                                  f"the {order.feature_m:g} m cube the order must detect (Table 1)"))
        else:
            out.append(OrderScale(order, order.thu_m, ComplianceRule(1),
                                  f"the order's fixed THU of {order.thu_m:g} m; no feature detection, so no density"))
    return tuple(out)


def order_figures(complies: np.ndarray, area_mask: np.ndarray, cell_area_m2: float,
                  scales: tuple[OrderScale, ...]) -> dict:
    """Per order, its scale and the compliant cells within ``area_mask`` (cells,) bool of the plan grid whose cells
    are ``cell_area_m2``: ``compliant_area_m2`` and ``compliant_fraction`` of the masked area (None when empty)."""
    mask = np.asarray(area_mask, bool)
    total = int(mask.sum())
    out = {}
    for k, scale in enumerate(scales):
        n = int((complies[k] & mask).sum())
        out[scale.order.name] = {"cell_m": scale.cell_m, "min_soundings": scale.rule.min_soundings,
                                 "compliant_area_m2": n * cell_area_m2,
                                 "compliant_fraction": n / total if total else None}
    return out


class OrderTally:
    """Per order, on that order's own grid, the soundings of each cell and those meeting the order; streamed chunk
    by chunk. ``grids``: one plan grid per order (``index(xy)``, ``size``, ``shape``, ``origin_m``, ``cell_m``),
    all with the same origin and axes."""

    def __init__(self, grids, scales: tuple[OrderScale, ...]):
        self.grids, self.scales = tuple(grids), tuple(scales)
        sizes = [g.size for g in self.grids]
        self._offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        # int32 as coverage's BinTally: memory grows with the area reached. Each order's counts are a view of one
        # flat array, which the tally's kernel fills for every order in one pass.
        self._soundings, self._meeting = np.zeros(sum(sizes), np.int32), np.zeros(sum(sizes), np.int32)
        self.soundings = [self._soundings[o:o + n] for o, n in zip(self._offsets, sizes)]
        self.meeting = [self._meeting[o:o + n] for o, n in zip(self._offsets, sizes)]
        self._limits = np.array([[s.order.tvu_a_m ** 2, s.order.tvu_b, s.order.thu_m, s.order.thu_depth_fraction]
                                 for s in self.scales], np.float64).reshape(-1, 4)
        self._origin_m = np.array(self.grids[0].origin_m, np.float64) if self.grids else np.zeros(2)
        self._cell_m = np.array([g.cell_m for g in self.grids], np.float64)
        self._shapes = np.array([g.shape for g in self.grids], np.int64).reshape(-1, 2)

    def add(self, truth_xyz, measured_xyz, tvu_m=None, thu_m=None) -> None:
        """Soundings (n,) of a chunk: ``truth_xyz`` (n, 3) the true point of each [m] (z up, the surface at 0; NaN:
        none, counted nowhere), ``measured_xyz`` (n, 3) where the pass put it; its depth is the truth's, its true
        errors the two's vertical and horizontal offsets; ``tvu_m``, ``thu_m`` as in :func:`soundings_meeting`."""
        from scanner_sim.metrics.sounding_tally import tally_soundings  # numba: only where a pass tallies

        none = np.zeros(0)
        tally_soundings(np.ascontiguousarray(truth_xyz, np.float64), np.ascontiguousarray(measured_xyz, np.float64),
                        none if tvu_m is None else np.ascontiguousarray(tvu_m, np.float64),
                        none if thu_m is None else np.ascontiguousarray(thu_m, np.float64),
                        self._limits, self._origin_m, self._cell_m, self._shapes, self._offsets, self._soundings,
                        self._meeting)

    @classmethod
    def load_kernel(cls) -> None:
        """Compile the tally's kernel (or load it from the cache) through :meth:`add` on no soundings, so with the
        argument types a pass gives it: a pass does so before its clock starts, since the tally first runs in the
        pass's sinks (0.3 s of compiling on a fresh machine)."""
        cls((), ()).add(np.zeros((0, 3)), np.zeros((0, 3)))

    def complies(self, k: int) -> np.ndarray:
        """(grids[k].size,) bool: the cells of order k's own grid that comply with it."""
        return self.scales[k].rule.complies(self.soundings[k], self.meeting[k])

    def on_grid(self, grid) -> np.ndarray:
        """(len(ORDERS), grid.size) bool: the cells of a finer plan ``grid`` (same origin and axes) whose centre
        lies in a complying cell of each order, or of a stricter one: the orders' limits nest, so a cell meeting a
        stricter order's limits and density meets every looser order's."""
        ny, nx = grid.shape
        out = np.zeros((len(self.grids), ny * nx), bool)
        for k, coarse in enumerate(self.grids):
            row = _cells_along(grid.origin_m[1], grid.cell_m, ny, coarse.origin_m[1], coarse.cell_m, coarse.shape[0])
            col = _cells_along(grid.origin_m[0], grid.cell_m, nx, coarse.origin_m[0], coarse.cell_m, coarse.shape[1])
            flat = row[:, None] * coarse.shape[1] + col[None, :]
            valid = (row[:, None] >= 0) & (col[None, :] >= 0)
            out[k] = np.where(valid, self.complies(k)[np.where(valid, flat, 0)], False).ravel()
        return np.logical_or.accumulate(out, axis=0)


def _cells_along(fine_origin: float, fine_cell: float, n_fine: int, origin: float, cell: float, n: int) -> np.ndarray:
    """(n_fine,) int64: the coarse cell (of n from ``origin``, ``cell`` wide) holding each fine cell's centre, -1
    outside."""
    centre = fine_origin + (np.arange(n_fine) + 0.5) * fine_cell
    i = np.floor((centre - origin) / cell).astype(np.int64)
    return np.where((i >= 0) & (i < n), i, -1)
