"""Fidelity levels: how faithfully a pass simulates each pulse, in one table (vocabulary shared by the scene
format, the pass, the studies and the command line).

A level fixes the geometry stage (sub-rays per pulse, shadow rays to the receiver), what the waveform stage
records, and how the water column is cut. A scene picks a level with ``survey.fidelity`` and may override
``survey.subrays`` and ``survey.shadow_rays`` (``SurveyConfig.level`` applies them).
"""

from __future__ import annotations

from dataclasses import dataclass

from muls.infra.errors import ParameterError

#: Where the water column stops: ``"pulse"`` once per pulse, at the energy-weighted mean hit range for the share
#: of the beam that hits; ``"subray"`` where each sub-ray stops (:func:`scanner_sim.survey.handoff.column_cuts`).
COLUMN_CUTS = ("pulse", "subray")


@dataclass(frozen=True)
class FidelityLevel:
    """One fidelity level.

    subrays: beam sub-rays per pulse (one of ``rays.beams.SUBRAY_COUNTS``). shadow_rays: cast a visibility ray
    from each hit to the receiver aperture (parallax shadows); without them only the FOV cone is checked.
    record_mode: ``"windowed"`` (samples around the echoes) or ``"full"`` (every sample of every channel),
    ``muls.receiver.record_windows.RECORD_MODES``. column_cut: where the water column stops, one of :data:`COLUMN_CUTS`
    (:func:`scanner_sim.survey.handoff.column_cuts`). adaptive: decide per pulse (:mod:`scanner_sim.rays.auto`):
    where all ``subrays`` hit one surface within 0.10 m of range (:data:`scanner_sim.rays.collapse.COLLAPSE_SPAN_M`),
    two echoes with their delays' energy, mean, variance and skewness, else one per sub-ray. deciding_only:
    synthesise and search in each record window only the channels that can decide a return
    (:mod:`muls.receiver.deciding_channels`). multiple_scattering: ``"table"`` (the Monte Carlo's water column and
    each echo's spread in time, :mod:`muls.montecarlo.scattering_tables`) or ``"none"`` (single scattering),
    ``muls.water.properties.MULTIPLE_SCATTERING``.
    """

    name: str
    subrays: int
    shadow_rays: bool
    record_mode: str
    column_cut: str
    adaptive: bool = False
    deciding_only: bool = False
    multiple_scattering: str = "table"


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
