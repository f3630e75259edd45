"""Compiled plane-parallel transport: a homogeneous water below a level air-water surface, lit by the sun.

The lidar's transport (:mod:`.transport`) without its instrument: the same free paths (drawn with the
scattering coefficient b, :func:`.sampling.free_path`), the same absorption (the packet's weight,
exp(-a s) over a path s), the same scattering angles (the phase function's inverse CDF,
:func:`.sampling.turn`) and the same per-packet random streams and batches. What differs is the boundary
and the tallies, so that the transport core can be run on the canonical problems of Mobley et al. (1993)
(:mod:`.mobley1993`):

- **The sun.** A collimated beam of irradiance E_perp on a plane normal to it, at zenith angle theta_s. The
  surface reflects the Fresnel share R(theta_s) of it (unpolarised) and refracts the rest to the angle
  theta_w = asin(sin theta_s / n). Every packet starts just below the surface along that direction, with
  weight 1 standing for the transmitted irradiance E_perp cos(theta_s) (1 - R(theta_s)) on the horizontal.
- **The surface** is level. A packet that reaches it from below leaves the share 1 - R(theta) to the air
  (escaped) and goes on, reflected, with weight w R(theta); beyond the critical angle R = 1. No packet is
  lost to a random choice there.
- **Depth.** The water is homogeneous. It ends at a black bottom (``bottom_m``) chosen deep enough that the
  light it fails to send back is negligible at the tallied depths (the caller says how deep).
- **Roulette.** A packet whose weight falls below ``roulette`` times the unscattered beam's weight at its depth,
  exp(-c z / cos theta_w), survives with probability ROULETTE_SURVIVAL and its weight is divided by it; its
  expectation, and so every estimate, is unchanged.
- **Orders.** A run may stop every packet at its scattering number ``max_orders`` + 1, before that event
  makes any estimate: the tallies are then the light scattered at most ``max_orders`` times (0: the
  unscattered sun alone), which the tests compare with closed forms.

Tallies at each depth z_k (per packet, times the transmitted irradiance they stand for):

- **Ed, Eu** (plane irradiances, down and up): each crossing of the plane z_k adds the weight there.
- **Eod, Eou** (scalar irradiances): each crossing adds w / |cos theta|, theta the angle from the vertical.
  Crossings closer to horizontal than MU_CUT add 2 w / MU_CUT, the mean of w / |cos theta| over
  [0, MU_CUT] for a radiance that is flat there (the usual cosine cut-off of a surface-crossing fluence
  estimator); without it the estimator's variance is infinite.
- **Lu** (nadir-viewing radiance: light travelling straight up): a local estimate at every scattering event
  below z_k, w p(Theta) exp(-c (z - z_k)), Theta the angle between the packet's direction before the event
  and the zenith. Within CONE_RAD of the zenith p is replaced by its mean over that cone, F(CONE_RAD) /
  (2 pi (1 - cos CONE_RAD)), which bounds the estimate where Petzold's p reaches 10^3-10^4 per sr; the bias
  is second order in how much the radiance varies across the cone.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numba
import numpy as np

from ..infra.errors import ParameterError, check_fraction, check_non_negative, check_positive
from ..infra.runtime import kernel
from ..water.phase import PhaseFunction, check_phase
from ..water.phase_kernels import cumulative_at, value_at
from .run import BATCHES, check_packets, in_parts, seed_key, var_of_mean
from .sampling import angle, batch_packets, free_path, packet_stream, turn, uniform

#: Crossings closer to horizontal than this cosine count as 2 / MU_CUT in the scalar irradiances.
MU_CUT = 0.01
#: The cone around the zenith [rad] over which Lu's local estimate uses the mean of p (5.7 deg). Cones of 0.03
#: and 0.2 rad gave the same Lu within 0.5-1.6 % errors (docs/multiple-scattering.md).
CONE_RAD = 0.1
#: Probability that a packet below the roulette threshold survives.
ROULETTE_SURVIVAL = 0.1
#: The random streams of the plane-parallel runs (0 and 1 are the lidar's beam and receiver).
STREAM = 2

# Tally rows (per depth) and energy budget columns.
ED, EU, EOD, EOU, LU = range(5)
TALLIES = ("Ed", "Eu", "Eod", "Eou", "Lu")
TRANSMITTED, ABSORBED, ESCAPED, BOTTOM, ROULETTE, STOPPED = range(6)
ENERGY_KEYS = ("transmitted", "absorbed_by_water", "escaped_through_surface", "passed_bottom", "roulette_net",
               "stopped_at_max_orders")


@kernel
def fresnel_reflectance(cos_i, n_ratio):
    """Unpolarised Fresnel reflectance at incidence cosine ``cos_i`` from index n1 into n2 = ``n_ratio`` n1
    (1 beyond the critical angle)."""
    sin_t2 = (1.0 - cos_i * cos_i) / (n_ratio * n_ratio)
    if sin_t2 >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin_t2)
    rs = (cos_i - n_ratio * cos_t) / (cos_i + n_ratio * cos_t)  # Fresnel, s-polarised amplitude
    rp = (n_ratio * cos_i - cos_t) / (n_ratio * cos_i + cos_t)  # Fresnel, p-polarised amplitude
    return 0.5 * (rs * rs + rp * rp)


@kernel(inline="always")
def _cross(tallies, batch, depths, z, dz, step, w, a):
    """Add the plane crossings of the flight from depth z along cosine dz over ``step`` [m] (weight w at z)."""
    z_end = z + step * dz
    for k in range(depths.shape[0]):
        zk = depths[k]
        if dz > 0.0 and z < zk <= z_end:
            wk = w * math.exp(-a * (zk - z) / dz)
            tallies[batch, ED, k] += wk
            tallies[batch, EOD, k] += wk / dz if dz >= MU_CUT else 2.0 * wk / MU_CUT
        elif dz < 0.0 and z_end <= zk < z:
            wk = w * math.exp(-a * (z - zk) / -dz)
            tallies[batch, EU, k] += wk
            tallies[batch, EOU, k] += wk / -dz if -dz >= MU_CUT else 2.0 * wk / MU_CUT


@kernel(parallel=True)
def trace_slab(seed_key, stream, n_packets, mu_w, a, b, n_water, depths, bottom_m, roulette, max_orders, phase, tallies,
               energy, part):
    """Trace ``n_packets`` packets of the refracted sun in ``tallies.shape[0]`` batches (one thread per batch).

    mu_w: cosine of the refracted sun's angle from the nadir; a, b [1/m]; n_water: refractive index of the
    water (the air's is 1); depths: (K,) ascending tally depths [m], > 0; bottom_m: depth of the black bottom
    [m]; roulette: the threshold over exp(-c z / mu_w); max_orders: the most scatterings a packet undergoes
    (-1: no limit); phase = (sampling table, ln p table, ln theta of its first point, 1 / its step).
    tallies (B, 5, K): sums over each batch's packets of the rows ED .. LU (weights, not yet divided by the
    packets); energy (B, 6): the budget columns TRANSMITTED .. STOPPED. part: (start, stop), the packets of each
    batch's share this call traces (:func:`muls.montecarlo.run.in_parts`).
    """
    n_batches = tallies.shape[0]
    n_k = depths.shape[0]
    c = a + b
    sample, ln_p, ln_theta0, inv_step = phase
    cap = cumulative_at(sample, CONE_RAD) / (2.0 * math.pi * (1.0 - math.cos(CONE_RAD)))
    sin_w = math.sqrt(max(0.0, 1.0 - mu_w * mu_w))
    for batch in numba.prange(n_batches):
        lo, hi = batch_packets(batch, 0, n_packets, n_batches, part)
        for pid in range(lo, hi):
            state = packet_stream(seed_key, stream, pid)
            z, dx, dy, dz = 0.0, sin_w, 0.0, mu_w
            w = 1.0
            n_scat = 0
            energy[batch, TRANSMITTED] += 1.0
            while True:
                state, s_free = free_path(state, b)
                s_surface = -z / dz if dz < 0.0 else math.inf
                s_bottom = (bottom_m - z) / dz if dz > 0.0 else math.inf
                step = min(s_free, s_surface, s_bottom)
                _cross(tallies, batch, depths, z, dz, step, w, a)
                if step == math.inf:  # b = 0: straight down for ever, all of it absorbed
                    energy[batch, ABSORBED] += w
                    break
                w_new = w * math.exp(-a * step)
                energy[batch, ABSORBED] += w - w_new
                w = w_new
                if step == s_bottom:
                    energy[batch, BOTTOM] += w
                    break
                if step == s_surface:  # the level surface: the Fresnel share leaves, the rest turns down
                    z = 0.0
                    r = fresnel_reflectance(-dz, 1.0 / n_water)
                    energy[batch, ESCAPED] += w * (1.0 - r)
                    w *= r
                    dz = -dz
                    continue
                z += step * dz
                n_scat += 1
                if n_scat > max_orders >= 0:
                    energy[batch, STOPPED] += w
                    break
                # a scattering event: the nadir radiance it sends up to each shallower depth (local estimate)
                theta = angle(dx, dy, dz, 0.0, 0.0, -1.0)
                p = cap if theta < CONE_RAD else value_at(ln_p, ln_theta0, inv_step, theta)
                for k in range(n_k):
                    if depths[k] < z:
                        tallies[batch, LU, k] += w * p * math.exp(-c * (z - depths[k]))
                state, dx, dy, dz = turn(state, dx, dy, dz, sample)
                if w < roulette * math.exp(-c * z / mu_w):
                    state, v = uniform(state)
                    if v >= ROULETTE_SURVIVAL:
                        energy[batch, ROULETTE] += w
                        break
                    energy[batch, ROULETTE] -= w * (1.0 / ROULETTE_SURVIVAL - 1.0)
                    w /= ROULETTE_SURVIVAL


def empty_tallies(batches: int, depths: int) -> tuple[np.ndarray, np.ndarray]:
    """Zeroed (tallies (batches, 5, depths), energy (batches, 6)) for :func:`trace_slab`."""
    return np.zeros((batches, len(TALLIES), depths)), np.zeros((batches, len(ENERGY_KEYS)))


#: How far below the deepest tallied depth the black bottom lies, in optical depths c z. The light it fails to
#: send back up there is of order exp(-2 k_inf 40) of the upwelling light, k_inf the asymptotic diffuse
#: attenuation over c: 4e-7 for k_inf = 0.18, the smallest of Mobley et al. (1993) Table 7.
BOTTOM_MARGIN_TAU = 40.0
#: Roulette threshold, over the unscattered beam's weight at the packet's depth (see the module doc).
ROULETTE_THRESHOLD = 1e-4


@dataclass(frozen=True)
class SlabResult:
    """Light field of one plane-parallel run, per depth, for an irradiance E_perp = 1 normal to the sun.

    depths_m: (K,) tally depths [m]; mean, sigma: dicts of :data:`TALLIES` names to (K,) estimates and their
    standard errors (from the spread of the batches): irradiances Ed, Eu, Eod, Eou [W m^-2 nm^-1] and the
    nadir-viewing radiance Lu [W m^-2 sr^-1 nm^-1] per W m^-2 nm^-1 of E_perp; per_batch: (B, 5, K) each
    batch's estimate of them (rows in the order of :data:`TALLIES`). energy: the budget as shares of
    the irradiance on the surface, E_perp cos(theta_s): ``reflected_by_surface`` (the sun's specular share),
    then the transmitted share and where it went (:data:`ENERGY_KEYS`); they close to rounding. energy_sigma:
    the standard errors of the :data:`ENERGY_KEYS` shares.
    """

    depths_m: np.ndarray
    mean: dict
    sigma: dict
    per_batch: np.ndarray
    energy: dict
    energy_sigma: dict
    packets: int
    seconds: float
    settings: dict = field(default_factory=dict)


def run_slab(phase: str | PhaseFunction, albedo: float, depths_m, attenuation_per_m: float = 1.0,
             sun_zenith_deg: float = 60.0, water_index: float = 1.34, packets: int = 1_000_000, seed: int = 0,
             batches: int = BATCHES, stream: int = STREAM, bottom_m: float | None = None,
             roulette: float = ROULETTE_THRESHOLD, max_orders: int | None = None) -> SlabResult:
    """Trace ``packets`` packets of the sun through a homogeneous water of single-scattering albedo ``albedo``
    (a = (1 - albedo) c, b = albedo c, c = ``attenuation_per_m``) under a level surface, and tally the light
    field at ``depths_m`` (ascending, > 0 [m]). phase: a :class:`muls.water.phase.PhaseFunction` or its name;
    bottom_m: the black bottom [m] (default :data:`BOTTOM_MARGIN_TAU` / c below the deepest depth); stream: the
    random stream (runs on different streams are independent); max_orders: count only light scattered at
    most that many times (None: all orders). Packets are rounded up to a multiple of ``batches``."""
    phase = check_phase(phase)
    check_fraction("albedo", albedo)
    check_positive("attenuation_per_m", attenuation_per_m)
    if not 0.0 <= sun_zenith_deg < 90.0:
        raise ParameterError(f"sun_zenith_deg = {sun_zenith_deg!r}: must lie in [0, 90) deg")
    if not (math.isfinite(water_index) and water_index >= 1.0):
        raise ParameterError(f"water_index = {water_index!r}: must be a number >= 1")
    depths = np.atleast_1d(np.asarray(depths_m, float))
    if depths.size == 0 or not np.all(np.isfinite(depths)) or depths[0] <= 0.0 or np.any(np.diff(depths) <= 0.0):
        raise ParameterError(f"depths_m = {depths.tolist()!r}: must be finite, > 0 and strictly ascending [m]")
    if isinstance(batches, bool) or int(batches) != batches or batches < 2:
        raise ParameterError(f"batches = {batches!r}: must be an integer >= 2")
    batches = int(batches)
    check_packets("packets", packets, batches)
    packets = -(-int(packets) // batches) * batches
    c = float(attenuation_per_m)
    bottom = depths[-1] + BOTTOM_MARGIN_TAU / c if bottom_m is None else float(bottom_m)
    if not bottom > depths[-1]:
        raise ParameterError(f"bottom_m = {bottom_m!r}: must lie below the deepest depth {depths[-1]:g} m")
    check_non_negative("roulette", roulette)
    if max_orders is not None and (isinstance(max_orders, bool) or int(max_orders) != max_orders or max_orders < 0):
        raise ParameterError(f"max_orders = {max_orders!r}: must be None or an integer >= 0")

    mu_s = math.cos(math.radians(sun_zenith_deg))
    mu_w = math.sqrt(1.0 - (1.0 - mu_s * mu_s) / water_index**2)  # Snell: sin(theta_w) = sin(theta_s) / n
    transmitted = 1.0 - float(fresnel_reflectance(mu_s, water_index))
    ln_p, ln_theta0, inv_step = phase.log_table
    tallies, energy = empty_tallies(batches, depths.size)
    t0 = time.perf_counter()
    in_parts(lambda part: trace_slab(seed_key(seed), int(stream), packets, mu_w, (1.0 - albedo) * c, albedo * c,
                                     float(water_index), depths, bottom, float(roulette),
                                     -1 if max_orders is None else int(max_orders),
                                     (phase.sample_theta_rad, ln_p, ln_theta0, inv_step), tallies, energy, part),
             packets // batches)
    seconds = time.perf_counter() - t0

    scale = mu_s * transmitted / (packets // batches)  # a packet stands for the transmitted E_perp cos T
    estimates = tallies * scale  # (B, 5, K): each batch's estimate
    mean = {name: estimates[:, i].mean(axis=0) for i, name in enumerate(TALLIES)}
    sigma = {name: np.sqrt(var_of_mean(estimates[:, i])) for i, name in enumerate(TALLIES)}
    budget = energy.sum(axis=0) / packets * transmitted
    budget_sigma = np.sqrt(var_of_mean(energy / (packets // batches) * transmitted))
    return SlabResult(
        depths_m=depths, mean=mean, sigma=sigma, per_batch=estimates,
        energy={"reflected_by_surface": 1.0 - transmitted, **{k: float(v) for k, v in zip(ENERGY_KEYS, budget)}},
        energy_sigma={k: float(v) for k, v in zip(ENERGY_KEYS, budget_sigma)},
        packets=packets, seconds=seconds,
        settings={"phase": phase.name, "albedo": float(albedo), "attenuation_per_m": c,
                  "sun_zenith_deg": float(sun_zenith_deg), "water_index": float(water_index), "seed": int(seed),
                  "stream": int(stream), "batches": batches, "bottom_m": bottom, "roulette": float(roulette),
                  "max_orders": max_orders},
    )
