"""The hand-off from the geometry to the physics: a chunk's hits become the MULS input of its pulses
(:class:`muls.optics.optical_model.PulseBatch`), one echo per hit at the range and weight :mod:`scanner_sim.rays.echoes` gives
it, the water column cut where the beam's energy stops, and the background light.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from muls.infra.errors import ParameterError
from muls.infra.runtime import kernel
from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.optics.radiometry import background_power_w
from scanner_sim.fidelity import COLUMN_CUTS
from scanner_sim.rays.echoes import ECHO_BIN_M, echo_energy
from scanner_sim.rays.hits import Hits


def pulse_batch(hits: Hits, slots: np.ndarray, model: OpticalModel, background_radiance: float = 0.0,
                column_cut: str = "pulse") -> PulseBatch:
    """The muls input of a chunk: one echo per sub-ray hit (return i is hit i), the column cut where the
    beam's energy stops, and the background light.

    Echo weight [1/sr] (Eq. 7 per sub-ray): the sub-ray's :func:`~scanner_sim.rays.echoes.echo_energy` / pi. The
    column of the footprint is cut as ``column_cut`` says (:func:`column_cuts`: once per pulse at the
    energy-weighted mean hit range, or per sub-ray), and runs to the record's end for the share that misses.
    The background (Eqs. 8-10) of artificial light of spectral radiance ``background_radiance``
    [W/(m^2 sr nm)] sees the footprint's mean range and reflectance.
    """
    n = slots.shape[0]
    weight = echo_energy(hits.weight, hits.reflectance, np.cos(hits.incidence_rad), hits.receiver_weight) / np.pi
    cuts, shares = column_cuts(hits.pulse_index, hits.range_m, hits.weight, n, column_cut)
    background = np.zeros(n)
    if background_radiance > 0.0:
        hit_share = np.bincount(hits.pulse_index, weights=hits.weight, minlength=n)
        mean_range = np.bincount(hits.pulse_index, weights=hits.weight * hits.range_m, minlength=n)
        mean_range = np.divide(mean_range, hit_share, out=np.full(n, np.inf), where=hit_share > 0)
        rho = np.bincount(hits.pulse_index, weights=hits.weight * hits.reflectance, minlength=n)
        rho = np.divide(rho, hit_share, out=np.zeros(n), where=hit_share > 0)
        background = background_power_w(model.instrument, model.water, background_radiance, mean_range, rho)
    return PulseBatch(pulse_id=slots, return_pulse=hits.pulse_index, return_range_m=hits.echo_range_m,
                      return_weight_per_sr=weight, column_cut_m=cuts, column_cut_weight=np.clip(shares, 0.0, 1.0),
                      background_w=background)


@dataclass(frozen=True)
class Handoff:
    """The hand-off stage bound to its pass: a chunk's hits and pulse slots -> its muls input (:func:`pulse_batch`
    with the pass's instrument in its water, background radiance [W/(m^2 sr nm)] and column cut)."""

    model: OpticalModel
    background_radiance: float
    column_cut: str

    def __call__(self, hits: Hits, slots: np.ndarray) -> PulseBatch:
        return pulse_batch(hits, slots, self.model, self.background_radiance, self.column_cut)


def column_cuts(pulse_index: np.ndarray, range_m: np.ndarray, weight: np.ndarray, n_pulses: int, how: str = "pulse"
                ) -> tuple[np.ndarray, np.ndarray]:
    """Where each pulse's water column stops and the share of the beam stopping there: (cuts [m], shares), both
    (n_pulses, k), the last column the share that meets nothing (cut at inf).

    pulse_index, range_m, weight: (h,) each hit's pulse, range along its sub-ray [m] and share of the pulse energy.
    ``how`` is one of :data:`COLUMN_CUTS`: ``"pulse"`` puts every hit's share at their energy-weighted mean range,
    ``"subray"`` each at its own range (binned to :data:`~scanner_sim.rays.echoes.ECHO_BIN_M`), so a beam split
    between two surfaces lights the column to each.
    """
    if how not in COLUMN_CUTS:
        raise ParameterError(f"column_cut = {how!r}: must be one of {', '.join(map(repr, COLUMN_CUTS))}")
    hit_share = np.bincount(pulse_index, weights=weight, minlength=n_pulses)
    miss = 1.0 - hit_share
    if how == "pulse":
        mean_range = np.bincount(pulse_index, weights=weight * range_m, minlength=n_pulses)
        mean_range = np.divide(mean_range, hit_share, out=np.full(n_pulses, np.inf), where=hit_share > 0)
        cuts = np.stack([mean_range, np.full(n_pulses, np.inf)], axis=1)
        return cuts, np.clip(np.stack([hit_share, miss], axis=1), 0.0, 1.0)
    cuts, shares = _subray_cuts(np.asarray(pulse_index, np.int64), np.asarray(range_m, np.float64),
                                np.asarray(weight, np.float64), n_pulses, ECHO_BIN_M)
    shares[:, -1] = miss
    return cuts, np.clip(shares, 0.0, 1.0)


@kernel(nogil=True)
def _subray_cuts(pulse_index, range_m, weight, n_pulses, bin_m):
    """Per pulse, the hits grouped by range bin (rounded half to even), bins ascending: (cuts (n_pulses, k) [m],
    shares (n_pulses, k)), a group's cut the weighted mean range of its hits, its share their summed weight; the
    last column is left for the caller. Sums run in hit order, the order a stable sort would leave them in."""
    h = pulse_index.shape[0]
    start = np.zeros(n_pulses + 1, np.int64)
    for i in range(h):
        start[pulse_index[i] + 1] += 1
    for p in range(n_pulses):
        start[p + 1] += start[p]
    order = np.empty(h, np.int64)  # hits by pulse, in hit order within a pulse (a counting sort)
    fill = start[:-1].copy()
    for i in range(h):
        order[fill[pulse_index[i]]] = i
        fill[pulse_index[i]] += 1
    widest = 0
    for p in range(n_pulses):
        widest = max(widest, start[p + 1] - start[p])
    bins = np.empty(widest, np.int64)  # one pulse's distinct bins, ascending
    share = np.empty(widest)
    moment = np.empty(widest)
    cuts = np.full((n_pulses, widest + 1), np.inf)  # trimmed to the most groups a pulse has, plus one
    shares = np.zeros((n_pulses, widest + 1))
    k = 1
    for p in range(n_pulses):
        m = 0
        for j in range(start[p], start[p + 1]):
            i = order[j]
            b = np.int64(np.rint(range_m[i] / bin_m))
            g = 0
            while g < m and bins[g] < b:
                g += 1
            if g == m or bins[g] != b:  # a new bin: open its group at g
                for q in range(m, g, -1):
                    bins[q], share[q], moment[q] = bins[q - 1], share[q - 1], moment[q - 1]
                bins[g], share[g], moment[g] = b, 0.0, 0.0
                m += 1
            share[g] += weight[i]
            moment[g] += weight[i] * range_m[i]
        for g in range(m):
            cuts[p, g] = moment[g] / (share[g] if share[g] > 0.0 else 1.0)
            shares[p, g] = share[g]
        k = max(k, m + 1)
    return np.ascontiguousarray(cuts[:, :k]), np.ascontiguousarray(shares[:, :k])
