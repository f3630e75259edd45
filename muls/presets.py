"""Presets: the waters of the paper and of Petzold's measurements, and the instruments (the MUL prototype,
its coaxial variant, a single-channel comparison unit whose gain is set for the water).

Values come from the paper's Table 1 and sections 3-4, or from the cited measurements; anything else is a
named assumption listed in docs/assumptions.md. This module sits above the physics (it needs the
water-column model for the single channel's gain rule), so nothing in muls below it imports it.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .channels import shot_noise_lsb2_per_w
from .errors import ParameterError
from .instrument import Channel, Instrument
from .water import GROUP_INDEX_FRESHWATER, GROUP_INDEX_SEAWATER, Water
from .waveform import OpticalModel

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

#: The attenuation rule of the studies that predict the paper (docs/design.md#attenuation): forward
#: scattering kept by the receiver's field of view (small-angle approximation). The water presets keep Eq.
#: 6's k_lidar as their own default for now (docs/design.md#attenuation: switching changes every survey pass).
STUDY_ATTENUATION_MODEL = "small_angle"


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
    peak_w = column_peak_w(OpticalModel.build(probe, water))
    m1 = highest_unclipped_gain(probe.channel("ch2"), probe.digitizer, peak_w, max_gain)
    return replace(mul2023(gate_delay_s, gate_width_s, gain_pmt1=m1, gain_pmt2=max_gain), name="mul2023 (designed)")
