"""The pond examined: how far each input the paper leaves unknown moves the pond's predicted detections (``muls
pond-unknowns``).

The paper ranged its 0.1 panel in the pond (c 1.44, a 0.22 per m) on CH1, CH2 and CH3 at 8.5, 10 and 11.5 m. The
model's prediction rests on four inputs the paper does not give; each is moved here alone over a range the set-up
itself or the literature allows, then all together at the end of each range that favours detection:

- the phase function and its b_b/b: the family of :data:`muls.water.phase_family.SENSITIVITY_FAMILY`;
- the gate's reference: CH3's 100 ns delay counted from a trigger that precedes the light by a lead of 0 (the model's
  reading) up to the whole 100 ns (the gate cannot open before the light leaves);
- the detection criterion: a detection within 3 range bins of the truth (the project's) up to 10 (1.1 m, wider than
  the 0.6 m the Monte Carlo's spread puts the peak late), and a 5-sigma threshold or a 4-sigma one;
- Table 1's 50 mrad field of view read as a half angle (the model's, 100 mrad full) or as the full angle.

Nothing is fitted: the paper's measured results are withheld, and only its qualitative claim (detected on every
channel at every distance) is set beside the model's.
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import replace

import numpy as np

from ..experiments import EXPERIMENT_SHOTS, Experiment, experiment_preset
from ..montecarlo.tables import table_packets
from ..optics.optical_model import OpticalModel
from ..simulate import simulate
from ..water.phase_family import DEFAULT_PHASE, SENSITIVITY_FAMILY, PhaseMember
from .bands import BAND_PACKETS, experiment_band, family_summary
from .common import DETECTION_TOLERANCE_BINS, _shots, detections, range_tolerance_m, truth_batch

#: Leads [s] of the trigger over the light: 0 (the model's reading) to the whole gate delay (gate open at emission).
GATE_LEADS_S = (0.0, 25e-9, 50e-9, 100e-9)
#: Detection tolerances [range bins]: the project's 3 to 10 (1.1 m).
TOLERANCE_BINS = (DETECTION_TOLERANCE_BINS, 6, 10)
#: Threshold of the peak search [sigma of the noise]: the project's 5 and a 4-sigma processing.
THRESHOLDS_SIGMA = (5.0, 4.0)
#: Table 1's field of view, 50 mrad, as a full angle [rad]: the half-angle reading (the model's) and the full one.
FOV_FULL_RAD = (0.100, 0.050)
#: What the paper reports: the panel ranged on every channel at every distance (its Table 2).
PAPER_CLAIM = "ranged on CH1, CH2 and CH3 at 8.5, 10 and 11.5 m (section 4.2, Table 2)"
SOURCES = {
    "phase function and b_b/b": "the family's sources (muls.water.phase_family): Petzold; Fournier-Forand b_b/b "
                                "0.005-0.025 (coastal waters); Henyey-Greenstein g 0.85-0.95",
    "gate reference": "the paper gives a 100 ns delay, not its reference; a lead of the trigger over the light "
                      "between 0 and the whole delay (the gate cannot open before the light leaves)",
    "detection criterion": "the paper states none; 3 bins (the project's) to 10 bins (1.1 m, beyond the 0.6 m "
                           "the Monte Carlo's spread delays the pond's echo peak); threshold 5 or 4 sigma",
    "field of view": "Table 1's 50 mrad as a half angle (the model's reading, 100 mrad full) or as the full angle",
}


def detected(exp: Experiment, shots: int, seed: int, ranging: str = "prototype", gate_lead_s: float = 0.0,
             tolerance_bins: int = DETECTION_TOLERANCE_BINS, threshold_sigma: float | None = None,
             fov_full_rad: float | None = None) -> dict:
    """{distance: {channel: detected fraction}} of ``exp`` with one input moved: CH3's gate opened ``gate_lead_s``
    earlier, the tolerance, the threshold, the receiver's full field of view (None: as the experiment has it)."""
    exp = replace(exp, gate_delay_s=max(0.0, exp.gate_delay_s - gate_lead_s))
    instrument = exp.instrument(ranging)
    if threshold_sigma is not None:
        instrument = replace(instrument, processing=replace(instrument.processing, threshold_sigma=threshold_sigma))
    if fov_full_rad is not None:
        instrument = replace(instrument, receiver=replace(instrument.receiver, fov_full_rad=fov_full_rad))
    model = OpticalModel.build(instrument, exp.water)
    r = np.asarray(exp.distances_m, float)
    truth, batch = truth_batch(instrument, r, shots, exp.reflectance, 0)
    _, result = simulate(model, batch, seed, mode="windowed")
    tol = range_tolerance_m(model, tolerance_bins)
    out: dict = {f"{d:g}": {} for d in r}
    for j, name in enumerate(instrument.channel_names):
        error, _ = detections(result.peaks, truth, tol, (j + 1,))
        for i, d in enumerate(r):
            out[f"{d:g}"][name] = round(float(np.isfinite(error[i * shots:(i + 1) * shots]).mean()), 4)
    return out


def _total(fractions: dict) -> float:
    return sum(f for chans in fractions.values() for f in chans.values())


def _all_detected(fractions: dict, level: float = 0.5) -> bool:
    return all(f >= level for chans in fractions.values() for f in chans.values())


def pond_unknowns_study(shots: int = EXPERIMENT_SHOTS, seed: int = 0, ranging: str = "prototype",
                        packets: int = BAND_PACKETS, family: tuple[PhaseMember, ...] = SENSITIVITY_FAMILY) -> dict:
    """Each unknown of the pond moved alone over its range, then all at their most favourable ends (module doc).
    Returns ``cases`` (unknown, setting, detected fractions per distance and channel, whether every cell reaches
    half the shots), the phase functions' ``band`` (:func:`muls.studies.bands.experiment_band`), ``sources``,
    ``paper`` and ``settings``."""
    shots = _shots("shots", shots)
    t0 = time.perf_counter()
    exp = experiment_preset("pond")
    cases = []

    def case(unknown: str, setting: str, fractions: dict) -> None:
        cases.append({"unknown": unknown, "setting": setting, "detected": fractions,
                      "every_cell_half_the_shots": _all_detected(fractions)})

    case("none", "the model's defaults", detected(exp, shots, seed, ranging))
    band = experiment_band(exp, shots, seed, ranging, family, packets)
    for label, fractions in band["members"].items():
        if label != family[0].label:
            case("phase function and b_b/b", label, fractions)
    for lead in GATE_LEADS_S[1:]:
        case("gate reference", f"trigger {lead * 1e9:g} ns before the light (gate opens at "
             f"{max(0.0, exp.gate_delay_s - lead) * 1e9:g} ns)", detected(exp, shots, seed, ranging, gate_lead_s=lead))
    for bins in TOLERANCE_BINS[1:]:
        case("detection criterion", f"within {bins} range bins", detected(exp, shots, seed, ranging,
                                                                          tolerance_bins=bins))
    for sigma in THRESHOLDS_SIGMA[1:]:
        case("detection criterion", f"threshold {sigma:g} sigma", detected(exp, shots, seed, ranging,
                                                                            threshold_sigma=sigma))
    fov_detected = {FOV_FULL_RAD[0]: cases[0]["detected"]}
    with table_packets(packets):  # the narrower receiver's own tables, a quicker run
        for fov in FOV_FULL_RAD[1:]:
            fov_detected[fov] = detected(exp, shots, seed, ranging, fov_full_rad=fov)
            case("field of view", f"{fov * 1e3:g} mrad full angle", fov_detected[fov])
    # All together, each at the end of its range that detects most: the phase function, the field of view; the gate
    # open at emission, the widest tolerance, the lower threshold.
    best = max(band["members"], key=lambda k: _total(band["members"][k]))
    fov = max(fov_detected, key=lambda f: _total(fov_detected[f]))
    member = next(m for m in family if m.label == best)
    water = replace(exp.water, phase_function=member.spec)
    standard = member.spec == DEFAULT_PHASE and fov == FOV_FULL_RAD[0]
    with nullcontext() if standard else table_packets(packets):
        together = detected(replace(exp, water=water), shots, seed, ranging, gate_lead_s=GATE_LEADS_S[-1],
                            tolerance_bins=TOLERANCE_BINS[-1], threshold_sigma=THRESHOLDS_SIGMA[-1], fov_full_rad=fov)
    case("all together", f"{best}, gate open at emission, {TOLERANCE_BINS[-1]} bins, {THRESHOLDS_SIGMA[-1]:g} sigma, "
         f"{fov * 1e3:g} mrad full angle", together)
    return {"cases": cases, "band": band["distances"], "sources": SOURCES, "paper": PAPER_CLAIM,
            **family_summary(family, packets),
            "settings": {"experiment": "pond", "shots": shots, "seed": int(seed), "ranging": ranging,
                         "detected_means": "share of the shots whose channel has a peak that detects the panel",
                         "every_cell": "every channel at every distance detects in at least half the shots",
                         "elapsed_s": round(time.perf_counter() - t0, 1)}}
