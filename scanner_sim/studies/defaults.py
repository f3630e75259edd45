"""What the study commands offer by default, and their choices: the coverage study's waters, instruments and gate
modes, survey planning's required share, the trade-off's knobs and pulses. Kept apart from the studies, which import
the pipeline and its kernels, so that ``scanner-sim coverage --help``, ``plan --help`` and ``tradeoff --help`` show
them without importing either (``tests/system/test_start_up.py``)."""

from __future__ import annotations

# -- the coverage study (scanner_sim.studies.coverage_study) ------------------------------------------------
INSTRUMENTS = ("mul2023", "single_channel", "coaxial")
GATE_MODES = ("follow", "fixed")
DEFAULT_WATERS = ("clean_ocean", "coastal_ocean", "turbid_harbor")
DEFAULT_INSTRUMENTS = ("mul2023", "single_channel")

# -- survey planning (scanner_sim.studies.planning) ---------------------------------------------------------
#: Share of the planned area on which the order must hold, by default.
DEFAULT_REQUIRED_SHARE = 0.95  # assumption: S-44's 95 % confidence read over the area (docs/assumptions.md)

# -- speed against accuracy (scanner_sim.studies.tradeoff) --------------------------------------------------
#: Single changes to ``balanced``, one knob each: name -> the field it sets and its value.
KNOBS: dict[str, tuple[str, object]] = {
    "subrays=1": ("subrays", 1), "subrays=7": ("subrays", 7), "subrays=37": ("subrays", 37),
    "subrays=91": ("subrays", 91), "shadow_rays=off": ("shadow_rays", False), "record_mode=full": ("record_mode", "full"),
    "column_cut=pulse": ("column_cut", "pulse"), "deciding_only=on": ("deciding_only", True),
    "multiple_scattering=none": ("multiple_scattering", "none"),
}
#: Pulses each run simulates, by default, and of those, pulses whose waveforms are compared. On 2 shared cores
#: ``scanner-sim tradeoff cable_survey`` (4 levels, 8 knobs, the convergence run, 3 timed passes) then takes 1.5-3 minutes
#: (docs/fidelity.md).
DEFAULT_PULSES = 30000
#: Timed passes of each run, the fastest kept: one pass of 30,000 pulses lasts about a second, and on a shared
#: machine two single passes of one level differ by up to a third.
DEFAULT_REPEAT = 3
DEFAULT_WAVEFORM_PULSES = 500
