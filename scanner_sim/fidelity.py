"""Fidelity levels: how faithfully a pass simulates each pulse, in one table.

A level fixes the geometry stage (sub-rays per pulse, shadow rays to the receiver), what the waveform stage
records, and how the water column is cut. A scene picks a level with ``survey.fidelity`` and may override
``survey.subrays`` and ``survey.shadow_rays`` (``SurveyConfig.level`` applies them).
"""

from __future__ import annotations

from dataclasses import dataclass

from muls.errors import ParameterError


@dataclass(frozen=True)
class FidelityLevel:
    """One fidelity level.

    subrays: beam sub-rays per pulse (one of ``beams.SUBRAY_COUNTS``). shadow_rays: cast a visibility ray from
    each hit to the receiver aperture (parallax shadows); without them only the FOV cone is checked.
    record_mode: ``"windowed"`` (samples around the echoes) or ``"full"`` (every sample of every channel),
    ``muls.detection.RECORD_MODES``. column_cut: where the water column stops; ``"pulse"`` cuts it once per
    pulse, at the energy-weighted mean hit range for the share of the beam that hits.
    """

    name: str
    subrays: int
    shadow_rays: bool
    record_mode: str
    column_cut: str


FIDELITY_LEVELS: dict[str, FidelityLevel] = {
    "fast": FidelityLevel("fast", subrays=7, shadow_rays=False, record_mode="windowed", column_cut="pulse"),
    "balanced": FidelityLevel("balanced", subrays=19, shadow_rays=True, record_mode="windowed", column_cut="pulse"),
    "reference": FidelityLevel("reference", subrays=91, shadow_rays=True, record_mode="full", column_cut="pulse"),
}


def fidelity_level(name: str) -> FidelityLevel:
    """The level called ``name``; raises :class:`ParameterError` naming the levels there are."""
    try:
        return FIDELITY_LEVELS[name]
    except (KeyError, TypeError):
        raise ParameterError(f"fidelity = {name!r}: must be one of "
                             f"{', '.join(map(repr, FIDELITY_LEVELS))}") from None
