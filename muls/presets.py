"""Presets: the waters of the paper, of Petzold's measurements and of Jerlov's classification, and the
instruments (the MUL prototype, its coaxial variant, a single-channel comparison unit whose gain is set for
the water).

Values come from the paper's Table 1 and sections 3-4, or from the cited measurements; anything else is a
named assumption listed in docs/assumptions.md. This module sits above the physics (it needs the
water-column model for the single channel's gain rule), so nothing in muls below it imports it.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from .infra.errors import ParameterError
from .instrument.description import Channel, Instrument
from .water.phase import PETZOLD_VALUES_PER_SR
from .water.properties import GROUP_INDEX_FRESHWATER, GROUP_INDEX_SEAWATER, Water

if TYPE_CHECKING:
    from .optics.optical_model import OpticalModel

# --- Waters ------------------------------------------------------------------------------------------------

_PETZOLD = "Petzold (1972) at 530 nm, tabulated in Mobley (1994) Light and Water, Table 3.10"


def _petzold(name: str, a: float, b: float, beta_pi_over_b: float) -> Water:
    return Water(
        name,
        absorption_per_m=a,
        scattering_per_m=b,
        group_index=GROUP_INDEX_SEAWATER,
        beta_pi_measured_per_m_sr=beta_pi_over_b * b,
        source=f"{_PETZOLD}; beta(180)/b = {beta_pi_over_b} from the same measured VSF",
    )


# Jerlov's water types (docs/assumptions.md#jerlov-water-types). Jerlov classified sea water by its downwelling
# diffuse attenuation K_d; Solonenko and Mobley (2015) found the a and b that reproduce it. Both tabulate 525
# and 550 nm: every value below is the printed pair, taken to 532 nm linearly in wavelength.

_SOLONENKO_MOBLEY = "Solonenko & Mobley (2015), Appl. Opt. 54, 5392-5401"
_JERLOV_1976 = "Jerlov (1976), Marine Optics, Table XXVII"

#: The tabulated wavelengths either side of the laser's 532 nm [nm].
JERLOV_TABLE_WAVELENGTHS_NM = (525.0, 550.0)
LASER_WAVELENGTH_NM = 532.0

#: Scattering by pure water at 532 nm [1/m]: the water term of Solonenko & Mobley's Eq. 8 (from Haltrin 1999),
#: 0.00583 (400/lambda)^4.322. Their b is this plus particle scattering.
PURE_WATER_SCATTERING_532_PER_M = 0.00583 * (400.0 / LASER_WAVELENGTH_NM) ** 4.322

#: Phase function of pure water at 180 deg [1/sr]: Morel (1974), beta_w(psi) proportional to 1 + 0.835 cos^2 psi
#: (depolarisation ratio 0.09), normalised over the sphere: 1.835 / (4 pi (1 + 0.835/3)) = 0.114.
PURE_WATER_PHASE_PI_PER_SR = (1.0 + 0.835) / (4.0 * math.pi * (1.0 + 0.835 / 3.0))

#: Petzold's average particle phase function at 180 deg [1/sr], as published (Mobley 1994, Table 3.10).
PARTICLE_PHASE_PI_PER_SR = float(PETZOLD_VALUES_PER_SR[-1])


def at_laser_wavelength(at_525: float, at_550: float) -> float:
    """A value tabulated at 525 and 550 nm, taken to 532 nm linearly in wavelength."""
    lo, hi = JERLOV_TABLE_WAVELENGTHS_NM
    return at_525 + (LASER_WAVELENGTH_NM - lo) / (hi - lo) * (at_550 - at_525)


def jerlov_beta_pi_per_m_sr(scattering_per_m: float) -> float:
    """beta(180 deg) [1/(m sr)] of a Jerlov type of scattering b: pure water's share of b scatters with its
    own phase function (Morel 1974), the rest (particles) with Petzold's average particle phase function."""
    water = min(PURE_WATER_SCATTERING_532_PER_M, scattering_per_m)
    return PURE_WATER_PHASE_PI_PER_SR * water + PARTICLE_PHASE_PI_PER_SR * (scattering_per_m - water)


def _jerlov(kind: str, table: str, a: tuple[float, float], b: tuple[float, float], kd: tuple[float, float]) -> Water:
    """Jerlov type ``kind``: a and b [1/m] from Solonenko & Mobley's ``table``, K_d [1/m] from Jerlov's
    Table XXVII, each as printed at (525, 550) nm."""
    sun = "the sun at the zenith" if kind in ("I", "IA", "IB", "II", "III") else "a solar elevation of 45 deg"
    scattering = at_laser_wavelength(*b)
    return Water(
        f"jerlov_{kind}",
        absorption_per_m=at_laser_wavelength(*a),
        scattering_per_m=scattering,
        group_index=GROUP_INDEX_SEAWATER,
        beta_pi_measured_per_m_sr=jerlov_beta_pi_per_m_sr(scattering),
        kd_per_m=at_laser_wavelength(*kd),
        source=(f"Jerlov type {kind}: a = {a[0]}, {a[1]} and b = {b[0]}, {b[1]} per m at 525, 550 nm from "
                f"{_SOLONENKO_MOBLEY}, {table}; K_d = {kd[0]}, {kd[1]} per m ({sun}) from {_JERLOV_1976}; "
                "each linear in wavelength to 532 nm; beta(180) from b split into pure water (their Eq. 8, "
                "Morel 1974 phase function) and particles (Petzold average phase function)"),
    )


#: The ten Jerlov types: (a, b) of Solonenko & Mobley (2015) and K_d of Jerlov (1976) at (525, 550) nm.
JERLOV_PRESETS: dict[str, Water] = {w.name: w for w in (
    # oceanic types (sun at the zenith)
    _jerlov("I", "Tables 4-5", a=(0.046, 0.062), b=(2.05e-3, 1.70e-3), kd=(0.043, 0.063)),
    _jerlov("IA", "Tables 4-5", a=(0.0468, 0.0622), b=(4.02e-3, 3.54e-3), kd=(0.048, 0.067)),
    _jerlov("IB", "Tables 4-5", a=(0.0469, 0.0623), b=(0.0565, 0.0536), kd=(0.054, 0.072)),
    _jerlov("II", "Tables 4-5", a=(0.0469, 0.0622), b=(0.387, 0.358), kd=(0.076, 0.089)),
    _jerlov("III", "Table 6", a=(0.0507, 0.0646), b=(1.06, 0.980), kd=(0.116, 0.12)),
    # coastal types (solar elevation 45 deg)
    _jerlov("1C", "Table 6", a=(0.068, 0.076), b=(0.395, 0.365), kd=(0.13, 0.12)),
    _jerlov("3C", "Table 7", a=(0.078, 0.082), b=(1.15, 1.06), kd=(0.20, 0.19)),
    _jerlov("5C", "Table 7", a=(0.127, 0.117), b=(1.44, 1.33), kd=(0.31, 0.30)),
    _jerlov("7C", "Table 8", a=(0.233, 0.195), b=(2.54, 2.35), kd=(0.49, 0.46)),
    _jerlov("9C", "Table 8", a=(0.430, 0.348), b=(3.38, 3.12), kd=(0.78, 0.63)),
)}

WATER_PRESETS: dict[str, Water] = {
    "clean_ocean": _petzold("clean_ocean", 0.114, 0.037, 0.0135),
    "coastal_ocean": _petzold("coastal_ocean", 0.179, 0.219, 0.0047),
    "turbid_harbor": _petzold("turbid_harbor", 0.366, 1.824, 0.0031),
    # The paper's test waters (section 4.3 and 4.2); both are fresh-water facilities (named assumption).
    "pool": Water.from_attenuation(
        "pool", 0.056, 0.05, group_index=GROUP_INDEX_FRESHWATER,
        source="MULS paper section 4.3: swimming pool, c = 0.056, a = 0.05 per m at 532 nm",
    ),
    "pond": Water.from_attenuation(
        "pond", 1.44, 0.22, group_index=GROUP_INDEX_FRESHWATER,
        source="MULS paper section 4.2: anechoic pond (WETLabs ac-s), c = 1.44, a = 0.22 per m at 532 nm",
    ),
    **JERLOV_PRESETS,
}


def water_preset(name: str) -> Water:
    """Return the named water preset; the error lists the valid names."""
    try:
        return WATER_PRESETS[name]
    except KeyError:
        raise ParameterError(f"water = {name!r}: must be one of {', '.join(sorted(WATER_PRESETS))}") from None


# --- Instruments -------------------------------------------------------------------------------------------

# Pond experiment gate (section 4.2): 100 ns delay, 400 ns width; the pool used 150 / 400 ns (section 4.3).
POND_GATE_S = (100e-9, 400e-9)
POOL_GATE_S = (150e-9, 400e-9)


#: PMT gains of the pond experiment, the only ones the paper states (section 4.2): M1 (PMT1, CH1 and CH2)
#: and M2 (PMT2, CH3). Gains are an operating setting: muls.experiments sets them for each experiment.
POND_GAIN_PMT1 = 2000.0
POND_GAIN_PMT2 = 20000.0


def mul2023(gate_delay_s: float = POND_GATE_S[0], gate_width_s: float = POND_GATE_S[1],
            gain_pmt1: float = POND_GAIN_PMT1, gain_pmt2: float = POND_GAIN_PMT2) -> Instrument:
    """The paper's MUL prototype: Table 1, the pond's gains and gate (section 4.2) unless given, named
    assumptions elsewhere."""
    return Instrument(
        name="mul2023",
        channels=(
            # PMT1 (H10720-01, non-gated) gets 2 % of the light; its output splits 9:1 (Table 1, section 3).
            Channel("ch1", "near", split_ratio=0.02, voltage_ratio=0.9, gain=gain_pmt1),
            Channel("ch2", "near", split_ratio=0.02, voltage_ratio=0.1, gain=gain_pmt1),
            # PMT2 (H11526-01, gated) gets 98 % (section 3).
            Channel("ch3", "far", split_ratio=0.98, voltage_ratio=1.0, gain=gain_pmt2,
                    gate_delay_s=gate_delay_s, gate_width_s=gate_width_s),
        ),
    )


#: assumption: the highest PMT gain a user would set on any tube, that of the MUL's far-field PMT (section 4.2);
#: higher gains only scale the dark noise of a real tube.
MAX_PMT_GAIN = 20000.0
SINGLE_CHANNEL_MAX_GAIN = MAX_PMT_GAIN
#: assumption: the gain rule keeps this many standard deviations of noise below the top code above the peak.
GAIN_RULE_SIGMA = 5.0

#: The attenuation rule of the studies that predict the paper (docs/design.md#attenuation): the Monte Carlo
#: reference's, as every water's default and every pass's, so that the studies and the surveys share one physics.
STUDY_ATTENUATION_MODEL = "monte_carlo"


def study_water(water: str | Water, attenuation_model: str | None = STUDY_ATTENUATION_MODEL) -> Water:
    """A water preset (or a Water) with the studies' attenuation rule; ``None`` keeps the water's own."""
    w = water if isinstance(water, Water) else water_preset(water)
    return w if attenuation_model is None else w.with_models(attenuation_model=attenuation_model)


def coaxial() -> Instrument:
    """The MUL with coaxial optics: no offset (overlap 1), the window return coupled (Eq. 3, O = 1)."""
    base = mul2023()
    return replace(base, name="coaxial", receiver=replace(base.receiver, offset_m=0.0, window_coupling=1.0))


def instrument_preset(name: str, water: Water | None = None) -> Instrument:
    """The named instrument; ``single_channel`` sets its gain for ``water``."""
    if water is not None and not isinstance(water, Water):
        raise TypeError(f"water must be a Water (muls.water_preset(name) gives one) or None, not "
                        f"{type(water).__name__} {water!r:.60}")
    if name == "mul2023":
        return mul2023()
    if name == "coaxial":
        return coaxial()
    if name == "single_channel":
        if water is None:
            raise ParameterError("instrument 'single_channel' needs a water type: its gain is set for the water")
        return single_channel(water)
    raise ParameterError(f"instrument = {name!r}: must be one of 'coaxial', 'mul2023', 'single_channel'")


def headroom_lsb(channel: Channel, digitizer, peak_w: float, k_sigma: float = GAIN_RULE_SIGMA) -> float:
    """Codes left above a signal of ``peak_w`` [W] in ``channel``: top code minus (dark level + signal +
    ``k_sigma`` standard deviations of dark and shot noise) [LSB]; negative when it would clip."""
    from .instrument.channels import shot_noise_lsb2_per_w  # here: that module defines kernels, a preset needs none

    level = channel.volts_per_watt * peak_w * digitizer.lsb_per_volt  # MULS Eqs. 12, 13
    shot_var = shot_noise_lsb2_per_w(channel, digitizer.bandwidth_hz, digitizer.lsb_per_volt) * peak_w
    return digitizer.max_code - (channel.dark_mean_lsb + level + k_sigma * math.sqrt(channel.dark_std_lsb**2 + shot_var))


def highest_unclipped_gain(channel: Channel, digitizer, peak_w: float, max_gain: float = MAX_PMT_GAIN) -> float:
    """The gain rule of every preset that sets one: the highest PMT gain M (up to ``max_gain``) at which a
    signal of ``peak_w`` [W] plus the dark level and GAIN_RULE_SIGMA standard deviations of noise stays below
    the top code (bisection on ln M). Raises when even gain 1 clips."""
    if headroom_lsb(replace(channel, gain=max_gain), digitizer, peak_w) >= 0.0:
        return float(max_gain)
    if headroom_lsb(replace(channel, gain=1.0), digitizer, peak_w) < 0.0:
        raise ParameterError(f"channel '{channel.name}': a signal of {peak_w:.3g} W clips the digitiser even at gain 1")
    lo, hi = 0.0, math.log(max_gain)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if headroom_lsb(replace(channel, gain=math.exp(mid)), digitizer, peak_w) >= 0.0 else (lo, mid)
    return math.exp(lo)


def column_peak_w(model: OpticalModel) -> float:
    """Peak of the noise-free water-column power [W] over the record (no target, no gate)."""
    t = np.arange(0.0, model.instrument.digitizer.record_length_s, 0.25e-9)
    return float(np.max(model.column_power_w(t)))


def single_channel(water: Water, base: Instrument | None = None) -> Instrument:
    """One non-gated detector receiving all the light, its gain set for ``water`` as a designer would.

    The gain is the highest (up to ``SINGLE_CHANNEL_MAX_GAIN``) at which the noise-free water-column
    backscatter plus the dark level and five standard deviations of noise stays below the top code
    (:func:`highest_unclipped_gain`).
    """
    base = base or mul2023()
    template = Channel("ch1", "single", split_ratio=1.0, voltage_ratio=1.0, gain=1.0)
    unit = replace(base, name="single_channel", channels=(template,))
    from .optics.optical_model import OpticalModel  # kernels: only for a gain designed for a water

    peak_w = column_peak_w(OpticalModel.build(unit, water))
    try:
        gain = highest_unclipped_gain(template, unit.digitizer, peak_w, SINGLE_CHANNEL_MAX_GAIN)
    except ParameterError:
        raise ParameterError(f"water '{water.name}': the column backscatter clips the digitiser even at gain 1") from None
    return replace(unit, channels=(replace(template, gain=gain),))


def designed_mul(water: Water, gate_delay_s: float = POND_GATE_S[0], gate_width_s: float = POND_GATE_S[1],
                 max_gain: float = MAX_PMT_GAIN) -> Instrument:
    """The MUL with its gains set for ``water`` as a designer would (the maximum-range comparison).

    PMT1 gets the highest gain (up to ``max_gain``) at which CH2, its low-gain output, keeps the water column
    unclipped (the rule of :func:`single_channel`); CH1 is then nine times CH2 by the 9:1 split and clips on
    the column near the instrument, which is what CH2 is for. PMT2 behind its gate runs at ``max_gain``.
    """
    probe = mul2023(gate_delay_s, gate_width_s, gain_pmt1=1.0, gain_pmt2=max_gain)
    from .optics.optical_model import OpticalModel  # kernels: only for a gain designed for a water

    peak_w = column_peak_w(OpticalModel.build(probe, water))
    m1 = highest_unclipped_gain(probe.channel("ch2"), probe.digitizer, peak_w, max_gain)
    return replace(mul2023(gate_delay_s, gate_width_s, gain_pmt1=m1, gain_pmt2=max_gain), name="mul2023 (designed)")
