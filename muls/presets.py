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


def mul2023(gate_delay_s: float = POND_GATE_S[0], gate_width_s: float = POND_GATE_S[1]) -> Instrument:
    """The paper's MUL prototype: Table 1, gains of section 4.2, named assumptions elsewhere."""
    return Instrument(
        name="mul2023",
        channels=(
            # PMT1 (H10720-01, non-gated) gets 2 % of the light; its output splits 9:1 (Table 1, section 3).
            Channel("ch1", "near", split_ratio=0.02, voltage_ratio=0.9, gain=2000.0),  # M1 = 2000, section 4.2
            Channel("ch2", "near", split_ratio=0.02, voltage_ratio=0.1, gain=2000.0),
            # PMT2 (H11526-01, gated) gets 98 % (section 3); M2 = 20,000 (section 4.2).
            Channel("ch3", "far", split_ratio=0.98, voltage_ratio=1.0, gain=20000.0,
                    gate_delay_s=gate_delay_s, gate_width_s=gate_width_s),
        ),
    )


#: assumption: the highest PMT gain a user would set on the single-channel instrument, that of the MUL's
#: far-field PMT (section 4.2); higher gains only scale the dark noise of a real tube.
SINGLE_CHANNEL_MAX_GAIN = 20000.0


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


def single_channel(water: Water, base: Instrument | None = None) -> Instrument:
    """One non-gated detector receiving all the light, its gain set for ``water`` as a user would.

    The gain is the highest (up to ``SINGLE_CHANNEL_MAX_GAIN``) at which the noise-free water-column
    backscatter plus the dark level and five standard deviations of noise stays below the top code.
    """
    base = base or mul2023()
    template = Channel("ch1", "single", split_ratio=1.0, voltage_ratio=1.0, gain=1.0)
    unit = replace(base, name="single_channel", channels=(template,))
    model = OpticalModel.build(unit, water)
    t = np.arange(0.0, unit.digitizer.record_length_s, 0.25e-9)
    peak_w = float(np.max(model.column_power_w(t)))
    dig = unit.digitizer

    def headroom(gain: float) -> float:
        ch = replace(template, gain=gain)
        level = ch.volts_per_watt * peak_w * dig.lsb_per_volt
        shot_var = shot_noise_lsb2_per_w(ch, dig.bandwidth_hz, dig.lsb_per_volt) * peak_w
        return dig.max_code - (ch.dark_mean_lsb + level + 5.0 * math.sqrt(ch.dark_std_lsb**2 + shot_var))

    if headroom(SINGLE_CHANNEL_MAX_GAIN) >= 0.0:
        gain = SINGLE_CHANNEL_MAX_GAIN
    else:
        lo, hi = 0.0, math.log(SINGLE_CHANNEL_MAX_GAIN)
        if headroom(1.0) < 0.0:
            raise ParameterError(f"water '{water.name}': the column backscatter clips the digitiser even at gain 1")
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if headroom(math.exp(mid)) >= 0.0 else (lo, mid)
        gain = math.exp(lo)
    return replace(unit, channels=(replace(template, gain=gain),))
