"""The photon budget of one echo: photons at the aperture, photoelectrons, peak codes and noise per channel,
and what limits its detection (MULS Eqs. 7, 12, 13 and the noise model of muls.instrument.channels).

Everything here is noise-free arithmetic on the model's own numbers (no simulation), so it shows why a
channel can or cannot see an echo: for a flat Lambertian panel at normal incidence filling the beam, the
echo energy is Eq. 7; photons reach the aperture before the receiver optics (eta_o) and become
photoelectrons in a PMT with the quantum efficiency its radiant sensitivity implies, QE = S_k h nu / e.
"""

from __future__ import annotations

import math

from .instrument.channels import ELECTRON_CHARGE_C
from .optics.optical_model import OpticalModel
from .optics.radiometry import lambertian_weight, target_factor

PLANCK_J_S = 6.62607015e-34
SPEED_OF_LIGHT_M_S = 299_792_458.0
#: Causes that limit a detection (:func:`limiting_cause`), in the order they are tested.
LIMITS = ("gate", "photons", "backscatter", "ADC noise")


def photon_energy_j(wavelength_m: float) -> float:
    """h nu [J] of one photon of vacuum wavelength ``wavelength_m`` [m]."""
    return PLANCK_J_S * SPEED_OF_LIGHT_M_S / wavelength_m


def quantum_efficiency(sensitivity_a_per_w: float, wavelength_m: float) -> float:
    """Photoelectrons per photon of a cathode of radiant sensitivity S_k [A/W]: S_k h nu / e."""
    return sensitivity_a_per_w * photon_energy_j(wavelength_m) / ELECTRON_CHARGE_C


def echo_energy_j(model: OpticalModel, range_m: float, reflectance: float) -> float:
    """Energy [J] of a flat panel's echo after the receiver optics (MULS Eq. 7 times E_t)."""
    ins = model.instrument
    return ins.transmitter.pulse_energy_j * float(
        target_factor(ins, model.water, range_m, lambertian_weight(ins, range_m, reflectance)))  # MULS Eq. 7


def channel_budget(model: OpticalModel, range_m: float, reflectance: float) -> tuple[float, dict]:
    """(photons at the aperture, {channel: budget}) of a flat panel's echo at ``range_m`` [m].

    Per channel, at the echo's peak (the pulse's peak delay after 2 R / c_w): ``photoelectrons`` of the echo
    in the channel's detector; ``peak_lsb`` of the echo over the baseline (0 when the gate is shut then);
    ``noise_lsb`` {"dark" (dark noise and rounding), "shot" (the echo's and the water column's), "total"};
    ``snr`` = peak / total; ``detectable``: the peak clears ``threshold_sigma`` x total where the column does
    not clip the channel; ``photon_limited_snr``: the SNR with shot noise alone, which no gain can raise;
    ``photons_needed_at_aperture``: the photons the echo would need for that SNR to reach the threshold
    (more than ``photons_at_aperture``: no gain detects it); ``in_gate``, ``blind``; ``noise_terms_lsb``
    {"dark", "column_shot", "echo_shot"} and ``limit`` (:func:`limiting_cause`, None when detectable).
    """
    ins = model.instrument
    dig = ins.digitizer
    chans = model.channels
    k = ins.processing.threshold_sigma
    hv = photon_energy_j(ins.transmitter.wavelength_m)
    energy = echo_energy_j(model, range_m, reflectance)
    photons = energy / (ins.receiver.efficiency * hv)
    t_peak = 2.0 * range_m / model.water.speed_m_s + ins.pulse.peak_delay_s
    echo_w = energy * ins.pulse.peak_per_s
    column_w = float(model.column_power_w(t_peak, range_m)[0])
    uncut_w = float(model.column_power_w(t_peak)[0])  # the calibrated baseline the processing subtracts
    out = {}
    for j, ch in enumerate(ins.channels, start=1):
        in_gate = bool(chans.gate_open_s[j] <= t_peak < chans.gate_close_s[j])
        lsb_per_w = float(chans.lsb_per_w[j]) if in_gate else 0.0
        shot_per_w = float(chans.shot_lsb2_per_w[j]) if in_gate else 0.0
        peak = lsb_per_w * echo_w  # MULS Eqs. 12, 13
        dark = math.sqrt(ch.dark_std_lsb**2 + 1.0 / 12.0)
        column_shot = math.sqrt(shot_per_w * column_w)
        echo_shot = math.sqrt(shot_per_w * echo_w)
        total = math.sqrt(dark**2 + column_shot**2 + echo_shot**2)
        blind = bool(ch.dark_mean_lsb + lsb_per_w * uncut_w >= dig.max_code)
        shot_only = math.sqrt(column_shot**2 + echo_shot**2)
        limited = peak / shot_only if shot_only > 0.0 else None
        pe = photons * ins.receiver.efficiency * ch.split_ratio * quantum_efficiency(ch.sensitivity_a_per_w,
                                                                                     ins.transmitter.wavelength_m)
        budget = {
            "photoelectrons": pe, "peak_lsb": peak,
            "noise_lsb": {"dark": dark, "shot": shot_only, "total": total},
            "snr": peak / total, "detectable": bool(in_gate and not blind and peak > k * total),
            "photon_limited_snr": limited,
            "photons_needed_at_aperture": _photons_needed(photons, peak, echo_shot, column_shot, k) if in_gate else None,
            "in_gate": in_gate, "blind": blind,
            "noise_terms_lsb": {"dark": dark, "column_shot": column_shot, "echo_shot": echo_shot},
        }
        budget["limit"] = None if budget["detectable"] else limiting_cause(budget, k)
        out[ch.name] = budget
    return photons, out


def _photons_needed(photons: float, peak: float, echo_shot: float, column_shot: float, k: float) -> float | None:
    """Photons at the aperture for which the echo clears k sigma of shot noise alone (unlimited gain): the
    echo scales by s, its peak as s and its shot variance as s, the column's stays: s^2 A^2 = k^2 (s e + c)."""
    if peak <= 0.0:
        return None
    a2, e2, c2 = peak**2, echo_shot**2, column_shot**2
    s = (k * k * e2 + math.sqrt(k**4 * e2 * e2 + 4.0 * a2 * k * k * c2)) / (2.0 * a2)
    return s * photons


def limiting_cause(budget: dict, k: float) -> str:
    """What limits a channel's view of an echo, tested in order: ``gate`` (shut at the echo's peak);
    ``backscatter`` (the water column clips the channel there); when even unlimited gain would leave the
    echo under ``k`` sigma of shot noise, ``photons`` (too few photoelectrons in the echo) or ``backscatter``
    (the column's shot noise, if it is the larger); else the largest noise term at the peak: ``ADC noise``
    (the digitiser's dark and rounding noise: more gain would lift the echo above it, if the gain rule
    allowed it), ``backscatter`` (the column's shot noise) or ``photons`` (the echo's own)."""
    if not budget["in_gate"]:
        return "gate"
    if budget["blind"]:
        return "backscatter"
    terms = budget["noise_terms_lsb"]
    limited = budget["photon_limited_snr"]
    if limited is not None and limited < k:
        return "photons" if terms["echo_shot"] >= terms["column_shot"] else "backscatter"
    return {"dark": "ADC noise", "column_shot": "backscatter", "echo_shot": "photons"}[max(terms, key=terms.get)]
