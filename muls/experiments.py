"""The paper's two tank tests as presets: water, panel, static geometry, gate and PMT gains, each with its
source or a named assumption (docs/assumptions.md), so that ``muls experiment pond|pool`` predicts them.

- ``pond``: the anechoic pond of section 4.2 (1 December 2022): c 1.44, a 0.22 per m, a 0.1 panel at 8.5,
  10 and 11.5 m, one thousand static shots at each, CH3 gated 100/400 ns, PMT gains M1 2000 and M2 20,000.
- ``pool``: the swimming pool of section 4.3 (23 December 2022): c 0.056, a 0.05 per m, the same panel at 3
  to 19 m every 2 m, one thousand shots at each, CH3 gated 150/400 ns. The paper states no gains for the
  pool: they are an operating setting, set here by the rule an operator follows (:func:`operator_gains`).

Gains are never fitted to a measured result: the pond's are the paper's, the pool's come from the rule.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .infra.errors import ParameterError
from .instrument.description import Instrument, Processing
from .optics.optical_model import OpticalModel
from .presets import (
    MAX_PMT_GAIN,
    POND_GAIN_PMT1,
    POND_GAIN_PMT2,
    POND_GATE_S,
    POOL_GATE_S,
    STUDY_ATTENUATION_MODEL,
    highest_unclipped_gain,
    mul2023,
    water_preset,
)
from .water.properties import Water

#: How the instrument finds each peak (``Processing.peak_fit``): the prototype's plain peak detection on
#: the 1 GS/s record (section 4.2: peak detection between the CH0 reference and each channel, Eq. 14), or
#: the project's three-point fit to the known pulse shape (the default of :class:`muls.Processing`).
RANGING = {"prototype": "sample_maximum", "template": "pulse"}
#: Shots at each distance in both experiments (sections 4.2 and 4.3: one thousand measurements).
EXPERIMENT_SHOTS = 1000
#: Reflectance of the black-painted aluminium panel in both experiments (sections 4.2 and 4.3).
PANEL_REFLECTANCE = 0.1


@dataclass(frozen=True)
class Experiment:
    """One tank test: the water, a flat panel at normal incidence at each distance, the CH3 gate [s] and the
    PMT gains. ``sources`` names where each value comes from; ``gain_rule`` says how the gains were set."""

    name: str
    water: Water
    distances_m: tuple[float, ...]
    reflectance: float
    gate_delay_s: float
    gate_width_s: float
    gain_pmt1: float
    gain_pmt2: float
    gain_rule: str
    sources: dict = field(default_factory=dict)

    def instrument(self, ranging: str = "prototype") -> Instrument:
        """The MUL set up for this experiment, ranging with ``ranging`` (a key of :data:`RANGING`)."""
        if ranging not in RANGING:
            raise ParameterError(f"ranging = {ranging!r}: must be one of {', '.join(RANGING)}")
        base = mul2023(self.gate_delay_s, self.gate_width_s, self.gain_pmt1, self.gain_pmt2)
        return replace(base, name=f"mul2023 ({self.name})", processing=Processing(peak_fit=RANGING[ranging]))

    def settings(self) -> dict:
        """JSON-ready description of the experiment, with the source of every value."""
        return {
            "experiment": self.name, "water": self.water.name, "attenuation_model": self.water.attenuation_model,
            "attenuation_per_m": self.water.attenuation_per_m, "absorption_per_m": self.water.absorption_per_m,
            "distances_m": list(self.distances_m), "reflectance": self.reflectance,
            "gate_delay_ns": self.gate_delay_s * 1e9, "gate_width_ns": self.gate_width_s * 1e9,
            "gain_pmt1": self.gain_pmt1, "gain_pmt2": self.gain_pmt2, "gain_rule": self.gain_rule,
            "sources": dict(self.sources),
        }


def channel_peak_w(model: OpticalModel, range_m: float, reflectance: float, channel: str) -> float:
    """Highest noise-free optical power [W] a channel sees around the echo of a flat panel at ``range_m``:
    the column cut at the panel plus the Eq. 7 echo, on a 0.05 ns grid, within the channel's open gate."""
    from .optics.radiometry import lambertian_weight, target_factor

    ins = model.instrument
    delay = 2.0 * range_m / model.water.speed_m_s
    t = np.arange(max(0.0, delay - 10e-9), delay + 60e-9, 0.05e-9)
    energy = ins.transmitter.pulse_energy_j * float(
        target_factor(ins, model.water, range_m, lambertian_weight(ins, range_m, reflectance)))  # MULS Eq. 7
    power = model.column_power_w(t, range_m) + energy * ins.pulse(t - delay)
    ch = ins.channel(channel)
    if ch.gated:
        power = np.where((t >= ch.gate_delay_s) & (t < ch.gate_delay_s + ch.gate_width_s), power, 0.0)
    return float(power.max())


def operator_gains(water: Water, distances_m, reflectance: float, gate_delay_s: float, gate_width_s: float,
                   max_gain: float = MAX_PMT_GAIN) -> tuple[float, float, str]:
    """(M1, M2, rule) as an operator sets the PMT gains for a static test at ``distances_m``.

    The rule: each tube gets the highest gain (up to ``max_gain``) at which the strongest echo it must range
    stays on scale in the channel meant for it: M1 keeps the nearest panel unclipped in CH2, the low-gain
    output of PMT1 (CH1, nine times higher, may clip there: that is what CH2 is for); M2 keeps unclipped in
    CH3 the nearest panel whose echo starts inside the gate (the far channel is there for the far panels).
    'Unclipped': the noise-free peak plus the dark level and five standard deviations of noise stays below
    the top code (:func:`muls.presets.highest_unclipped_gain`, the rule the single channel's gain follows).
    """
    distances = sorted(float(d) for d in distances_m)
    probe = mul2023(gate_delay_s, gate_width_s, 1.0, 1.0)
    model = OpticalModel.build(probe, water)
    dig = probe.digitizer
    m1 = highest_unclipped_gain(probe.channel("ch2"), dig, channel_peak_w(model, distances[0], reflectance, "ch2"),
                                max_gain)
    in_gate = [d for d in distances if 2.0 * d / water.speed_m_s >= gate_delay_s]
    far = in_gate[0] if in_gate else distances[-1]
    m2 = highest_unclipped_gain(probe.channel("ch3"), dig, channel_peak_w(model, far, reflectance, "ch3"), max_gain)
    rule = (f"M1: highest gain <= {max_gain:g} keeping CH2 unclipped on the nearest panel ({distances[0]:g} m); "
            f"M2: highest gain <= {max_gain:g} keeping CH3 unclipped on the nearest panel whose echo starts in the "
            f"gate ({far:g} m); unclipped = noise-free peak + dark level + 5 sigma below the top code")
    return m1, m2, rule


def pond(attenuation_model: str = STUDY_ATTENUATION_MODEL) -> Experiment:
    """The anechoic pond test (paper section 4.2)."""
    water = water_preset("pond").with_models(attenuation_model=attenuation_model)
    return Experiment(
        name="pond", water=water, distances_m=(8.5, 10.0, 11.5), reflectance=PANEL_REFLECTANCE,
        gate_delay_s=POND_GATE_S[0], gate_width_s=POND_GATE_S[1],
        gain_pmt1=POND_GAIN_PMT1, gain_pmt2=POND_GAIN_PMT2,
        gain_rule="the paper's stated gains (section 4.2)",
        sources={
            "water": "section 4.2: WETLabs ac-s, c 1.44 and a 0.22 per m at 532 nm; fresh-water group index "
                     "(assumption); Petzold's average phase function for the small-angle rule (assumption)",
            "attenuation_model": f"{attenuation_model}: the studies' rule (docs/design.md#attenuation)",
            "distances_m": "section 4.2: 8.5, 10.0 and 11.5 m, static, normal incidence",
            "reflectance": "section 4.2: black-painted aluminium plate of reflectance 0.1 (Lambertian: assumption)",
            "gate": "section 4.2: delay 100 ns, width 400 ns",
            "gains": "section 4.2: M1 = 2000 (PMT1), M2 = 20,000 (PMT2)",
            "shots": "section 4.2: one thousand measurements at each position",
        },
    )


def pool(attenuation_model: str = STUDY_ATTENUATION_MODEL) -> Experiment:
    """The swimming-pool test (paper section 4.3), its gains set by :func:`operator_gains`."""
    water = water_preset("pool").with_models(attenuation_model=attenuation_model)
    distances = tuple(float(d) for d in range(3, 20, 2))
    m1, m2, rule = operator_gains(water, distances, PANEL_REFLECTANCE, *POOL_GATE_S)
    return Experiment(
        name="pool", water=water, distances_m=distances, reflectance=PANEL_REFLECTANCE,
        gate_delay_s=POOL_GATE_S[0], gate_width_s=POOL_GATE_S[1], gain_pmt1=m1, gain_pmt2=m2, gain_rule=rule,
        sources={
            "water": "section 4.3: c 0.056 and a 0.05 per m at 532 nm; fresh-water group index (assumption); "
                     "Petzold's average phase function for the small-angle rule (assumption)",
            "attenuation_model": f"{attenuation_model}: the studies' rule (docs/design.md#attenuation)",
            "distances_m": "section 4.3: nine distances from 3 m to 19 m every 2 m, static, normal incidence",
            "reflectance": "section 4.3: black-painted aluminium panel of reflectance 0.1 (Lambertian: assumption)",
            "gate": "section 4.3: delay 150 ns, width 400 ns",
            "gains": "not given by the paper: the operator's rule (named assumption, docs/assumptions.md)",
            "shots": "section 4.3: one thousand measurements at each position",
        },
    )


EXPERIMENTS = {"pond": pond, "pool": pool}


def experiment_preset(name: str, attenuation_model: str = STUDY_ATTENUATION_MODEL) -> Experiment:
    """The named experiment (``pond`` or ``pool``); the error lists the valid names."""
    try:
        build = EXPERIMENTS[name]
    except KeyError:
        raise ParameterError(f"experiment = {name!r}: must be one of {', '.join(EXPERIMENTS)}") from None
    return build(attenuation_model)
