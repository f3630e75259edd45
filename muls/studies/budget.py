"""The photon budget of every study point: the pond and pool tests and the three Petzold waters from 5 to
110 m (:mod:`muls.photon_budget`), and where a range the paper reports needs more photons than a pulse delivers."""

from __future__ import annotations

import math

from ..experiments import experiment_preset
from ..optics.optical_model import OpticalModel
from ..photon_budget import channel_budget
from ..presets import STUDY_ATTENUATION_MODEL, designed_mul, single_channel, study_water
from .common import FAR_GATE_WIDTH_S, MAXRANGE_WATERS, far_gate_delay_s

#: Ranges of the Petzold waters in the budget [m] (the maximum-range study's span).
BUDGET_RANGES_M = tuple(float(r) for r in range(5, 111, 5))
#: What the paper reports ranging (sections 4.2 and 4.3): in the pond every channel at every distance
#: (its Table 2); in the pool CH1 and CH2 at every distance (Figure 11) and CH3 from 17 m, where its gated
#: echo appears (Figure 10h, i).
PAPER_RANGED = {
    "pond": lambda d: ("ch1", "ch2", "ch3"),
    "pool": lambda d: ("ch1", "ch2", "ch3") if d >= 17.0 else ("ch1", "ch2"),
}


def _sig(v, digits: int = 4):
    if v is None:
        return None
    if isinstance(v, bool):
        return v
    if isinstance(v, dict):
        return {k: _sig(x, digits) for k, x in v.items()}
    if isinstance(v, str):
        return v
    v = float(v)
    return 0.0 if v == 0.0 else float(f"{v:.{digits}g}") if math.isfinite(v) else None


def _case(study: str, model: OpticalModel, range_m: float, reflectance: float, extra: dict | None = None,
          paper: tuple[str, ...] = ()) -> dict:
    photons, chans = channel_budget(model, range_m, reflectance)
    for name, b in (extra or {}).items():
        chans[name] = b
    return {
        "study": study, "water": model.water.name, "range_m": float(range_m), "photons_at_aperture": _sig(photons),
        "channels": {name: {k: _sig(v) for k, v in b.items()} for name, b in chans.items()},
        "paper_ranged": list(paper),
    }


def budget_study(attenuation_model: str = STUDY_ATTENUATION_MODEL, waters=MAXRANGE_WATERS,
                 ranges_m=BUDGET_RANGES_M, reflectance: float = 0.1) -> dict:
    """Photon budget of every study point (noise-free arithmetic, no simulation).

    Cases: the pond and pool experiments (:mod:`muls.experiments`: their gains and gates) at their
    distances; each of ``waters`` at ``ranges_m`` with the designed MUL of the maximum-range study (CH3 gated
    for the range) and the single channel (key ``single``). Each case: ``photons_at_aperture`` of the panel's
    echo and, per channel, :func:`muls.photon_budget.channel_budget`. ``beyond_the_budget`` lists every channel and
    distance the paper reports ranging where the echo would need more photons than the pulse delivers even at
    unlimited gain; ``not_detectable`` every one the model cannot detect at the experiment's gains, with why.
    """
    cases = []
    for name in ("pond", "pool"):
        exp = experiment_preset(name, attenuation_model)
        model = OpticalModel.build(exp.instrument("prototype"), exp.water)
        for d in exp.distances_m:
            cases.append(_case(name, model, d, exp.reflectance, paper=PAPER_RANGED[name](d)))
    for name in waters:
        w = study_water(name, attenuation_model)
        single = OpticalModel.build(single_channel(w), w)
        for r in ranges_m:
            mul = OpticalModel.build(designed_mul(w, float(far_gate_delay_s(r, w.speed_m_s)), FAR_GATE_WIDTH_S), w)
            _, one = channel_budget(single, r, reflectance)
            cases.append(_case("maxrange", mul, r, reflectance, extra={"single": one["ch1"]}))
    beyond, missed = [], []
    for case in cases:
        for ch in case["paper_ranged"]:
            b = case["channels"][ch]
            row = {"study": case["study"], "range_m": case["range_m"], "channel": ch, "snr": b["snr"],
                   "photon_limited_snr": b["photon_limited_snr"], "photons_at_aperture": case["photons_at_aperture"],
                   "photons_needed_at_aperture": b["photons_needed_at_aperture"], "limit": b["limit"]}
            need = b["photons_needed_at_aperture"]
            if need is not None and need > case["photons_at_aperture"]:
                beyond.append({**row, "factor": _sig(need / case["photons_at_aperture"], 3)})
            if not b["detectable"]:
                missed.append(row)
    return {
        "cases": cases,
        "beyond_the_budget": beyond,
        "not_detectable": missed,
        "settings": {
            "attenuation_model": attenuation_model, "reflectance": reflectance, "waters": list(waters),
            "ranges_m": list(ranges_m), "experiments": "pond and pool with their gains and gates (muls.experiments)",
            "maxrange_instrument": "designed MUL (muls.presets.designed_mul), CH3 gated for each range; 'single' "
                                   "the single channel (muls.presets.single_channel)",
            "photons_at_aperture": "echo photons reaching the receiver aperture, before the receiver optics (eta_o)",
            "photoelectrons": "photons x eta_o x split ratio x QE, QE = S_k h nu / e",
            "peak_lsb": "noise-free echo peak over the baseline (Eqs. 12-13), 0 when the gate is shut",
            "noise_lsb": "dark (dark noise and rounding), shot (echo and column), total, at the echo's peak",
            "detectable": "peak above threshold_sigma x total noise, gate open, column not clipping the channel",
            "photon_limited_snr": "SNR with shot noise alone: what unlimited gain would give",
            "photons_needed_at_aperture": "photons the echo needs for the photon-limited SNR to reach the threshold",
        },
    }


def budget_table(result: dict) -> list[str]:
    """Short text lines of the budget (the experiments in full, the Petzold waters every 10 m)."""
    names = ("ch1", "ch2", "ch3", "single")
    lines = [f"{'':35s}" + "".join(f"{n:^27s}" for n in names),
             f"{'study':9s} {'water':14s} {'R m':>5s} {'photons':>9s}" + f" {'pe':>8s} {'LSB':>8s} {'SNR':>7s} " * 4]
    for case in result["cases"]:
        if case["study"] == "maxrange" and case["range_m"] % 10 != 0:
            continue
        cells = []
        for c in names:
            b = case["channels"].get(c)
            cells.append(" " * 27 if b is None else
                         f" {b['photoelectrons']:8.3g} {b['peak_lsb']:8.3g} {b['snr']:7.3g}{' ' if b['detectable'] else 'x'}")
        lines.append(f"{case['study']:9s} {case['water']:14s} {case['range_m']:5.1f} {case['photons_at_aperture']:9.3g}"
                     + "".join(cells))
    lines.append("pe: echo photoelectrons; LSB: echo peak; x: not detectable at the project's threshold with the case's gains")
    for row in result["beyond_the_budget"]:
        lines.append(f"beyond the photon budget: {row['study']} {row['range_m']:g} m {row['channel']} needs "
                     f"{row['photons_needed_at_aperture']:.3g} photons at the aperture, the pulse delivers "
                     f"{row['photons_at_aperture']:.3g} ({row['factor']:.3g} x)")
    for row in result["not_detectable"]:
        lines.append(f"not detectable: {row['study']} {row['range_m']:g} m {row['channel']} (SNR {row['snr']:.3g}, "
                     f"limit {row['limit']})")
    return lines


__all__ = ["BUDGET_RANGES_M", "budget_study", "budget_table"]
