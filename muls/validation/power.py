"""Monte Carlo tallies as received optical power, beside MULS's: the pulse, the optics, the geometry share.

The Monte Carlo's tallies are impulse responses (energy per emitted energy per time bin at the aperture);
here they go through the emitted band-limited pulse (MULS Eq. 2) and the receiver's optics, and MULS's own
column (Eq. 4) and echo (Eq. 7) are evaluated on the same grid.
"""

from __future__ import annotations

import math

import numpy as np

from ..instrument.description import Instrument
from ..montecarlo.run import BATCHES, MonteCarloResult, TargetPlanes, run_monte_carlo, var_of_mean
from ..optics import radiometry
from ..optics.optical_model import OpticalModel
from ..optics.radiometry import lambertian_weight, target_factor
from ..water.properties import Water


def two_way_transmission(instrument: Instrument) -> float:
    """eta_t eta_o (1 - T_s)^2, the optics MULS Eqs. 4 and 7 carry and the Monte Carlo leaves out."""
    return float(radiometry.two_way_transmission(instrument))


def pulse_kernel(instrument: Instrument, time_step_s: float) -> np.ndarray:
    """(m,) the band-limited pulse of MULS Eq. 2 [1/s] averaged over bins [(i - 1/2) dt, (i + 1/2) dt).

    A histogram h of energies in bins [j dt, (j+1) dt) becomes the power sum_j h_j kernel[i - j] at the
    bin centres (i + 1/2) dt.
    """
    pulse = instrument.pulse
    m = int(math.ceil(pulse.duration_s * 1.5 / time_step_s)) + 2
    sub = (np.arange(16) + 0.5) / 16.0 - 0.5
    u = (np.arange(m)[:, None] + sub[None, :]) * time_step_s
    return pulse(u).mean(axis=1)


def to_power_w(energy_per_bin: np.ndarray, instrument: Instrument, time_step_s: float) -> np.ndarray:
    """Received optical power [W] at the bin centres from energy fractions per bin (..., n_t)."""
    from scipy.signal import fftconvolve  # here: scipy.signal costs every importer of the tables 0.8 s

    e = np.asarray(energy_per_bin, float)
    if e.shape[-1] == 0:
        return e.copy()
    kernel = pulse_kernel(instrument, time_step_s)
    scale = instrument.transmitter.pulse_energy_j * two_way_transmission(instrument)
    shape = (1,) * (e.ndim - 1) + (kernel.shape[0],)
    return scale * fftconvolve(e, kernel.reshape(shape), axes=-1)[..., : e.shape[-1]]


def mc_power_w(result: MonteCarloResult, k: int, instrument: Instrument) -> dict:
    """Scene k's Monte Carlo signals [W] at the bin centres: {part: (mean, standard error)}.

    Parts: ``column``, ``column_first`` (first scattering only), ``target`` (both returns), ``total``.
    Errors combine the spread of the beam batches and, for the scattered return, of the receiver batches.
    """
    dt = result.time_step_s
    keep = result.time_s < result.scene_end_s[k] if result.ranges_m else np.ones(result.n_t, bool)

    def stats(beam, receiver=None, extra_mean=0.0, beam_mean_offset=None):
        pb = to_power_w(beam, instrument, dt)
        mean = pb.mean(axis=0)
        var = var_of_mean(pb)
        if receiver is not None:
            pr = to_power_w(receiver, instrument, dt)
            mean = mean - to_power_w(beam_mean_offset, instrument, dt) + to_power_w(extra_mean, instrument, dt)
            var = var + var_of_mean(pr)
        return np.where(keep, mean, 0.0), np.where(keep, np.sqrt(np.maximum(var, 0.0)), 0.0)

    out = {"column": stats(result.column[:, k]), "column_first": stats(result.column_first[:, k])}
    if result.ranges_m:
        # the beam batches' reciprocity estimates average to the same mean as the receiver batches'; the
        # reported mean is the product of the two full means, the error adds both spreads
        sb = result.scattered_beam[:, k]
        out["target"] = stats(result.target_le[:, k] + sb, result.scattered_receiver[:, k],
                              result.scattered_return[k], sb.mean(axis=0))
        out["total"] = stats(result.column[:, k] + result.target_le[:, k] + sb, result.scattered_receiver[:, k],
                             result.scattered_return[k], sb.mean(axis=0))
    else:
        out["total"] = out["column"]
    return out


def muls_power_w(instrument: Instrument, water: Water, range_m: float, reflectance: float, time_s) -> dict:
    """MULS's noise-free column (Eq. 4 with the pulse) and target echo (Eq. 7) [W] at ``time_s``.

    Returns {"column": (n,), "target": (n,), "target_energy_j": float}; the target is a flat Lambertian
    plate at normal incidence filling the beam (Eq. 11 overlap), the column is cut at the plate.
    """
    t = np.asarray(time_s, float)
    model = OpticalModel.build(instrument, water)
    column = model.column_power_w(t, cut_m=range_m)
    energy = instrument.transmitter.pulse_energy_j * float(
        target_factor(instrument, water, range_m, lambertian_weight(instrument, range_m, reflectance)))  # MULS Eq. 7
    target = energy * instrument.pulse(t - 2.0 * range_m / water.speed_m_s)
    return {"column": column, "target": target, "target_energy_j": energy}


def effective_attenuation_per_m(instrument: Instrument, range_m: float, reflectance: float, water: Water,
                                echo_energy_j: float, geometry: float = 1.0) -> float | None:
    """The two-way k of Eq. 7 that gives ``echo_energy_j`` for a flat plate at ``range_m`` [1/m].

    geometry: the exact transceiver geometry over Eq. 7's (``geometry_factor``), so that k holds the
    propagation alone; 1 uses Eq. 11's overlap as it is.
    """
    if not echo_energy_j > 0.0:
        return None
    unattenuated = instrument.transmitter.pulse_energy_j * float(target_factor(
        instrument, water.with_models(attenuation_model="c"), range_m,
        lambertian_weight(instrument, range_m, reflectance))) * math.exp(2.0 * water.attenuation_per_m * range_m)
    if not geometry * unattenuated > 0.0:  # no overlap by the exact geometry: nothing to attenuate
        return None
    return math.log(geometry * unattenuated / echo_energy_j) / (2.0 * range_m)


def geometry_factor(instrument: Instrument, ranges_m, packets: int = 100_000, seed: int = 0) -> np.ndarray:
    """(K,) echo of a flat plate in water that does not scatter, Monte Carlo over MULS Eq. 7.

    The Monte Carlo lets an aperture point see a point of the plate only within its own field of view;
    Eq. 11 counts the whole aperture once the point lies in the union of the fields (radius r_ap +
    z tan(theta_r/2)). Beyond the range where every aperture point sees the whole spot the two agree
    (to the 1/R^2 of the offset path).
    """
    clear = Water("no_scattering", 1e-9, 0.0, attenuation_model="c")
    ranges = tuple(sorted(float(r) for r in np.atleast_1d(ranges_m)))
    result = run_monte_carlo(instrument, clear, TargetPlanes(ranges, 0.1), packets=packets, seed=seed,
                             receiver_packets=BATCHES)
    eta = two_way_transmission(instrument)
    return np.array([result.target(k)[0].sum() * eta / float(target_factor(
        instrument, clear, r, lambertian_weight(instrument, r, 0.1))) for k, r in enumerate(ranges)])  # MULS Eq. 7
