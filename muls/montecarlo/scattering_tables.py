"""Multiple scattering in the model: tables the Monte Carlo reference builds once per water and receiver.

MULS's lidar equation counts single scattering and folds forward scattering into one attenuation coefficient;
the Monte Carlo reference (:mod:`muls.montecarlo`) traces the light instead, with the instrument's own beam,
aperture, offset and field of view. :class:`ScatteringTables` holds what one Monte Carlo run of flat 0.1 plates
at a grid of ranges says about a water and a receiver, in the form the model applies at the cost of an
interpolation:

- the echo's **two-way transmission** T(R) [-]: the Monte Carlo's echo energy over Eq. 7 with the finite-aperture
  overlap (:mod:`muls.instrument.overlap`) and no attenuation. It is the ``monte_carlo`` attenuation rule
  (:data:`muls.water.properties.ATTENUATION_MODELS`): k(R) = -ln T(R) / (2 R), interpolated linearly in ln R, the end values
  held outside the grid;
- the echo's **spread in time**: the share of its energy that comes back on the straight path (both legs
  unscattered, at the geometric delay), and the delays [s] of equal-energy quantile nodes of the rest after the
  geometric delay (:data:`SPREAD_NODES` of them, at the midpoints of equal steps of the cumulative energy);
- the **water column**: the Monte Carlo's impulse response of the column [1/s] (received energy over emitted
  energy per second at the aperture, all orders of scattering, before the receiver's optics), with the phase
  function's own backscatter b p(pi); the model rescales it to the water's beta_pi.

:func:`muls.montecarlo.tables.find_or_build_tables` finds the tables for a geometry and a water: in memory, shipped with
the package (:data:`SHIPPED_DIR`, the presets with the instruments' geometries), in the user cache, or, failing
those, by running the Monte Carlo (about half a minute for a turbid water) and caching the result.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..instrument.overlap import TransceiverGeometry
from ..water.properties import Water

#: Version of the tables' content: a change to how they are built makes a new key (old files are not read).
TABLE_FORMAT = 2
#: Quantile nodes of the scattered part of an echo (even: the model pairs them where the spread is narrow).
SPREAD_NODES = 8
#: Tables shipped with the package (the presets, with the instruments' geometries: python3 -m muls.validation.shipped_tables).
SHIPPED_DIR = Path(__file__).resolve().parents[1] / "data" / "scattering"


@dataclass(frozen=True)
class ScatteringTables:
    """The Monte Carlo's answer for one water and receiver (module doc). Arrays over the run's plate ranges.

    ranges_m (K,); attenuation_per_m (K,): k(R) = -ln T(R) / (2 R) [1/m], filled from the nearest defined range
    where the plate is not seen at all (the blind zone); transmission_rel_err (K,): the Monte Carlo's relative
    standard error of T; direct_share (K,) [-]; spread_s (K, SPREAD_NODES) [s]; column_step_s [s] and column
    (n,) [1/s]: the column's impulse response on bins [i step, (i + 1) step); phase_value_at_pi_per_sr: p(pi) of
    the Monte Carlo's phase function [1/sr]; source: how the tables were made (run, packets, seed)."""

    key: str
    ranges_m: np.ndarray
    attenuation_per_m_table: np.ndarray
    transmission_rel_err: np.ndarray
    direct_share: np.ndarray
    spread_s: np.ndarray
    column_step_s: float
    column: np.ndarray
    phase_value_at_pi_per_sr: float
    source: str

    def lidar_attenuation_per_m(self, range_m) -> np.ndarray:
        """k [1/m] at ``range_m`` [m] (any shape): interpolated linearly in ln R, held outside the grid."""
        r = np.maximum(np.asarray(range_m, float), 1e-6)
        return np.interp(np.log(r), np.log(self.ranges_m), self.attenuation_per_m_table)

    @property
    def seen(self) -> np.ndarray:
        """(K,) bool: the plate ranges whose echo the Monte Carlo saw; elsewhere (the blind zone and its edge, overlap
        under :data:`muls.montecarlo.tables.SEEN_OVERLAP`) the run measured nothing, and the builder leaves the
        transmission's error 0 (a seen plate's is > 0), the direct share 1 and the spread 0."""
        return (self.transmission_rel_err > 0.0) | (self.direct_share < 1.0) | np.any(self.spread_s > 0.0, axis=1)

    def seen_spread(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows :meth:`spread_at` interpolates over: (ranges (k,) [m], direct share (k,), node delays (k,
        SPREAD_NODES) [s]), the ranges the Monte Carlo saw (all of them where it saw none), C-contiguous float64."""
        seen = self.seen
        if not np.any(seen):
            seen = np.ones(self.ranges_m.shape, bool)
        return (np.ascontiguousarray(self.ranges_m[seen], np.float64),
                np.ascontiguousarray(self.direct_share[seen], np.float64),
                np.ascontiguousarray(self.spread_s[seen], np.float64))

    def spread_at(self, range_m) -> tuple[np.ndarray, np.ndarray]:
        """(direct share (n,), node delays (n, SPREAD_NODES) [s]) of echoes at ``range_m`` (n,) [m]: interpolated
        linearly in range over the ranges the Monte Carlo saw (:attr:`seen`), held outside them, as the attenuation
        is filled: an unseen plate's placeholder (no spread) is not a measurement to interpolate towards."""
        r = np.asarray(range_m, float)
        ranges, direct, spread = self.seen_spread()
        share = np.interp(r, ranges, direct)
        delays = np.stack([np.interp(r, ranges, spread[:, q]) for q in range(spread.shape[1])], axis=-1)
        return share, delays

    def column_response(self, t_s) -> np.ndarray:
        """The column's impulse response [1/s] at two-way times ``t_s`` [s] (any shape); 0 past the table."""
        t = np.asarray(t_s, float)
        centres = (np.arange(self.column.shape[0]) + 0.5) * self.column_step_s
        return np.interp(t, centres, self.column, left=self.column[0], right=0.0)

    def save(self, path: Path) -> None:
        """Write the tables to ``path`` (.npz), atomically."""
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.name}.", suffix=".npz", delete=False) as fh:
            np.savez_compressed(fh, key=self.key, ranges_m=self.ranges_m, attenuation_per_m=self.attenuation_per_m_table,
                     transmission_rel_err=self.transmission_rel_err, direct_share=self.direct_share,
                     spread_s=self.spread_s, column_step_s=self.column_step_s, column=self.column,
                     phase_value_at_pi_per_sr=self.phase_value_at_pi_per_sr, source=self.source)
            tmp = fh.name
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: Path) -> ScatteringTables:
        with np.load(path, allow_pickle=False) as z:
            return cls(str(z["key"]), z["ranges_m"], z["attenuation_per_m"], z["transmission_rel_err"],
                       z["direct_share"], z["spread_s"], float(z["column_step_s"]), z["column"],
                       float(z["phase_value_at_pi_per_sr"]), str(z["source"]))


def tables_key(geometry: TransceiverGeometry, water: Water, phase: str | None = None, packets: int | None = None
               ) -> str:
    """16 hex digits naming the tables of ``geometry`` and ``water``: every input the Monte Carlo run sees (the
    geometry's lengths and angles, a, b, the group index, the phase function's spec: ``phase``, by default the
    water's) and :data:`TABLE_FORMAT`; ``packets``: a run's packet count where it is not the standard one (None),
    so that a quicker, noisier table never stands in for a standard one."""
    inputs = {"format": TABLE_FORMAT, "beam_diameter_m": geometry.beam_diameter_m,
              "beam_divergence_full_rad": geometry.beam_divergence_full_rad,
              "receiver_diameter_m": round(geometry.receiver_diameter_m, 12), "fov_full_rad": geometry.fov_full_rad,
              "offset_m": geometry.offset_m, "a": water.absorption_per_m, "b": water.scattering_per_m,
              "group_index": water.group_index, "phase": water.phase_function if phase is None else phase}
    if packets is not None:
        inputs["packets"] = int(packets)
    return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:16]


def clear_water_tables(geometry: TransceiverGeometry, water: Water) -> ScatteringTables:
    """Tables of a water that absorbs but does not scatter: k = a, every echo on the straight path, no column."""
    ranges = np.array([0.1, 1000.0])
    return ScatteringTables(tables_key(geometry, water), ranges, np.full(2, water.absorption_per_m), np.zeros(2),
                            np.ones(2), np.zeros((2, SPREAD_NODES)), 1e-9, np.zeros(1), 0.0,
                            "no scattering: T = exp(-2 a R)")
