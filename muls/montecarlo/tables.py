"""The Monte Carlo run behind :class:`~muls.montecarlo.scattering_tables.ScatteringTables`: flat 0.1 plates at a grid of ranges
in one run (the farthest plate's scene gives the water column), tabulated as the model applies them
(:mod:`muls.montecarlo.scattering_tables`); and where a water's tables are found: in memory, shipped with the package, in the
user cache, or built by that run.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..instrument.overlap import TransceiverGeometry
from ..water.phase_family import phase_from_spec
from ..water.properties import Water
from .scattering_tables import SHIPPED_DIR, SPREAD_NODES, ScatteringTables, clear_water_tables, tables_key

#: Plate ranges of a table's run [m]: every 0.25 m through the near field, where the finite aperture starts to see
#: the plate and the echo spreads least, then wider steps; cut at :func:`farthest_range_m` for the water.
TABLE_RANGES_M = (0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.25, 2.5, 2.75, 3.0, 3.25, 3.5, 3.75, 4.0, 4.5, 5.0,
                  5.5, 6.0, 7.0, 8.0, 9.0, 10.0, 12.0, 14.0, 16.0, 18.0, 20.0, 22.5, 25.0, 30.0, 35.0, 40.0, 50.0, 60.0,
                  70.0, 80.0)
#: Beam packets of a table's run (the receiver traces a quarter as many): relative errors of 0.1-1 % on the echo
#: energies, a few % on the column's 0.25 ns bins within 100 times of its peak.
TABLE_PACKETS = 400_000
TABLE_SEED = 20231
#: Histogram bin of a table's run [s].
TABLE_TIME_STEP_S = 0.25e-9
#: The farthest plate lies where Eq. 6's two-way attenuation reaches e^-FARTHEST_ATTENUATION (no echo returns
#: from beyond), within [FARTHEST_MIN_M, FARTHEST_MAX_M].
FARTHEST_ATTENUATION = 40.0
FARTHEST_MIN_M = 10.0
FARTHEST_MAX_M = 80.0
#: Below this finite-aperture overlap the plate is hardly seen and T is taken from the nearest range that is.
SEEN_OVERLAP = 1e-3
#: The column's impulse response is averaged over +-COLUMN_SMOOTHING of its time (at least one bin) against the
#: Monte Carlo's noise in its late, faint bins; it is extended past the run by the exponential decay of its last
#: COLUMN_TAIL_FIT share, to COLUMN_EXTEND times the run's length.
COLUMN_SMOOTHING = 0.03
COLUMN_TAIL_FIT = 0.2
COLUMN_EXTEND = 2.0


class RunOptics(NamedTuple):
    """What a Monte Carlo run reads of an instrument: its name and its transceiver geometry."""

    name: str
    geometry: TransceiverGeometry


def farthest_range_m(water: Water) -> float:
    """The farthest plate of a table's run for ``water`` [m] (:data:`FARTHEST_ATTENUATION`)."""
    k = water.k_lidar_per_m
    far = FARTHEST_ATTENUATION / (2.0 * k) if k > 0.0 else FARTHEST_MAX_M
    return float(min(FARTHEST_MAX_M, max(FARTHEST_MIN_M, far)))


def _packets_key(packets: int) -> int | None:
    """The packet count a table's key records: None for the standard :data:`TABLE_PACKETS`."""
    return None if packets == TABLE_PACKETS else int(packets)


def build_tables(geometry: TransceiverGeometry, water: Water, packets: int = TABLE_PACKETS, seed: int = TABLE_SEED
                 ) -> ScatteringTables:
    """Run the Monte Carlo for ``water`` (with its phase function) and the receiver of ``geometry`` and tabulate it
    (module doc of :mod:`muls.montecarlo.scattering_tables`)."""
    from .run import TargetPlanes, run_monte_carlo  # the transport's kernels: only where tables are built

    far = farthest_range_m(water)
    ranges = tuple(r for r in TABLE_RANGES_M if r <= far)
    phase = phase_from_spec(water.phase_function)
    result = run_monte_carlo(RunOptics("tables", geometry), water, TargetPlanes(ranges, 0.1), phase=phase,
                             packets=packets, seed=seed, time_step_s=TABLE_TIME_STEP_S)
    t, dt, speed = result.time_s, result.time_step_s, result.speed_m_s
    r_ap = 0.5 * geometry.receiver_diameter_m
    area = math.pi * r_ap * r_ap
    overlap = geometry.finite_aperture_overlap(np.array(ranges))
    k_table, rel_err, direct_share = np.full(len(ranges), np.nan), np.zeros(len(ranges)), np.ones(len(ranges))
    spread = np.zeros((len(ranges), SPREAD_NODES))
    for i, r in enumerate(ranges):
        mean, var = result.target(i)
        energy = mean.sum()
        unattenuated = area * (0.1 / math.pi) * overlap[i] / (r * r)  # MULS Eq. 7, no attenuation, finite aperture
        if overlap[i] < SEEN_OVERLAP or energy <= 0.0:
            continue
        k_table[i] = -math.log(energy / unattenuated) / (2.0 * r)
        rel_err[i] = math.sqrt(var.sum()) / energy
        direct = result.target_direct[:, i].mean(axis=0)
        direct_share[i] = min(1.0, direct.sum() / energy)
        geometric_s = (r + math.hypot(r, geometry.offset_m)) / speed
        spread[i] = _quantile_nodes(np.clip(mean - direct, 0.0, None), t - 0.5 * dt, dt, geometric_s)
    k_table = _fill_unseen(k_table)
    far_scene = len(ranges) - 1
    column = _smoothed(result.column[:, far_scene].mean(axis=0)[t < 2.0 * ranges[-1] / speed]) / dt
    column = _extended(column, dt)
    source = (f"Monte Carlo (muls.montecarlo.run), phase function {water.phase_function}, flat 0.1 plates at "
              f"{ranges[0]:g}-{ranges[-1]:g} m, "
              f"{result.packets:,} beam packets, seed {seed}, {result.seconds:.0f} s")
    return ScatteringTables(tables_key(geometry, water, packets=_packets_key(packets)), np.array(ranges), k_table, rel_err,
                            direct_share, spread, dt, column, float(phase.value_at_pi_per_sr), source)


def _quantile_nodes(energy: np.ndarray, bin_start_s: np.ndarray, dt: float, geometric_s: float) -> np.ndarray:
    """Delays [s] after ``geometric_s`` of :data:`SPREAD_NODES` equal-energy nodes of the histogram ``energy`` on
    bins starting at ``bin_start_s``: the times where its cumulative energy reaches (q + 1/2) / SPREAD_NODES, the
    energy spread evenly within each bin; 0 when the histogram is empty."""
    total = energy.sum()
    if total <= 0.0:
        return np.zeros(SPREAD_NODES)
    edges = np.concatenate([bin_start_s, [bin_start_s[-1] + dt]])
    cumulative = np.concatenate([[0.0], np.cumsum(energy)]) / total
    levels = (np.arange(SPREAD_NODES) + 0.5) / SPREAD_NODES
    return np.maximum(np.interp(levels, cumulative, edges) - geometric_s, 0.0)


def _fill_unseen(k: np.ndarray) -> np.ndarray:
    """``k`` with its undefined entries (plates not seen) taken from the nearest defined one."""
    defined = np.flatnonzero(np.isfinite(k))
    if defined.size == 0:
        raise ValueError("the Monte Carlo saw no plate: no echo to tabulate")
    nearest = defined[np.abs(np.arange(k.size)[:, None] - defined[None, :]).argmin(axis=1)]
    return k[nearest]


def _smoothed(values: np.ndarray) -> np.ndarray:
    """``values`` averaged over a window of +-COLUMN_SMOOTHING of each bin's time (at least the bin itself)."""
    n = values.shape[0]
    half = np.maximum(0, np.round(COLUMN_SMOOTHING * (np.arange(n) + 0.5)).astype(np.int64))
    lo, hi = np.maximum(0, np.arange(n) - half), np.minimum(n, np.arange(n) + half + 1)
    cumulative = np.concatenate([[0.0], np.cumsum(values)])
    return (cumulative[hi] - cumulative[lo]) / (hi - lo)


def _extended(column: np.ndarray, dt: float) -> np.ndarray:
    """``column`` continued past its end by the exponential decay fitted to its last COLUMN_TAIL_FIT share."""
    n = column.shape[0]
    tail = np.arange(int((1.0 - COLUMN_TAIL_FIT) * n), n)
    positive = tail[column[tail] > 0.0]
    extra = int((COLUMN_EXTEND - 1.0) * n)
    if positive.size < 2 or extra == 0:
        return np.concatenate([column, np.zeros(extra)])
    slope, intercept = np.polyfit(positive * dt, np.log(column[positive]), 1)
    slope = min(slope, 0.0)
    more = np.exp(intercept + slope * (np.arange(n, n + extra) * dt))
    return np.concatenate([column, more])


_lock = threading.Lock()
_memory: dict[str, ScatteringTables] = {}


def user_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/muls-scanner/scattering`` (``~/.cache`` by default): tables built on this machine."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "muls-scanner" / "scattering"


#: The packet count of the tables found or built where a caller gives none (:func:`table_packets`).
_context_packets: ContextVar[int] = ContextVar("table_packets", default=TABLE_PACKETS)


@contextmanager
def table_packets(packets: int) -> Iterator[None]:
    """Within the block, the tables a study finds or builds without naming a packet count are runs of ``packets``
    beam packets (their own key): a band over a family of phase functions runs its members quicker than the
    standard tables, through studies that build their models themselves."""
    token = _context_packets.set(int(packets))
    try:
        yield
    finally:
        _context_packets.reset(token)


def find_tables(geometry: TransceiverGeometry, water: Water, packets: int | None = None) -> ScatteringTables | None:
    """The tables of ``geometry`` and ``water`` (run with ``packets``, by default :data:`TABLE_PACKETS` or the
    block's :func:`table_packets`) if they exist already (memory, shipped, user cache), else None."""
    packets = _context_packets.get() if packets is None else packets
    key = tables_key(geometry, water, packets=_packets_key(packets))
    with _lock:
        if key in _memory:
            return _memory[key]
    for folder in (SHIPPED_DIR, user_cache_dir()):
        path = folder / f"{key}.npz"
        if path.is_file():
            try:
                tables = ScatteringTables.load(path)
            except (OSError, ValueError, KeyError):  # a damaged cache file is built again
                continue
            if tables.key == key:
                with _lock:
                    _memory[key] = tables
                return tables
    return None


def find_or_build_tables(geometry: TransceiverGeometry, water: Water, packets: int | None = None) -> ScatteringTables:
    """The tables of ``geometry`` and ``water``: found (:func:`find_tables`), or built by the Monte Carlo with
    ``packets`` beam packets and kept in the user cache (one run per water, receiver, phase function and packet
    count; by default :data:`TABLE_PACKETS` or the block's :func:`table_packets`). A water that does not scatter
    needs no run: its tables are exp(-2 a R)."""
    packets = _context_packets.get() if packets is None else packets
    found = find_tables(geometry, water, packets)
    if found is not None:
        return found
    if water.scattering_per_m == 0.0:
        tables = clear_water_tables(geometry, water)
    else:
        tables = build_tables(geometry, water, packets)
        try:
            tables.save(user_cache_dir() / f"{tables.key}.npz")
        except OSError:  # an unwritable cache costs a run in the next process, nothing else
            pass
    with _lock:
        _memory[tables.key] = tables
    return tables
