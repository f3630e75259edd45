"""Fidelity levels: how faithfully a pass simulates each pulse, in one table.

A level fixes the geometry stage (sub-rays per pulse, shadow rays to the receiver), what the waveform stage
records, and how the water column is cut. A scene picks a level with ``survey.fidelity`` and may override
``survey.subrays`` and ``survey.shadow_rays`` (``SurveyConfig.level`` applies them).
"""

from __future__ import annotations

from dataclasses import dataclass

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
    (:func:`column_cuts`). adaptive: decide per pulse (:mod:`scanner_sim.auto_level`): where all ``subrays`` hit one
    surface within 5 cm of range, two echoes with their delays' energy, mean, variance and skewness, else one per
    sub-ray.
    """

    name: str
    subrays: int
    shadow_rays: bool
    record_mode: str
    column_cut: str
    adaptive: bool = False


FIDELITY_LEVELS: dict[str, FidelityLevel] = {
    "fast": FidelityLevel("fast", subrays=7, shadow_rays=True, record_mode="windowed", column_cut="pulse"),
    "balanced": FidelityLevel("balanced", subrays=19, shadow_rays=True, record_mode="windowed", column_cut="subray"),
    "auto": FidelityLevel("auto", subrays=19, shadow_rays=True, record_mode="windowed", column_cut="subray",
                          adaptive=True),
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
    bins = np.round(np.asarray(range_m) / SUBRAY_CUT_BIN_M).astype(np.int64)
    order = np.lexsort((bins, pulse_index))
    p, b = pulse_index[order], bins[order]
    new = np.ones(p.size, bool)
    new[1:] = (p[1:] != p[:-1]) | (b[1:] != b[:-1])
    group = np.cumsum(new) - 1
    share = np.bincount(group, weights=weight[order])
    at = np.bincount(group, weights=(weight * range_m)[order]) / np.where(share > 0, share, 1.0)
    owner = p[new]
    first = np.searchsorted(owner, owner, "left")
    column = np.arange(owner.size) - first  # rank of the cut within its pulse
    k = int(column.max()) + 2 if owner.size else 1
    cuts = np.full((n_pulses, k), np.inf)
    shares = np.zeros((n_pulses, k))
    cuts[owner, column], shares[owner, column] = at, share
    shares[:, -1] = miss
    return cuts, np.clip(shares, 0.0, 1.0)
