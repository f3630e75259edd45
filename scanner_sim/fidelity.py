"""Fidelity levels: how faithfully a pass simulates each pulse, in one table.

A level fixes the geometry stage (sub-rays per pulse, shadow rays to the receiver), what the waveform stage
records, and how the water column is cut. A scene picks a level with ``survey.fidelity`` and may override
``survey.subrays`` and ``survey.shadow_rays`` (``SurveyConfig.level`` applies them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from muls.errors import ParameterError

#: Where the water column stops: ``"pulse"`` once per pulse, at the energy-weighted mean hit range for the share
#: of the beam that hits; ``"subray"`` where each sub-ray stops (hits within :data:`SUBRAY_CUT_BIN_M` share a cut).
COLUMN_CUTS = ("pulse", "subray")
#: [m] Sub-ray hit ranges closer than this share one column cut: under half the 0.11 m of range one 1 ns sample
#: spans, so a footprint at moderate incidence keeps one or two cuts (measured: no cost over the single cut on
#: cable_survey) while a footprint stretched over metres at grazing incidence is cut where its parts stop.
SUBRAY_CUT_BIN_M = 0.05


@dataclass(frozen=True)
class FidelityLevel:
    """One fidelity level.

    subrays: beam sub-rays per pulse (one of ``beams.SUBRAY_COUNTS``). shadow_rays: cast a visibility ray from
    each hit to the receiver aperture (parallax shadows); without them only the FOV cone is checked.
    record_mode: ``"windowed"`` (samples around the echoes) or ``"full"`` (every sample of every channel),
    ``muls.detection.RECORD_MODES``. column_cut: where the water column stops, one of :data:`COLUMN_CUTS`
    (:func:`column_cuts`). adaptive: decide per pulse (:mod:`scanner_sim.rays.auto`): where all ``subrays`` hit one
    surface within 5 cm of range, two echoes with their delays' energy, mean, variance and skewness, else one per
    sub-ray. deciding_only: synthesise and search in each record window only the channels that can decide a return
    (:mod:`muls.deciding_channels`).
    """

    name: str
    subrays: int
    shadow_rays: bool
    record_mode: str
    column_cut: str
    adaptive: bool = False
    deciding_only: bool = False


FIDELITY_LEVELS: dict[str, FidelityLevel] = {
    "fast": FidelityLevel("fast", subrays=7, shadow_rays=True, record_mode="windowed", column_cut="pulse",
                          deciding_only=True),
    "balanced": FidelityLevel("balanced", subrays=19, shadow_rays=True, record_mode="windowed", column_cut="subray"),
    "auto": FidelityLevel("auto", subrays=19, shadow_rays=True, record_mode="windowed", column_cut="subray",
                          adaptive=True, deciding_only=True),
    "reference": FidelityLevel("reference", subrays=91, shadow_rays=True, record_mode="full", column_cut="subray"),
}


def fidelity_level(name: str) -> FidelityLevel:
    """The level called ``name``; raises :class:`ParameterError` naming the levels there are."""
    try:
        return FIDELITY_LEVELS[name]
    except (KeyError, TypeError):
        raise ParameterError(f"fidelity = {name!r}: must be one of "
                             f"{', '.join(map(repr, FIDELITY_LEVELS))}") from None


def column_cuts(pulse_index: np.ndarray, range_m: np.ndarray, weight: np.ndarray, n_pulses: int, how: str = "pulse"
                ) -> tuple[np.ndarray, np.ndarray]:
    """Where each pulse's water column stops and the share of the beam stopping there: (cuts [m], shares), both
    (n_pulses, k), the last column the share that meets nothing (cut at inf).

    pulse_index, range_m, weight: (h,) each hit's pulse, range along its sub-ray [m] and share of the pulse energy.
    ``how`` is one of :data:`COLUMN_CUTS`: ``"pulse"`` puts every hit's share at their energy-weighted mean range,
    ``"subray"`` each at its own range (binned to :data:`SUBRAY_CUT_BIN_M`), so a beam split between two surfaces
    lights the column to each.
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
                                np.asarray(weight, np.float64), n_pulses, SUBRAY_CUT_BIN_M)
    shares[:, -1] = miss
    return cuts, np.clip(shares, 0.0, 1.0)


@numba.njit(cache=True, nogil=True)
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
