"""Compiled packet transport: beam packets and their ghosts.

Free paths are drawn with the scattering coefficient b (every event scatters); absorption is the packet's
weight, exp(-a s) over a path s. Scattering angles come from the phase function's inverse CDF, the
azimuth is uniform. Packets are split into a fixed number of batches, each traced in packet order by one
thread; every packet, ghost and copy draws from a stream fixed by the seed and the packet number, so a
seed fixes the result whatever the number of threads.

Ghosts. In turbid water most of the column comes back through the forward peak of p near the aperture:
light already heading home that a small-angle scattering turns into the field of view. Packets rarely
carry it, and the few that do bring rare, large estimates. So at every scattering event of a beam packet
ghosts take over the light scattered into a wide cone around the direction to the aperture:

- **Directions** are drawn from a mixture: share ``ghost_mix`` from p, share ``ghost_wide_share`` uniform
  in the wide cone (half-angle ``ghost_wide_rad``), the rest uniform in the aiming cone (half-angle
  ``ghost_cone_fov`` tan(theta_r/2) + ``ghost_cone_aperture`` r_ap / d: a line that close to the way to
  the aperture stays in the receiver's view). Directions outside the wide cone are dropped; a ghost's
  weight is w p / (mixture density), at most w / ``ghost_mix``. (Keys of :data:`DEVICES`.)
- **How many.** An event at distance d from the aperture sends n = min(GHOST_MAX_PER_EVENT,
  max(1, floor(``ghost_length_m`` / d))) ghosts, each with 1/n of the weight: a ghost's path is about d
  long, so near events get more samples for little time, and the near field is where the column rises.
- **The packet** still scatters by p; if it goes into the wide cone it stops estimating (that share
  belongs to the ghosts) but is still traced for the energy budget and for counting.
- **A ghost** makes every estimate a packet makes, spawns no ghost, ends at the farthest target, and
  survives each scattering out of the wide cone with probability ``ghost_survival`` (Russian roulette,
  weight divided by it).
- **Splitting.** A ghost's excess is its weight over that of a ghost sent straight at the aperture from
  the same event (1 for most; about 30 for the wide cone's in the MUL's geometry, more after roulette).
  Whenever a ghost within ``split_reach_m`` of the aperture is aimed at it (inside the aiming cone) with an
  excess of 2 or more, it is split into min(floor(excess), ``split_max``) copies of equal weight, each
  traced on its own stream: the rare heavy ghost that finds the aperture no longer brings one large
  estimate but many small ones. Farther out copies would only sharpen bins more than 100 times below the
  column's peak in the turbid waters where splitting matters (8 m is 72 ns), at the cost of tracing them.

Russian roulette and splitting keep every estimator unbiased; ghosts and packets together count every
path once.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..infra.errors import ParameterError, check_fraction, check_non_negative, check_positive
from ..infra.noise import splitmix64
from ..infra.runtime import kernel
from ..water.phase_kernels import sample_angle, value_at
from .estimators import column_estimate, cones, target_hit
from .layout import (
    APERTURE_RADIUS,
    APERTURE_X,
    BEAM_RADIUS,
    BEAM_SLOPE,
    FOV_COS,
    GHOST_LENGTH,
    GHOSTS_ON,
    MIX_P,
    MIX_WIDE,
    SPLIT_MAX,
    SPLIT_REACH,
    SURVIVAL,
)
from .sampling import STREAM_KEY, angle, batch_packets, flight, packet_stream, scatter, turn, uniform

#: The variance-reduction settings (see the module doc and muls.montecarlo.estimators); every choice keeps
#: the estimators unbiased. Chosen on the pond at 10 m, where the column's error was largest: among the
#: settings tried these gave the smallest worst-bin error for the time spent (docs/multiple-scattering.md).
DEVICES = {
    "cone_apertures": 0.3,  # forward cone of the estimates: theta_c = min(cone_max_rad, cone_apertures r_ap / d)
    "cone_max_rad": 0.03,
    "ghosts": True,
    "ghost_mix": 0.5,  # share of ghost directions drawn from p
    "ghost_wide_share": 0.3,  # share drawn uniformly in the wide cone
    "ghost_wide_rad": 0.7,  # half-angle of the wide cone [rad]
    "ghost_survival": 0.2,  # Russian roulette outside the wide cone
    "ghost_cone_fov": 1.5,  # aiming cone: ghost_cone_fov tan(theta_r/2) + ghost_cone_aperture r_ap / d
    "ghost_cone_aperture": 4.0,
    "ghost_length_m": 2.0,  # ghosts per event: floor(ghost_length_m / d), at least 1
    "split_max": 32,  # most copies of one split (1: no splitting)
    "split_reach_m": 8.0,  # split only within this distance of the aperture [m] (0: anywhere)
}
#: Most ghosts one event sends.
GHOST_MAX_PER_EVENT = 16
#: Copies waiting to be traced, per batch (a split that would overflow it is made smaller).
SPLIT_STACK = 512
_SPLIT_FIELDS = 11  # x, y, z, dx, dy, dz, w, t, next plane, scatterings, excess

# Energy budget columns.
EMITTED, ABSORBED, ESCAPED_BEHIND, ESCAPED_TIME, RECEIVED, TARGET_ABSORBED = range(6)


def devices(**changes) -> dict:
    """:data:`DEVICES` with ``changes`` (e.g. ``ghosts=False``), checked; unknown keys are refused."""
    unknown = sorted(set(changes) - set(DEVICES))
    if unknown:
        raise ParameterError(f"devices: unknown key(s) {unknown}; allowed: {', '.join(DEVICES)}")
    out = DEVICES | changes
    for key in ("ghost_mix", "ghost_wide_share", "ghost_survival"):
        check_fraction(key, out[key], open_low=key == "ghost_survival")
    if out["ghost_mix"] + out["ghost_wide_share"] > 1.0:
        raise ParameterError(f"ghost_mix + ghost_wide_share = {out['ghost_mix'] + out['ghost_wide_share']!r}: "
                             "must be at most 1")
    if not 0.0 <= out["ghost_wide_rad"] <= 0.5 * math.pi:
        raise ParameterError(f"ghost_wide_rad = {out['ghost_wide_rad']!r}: must lie in [0, pi/2] rad")
    for key in ("cone_apertures", "cone_max_rad", "ghost_cone_fov", "ghost_cone_aperture"):
        check_positive(key, out[key])
    check_non_negative("ghost_length_m", out["ghost_length_m"])
    check_non_negative("split_reach_m", out["split_reach_m"])
    if isinstance(out["split_max"], bool) or int(out["split_max"]) != out["split_max"] or out["split_max"] < 1:
        raise ParameterError(f"split_max = {out['split_max']!r}: must be an integer >= 1")
    return out


def split_stack(batches: int) -> tuple[np.ndarray, np.ndarray]:
    """Empty per-batch stacks of ghost copies: (fields (B, SPLIT_STACK, 11), stream states (B, SPLIT_STACK))."""
    return np.zeros((batches, SPLIT_STACK, _SPLIT_FIELDS)), np.zeros((batches, SPLIT_STACK), np.uint64)


@kernel
def first_arrivals(state, batch, nxt, last, estimate, direct, x, y, z, dx, dy, dz, t, w, sd, sp, step, geo, water,
                   scene, times, tallies):
    """Planes nxt .. last - 1 first reached along this flight: estimate each hit (when ``estimate``).

    Returns (state, the first plane not yet reached).
    """
    a, c, speed = water[0], water[2], water[3]
    depth = scene[3]
    while nxt < last and sd > 0.0 and sp + sd * step >= depth[nxt]:
        if estimate:
            sk = max(0.0, (depth[nxt] - sp) / sd)
            state = target_hit(state, batch, nxt, x + sk * dx, y + sk * dy, z + sk * dz, t + sk / speed,
                               w * math.exp(-a * sk), direct, geo, c, speed, scene, times, tallies[2], tallies[3],
                               tallies[4])
        nxt += 1
    return state, nxt


@kernel
def ghost_path(state, batch, x, y, z, dx, dy, dz, w, t, nxt, n_scat, excess, geo, water, scene, phase, times,
               tallies, stack, top):
    """Trace one ghost (or copy) until it ends; copies it splits off are pushed on ``stack`` above ``top``.

    Returns (state, new top of the stack).
    """
    fields, states = stack
    n_planes = scene[3].shape[0]
    b, c, speed, t_end = water[1], water[2], water[3], times[4]
    aimed = False
    while True:
        state, s_free, s_time, s_exit, sd, sp = flight(state, x, y, z, dx, dy, dz, t, b, speed, t_end, scene[0])
        step = min(s_free, s_time, s_exit)
        state, nxt = first_arrivals(state, batch, nxt, n_planes, True, False, x, y, z, dx, dy, dz, t, w, sd, sp,
                                    step, geo, water, scene, times, tallies)
        if nxt >= n_planes and n_planes > 0:
            return state, top  # the farthest target: its return is estimated, the ghost ends
        if step == s_time or step == s_exit:
            return state, top
        w *= math.exp(-water[0] * step)
        x += step * dx
        y += step * dy
        z += step * dz
        t += step / speed
        n_scat += 1
        ax, ay, az, d, alpha, alpha_w, theta_c = cones(x, y, z, geo)
        state = column_estimate(state, batch, nxt, n_scat == 1, x, y, z, dx, dy, dz, w, t, theta_c, geo, c, speed,
                                phase, times, tallies[0], tallies[1])
        state, dx, dy, dz = turn(state, dx, dy, dz, phase[0])
        off = angle(dx, dy, dz, ax, ay, az)
        if off > alpha_w:
            state, v = uniform(state)
            if v >= geo[SURVIVAL]:
                return state, top
            w /= geo[SURVIVAL]
            excess /= geo[SURVIVAL]
        aimed = off <= alpha
        if aimed and excess >= 2.0 and (geo[SPLIT_REACH] == 0.0 or d < geo[SPLIT_REACH]):
            copies = min(int(excess), int(geo[SPLIT_MAX]), fields.shape[1] - top + 1)
            if copies >= 2:
                w /= copies
                excess /= copies
                for j in range(copies - 1):
                    f = fields[batch, top]
                    f[0], f[1], f[2], f[3], f[4], f[5] = x, y, z, dx, dy, dz
                    f[6], f[7], f[8], f[9], f[10] = w, t, nxt, n_scat, excess
                    states[batch, top] = splitmix64(state + np.uint64(j + 1) * STREAM_KEY)
                    top += 1


@kernel
def ghost(state, batch, x, y, z, dx, dy, dz, w, t, nxt, n_scat, excess, geo, water, scene, phase, times, tallies,
          stack):
    """Trace a ghost leaving the event (x, y, z) in direction (dx, dy, dz), and every copy it splits into."""
    fields, states = stack
    state, top = ghost_path(state, batch, x, y, z, dx, dy, dz, w, t, nxt, n_scat, excess, geo, water, scene, phase,
                            times, tallies, stack, 0)
    while top > 0:
        top -= 1
        f = fields[batch, top]
        _, top = ghost_path(states[batch, top], batch, f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], int(f[8]),
                            int(f[9]), f[10], geo, water, scene, phase, times, tallies, stack, top)
    return state


@kernel
def launch_ghosts(state, batch, x, y, z, dx, dy, dz, w, t, nxt, n_scat, geo, water, scene, phase, times, tallies,
                  stack):
    """The ghosts of a beam packet's scattering event (incident direction (dx, dy, dz), weight w)."""
    ax, ay, az, d, alpha, alpha_w, _ = cones(x, y, z, geo)
    mix, mix_wide = geo[MIX_P], geo[MIX_WIDE]
    mix_aim = 1.0 - mix - mix_wide
    q_aim = 1.0 / (2.0 * math.pi * (1.0 - math.cos(alpha)))  # uniform densities in the two cones [1/sr]
    q_wide = 1.0 / (2.0 * math.pi * (1.0 - math.cos(alpha_w)))
    n_ghosts = max(1, min(GHOST_MAX_PER_EVENT, int(geo[GHOST_LENGTH] / d)))
    # the weight of a ghost sent straight at the aperture: the reference of the excess
    p_aim = value_at(phase[1], phase[2], phase[3], angle(dx, dy, dz, ax, ay, az))
    w_aim = w * p_aim / (mix * p_aim + mix_wide * q_wide + mix_aim * q_aim) / n_ghosts
    for _ in range(n_ghosts):
        state, v1 = uniform(state)
        state, v2 = uniform(state)
        state, v3 = uniform(state)
        if v1 < mix:
            gx, gy, gz = scatter(dx, dy, dz, sample_angle(phase[0], v2), 2.0 * math.pi * v3)
        else:
            cone = alpha_w if v1 >= 1.0 - mix_wide else alpha
            gx, gy, gz = scatter(ax, ay, az, math.acos(1.0 - v2 * (1.0 - math.cos(cone))), 2.0 * math.pi * v3)
        off = angle(gx, gy, gz, ax, ay, az)
        if off <= alpha_w:
            pv = value_at(phase[1], phase[2], phase[3], angle(dx, dy, dz, gx, gy, gz))
            density = mix * pv + mix_wide * q_wide + (mix_aim * q_aim if off <= alpha else 0.0)
            w_ghost = w * pv / density / n_ghosts
            state = ghost(state, batch, x, y, z, gx, gy, gz, w_ghost, t, nxt, n_scat, w_ghost / w_aim, geo, water,
                          scene, phase, times, tallies, stack)
    return state, ax, ay, az, alpha_w


@kernel(parallel=True)
def trace_beam(seed_key, first_packet, n_packets, geo, water, scene, phase, times, tallies, stack, part):
    """Trace ``n_packets`` beam packets in ``tallies[0].shape[0]`` batches (one thread per batch, packet order).

    tallies = (column, column1, target, target_direct, hits, counted, energy), per batch (sums of packet
    weights, emitted energy 1 per packet): column (B, K+1, T), column1 (B, K+1, T): estimates of events
    before plane k is first reached (index k; K = beyond every plane), all orders and first scattering
    only; target (B, K, T), target_direct (B, K, T): unscattered-return estimate at the hits of plane k,
    all outbound orders and unscattered beam only; hits (B, K, cells, G): (rho/pi) w of the hits binned on
    the receiver grid and in time from the grid start of plane k; counted (B, T): packets that cross the
    aperture within the field of view; energy (B, 6). stack: see :func:`split_stack`. part: (start, stop), the
    packets of each batch's share this call traces (:func:`muls.montecarlo.run.in_parts`).
    """
    column, counted, energy = tallies[0], tallies[5], tallies[6]
    n, e1, e2, depth = scene[0], scene[1], scene[2], scene[3]
    reflectance = scene[8]
    n_batches = column.shape[0]
    n_planes = depth.shape[0]
    r0, slope, ap_x, ap_r, fov_cos = geo[BEAM_RADIUS], geo[BEAM_SLOPE], geo[APERTURE_X], geo[APERTURE_RADIUS], geo[
        FOV_COS]
    ghosts = geo[GHOSTS_ON] > 0.0
    a, b, c, speed = water[0], water[1], water[2], water[3]
    dt, n_t, t_end = times[0], int(times[1]), times[4]
    for batch in numba.prange(n_batches):
        lo, hi = batch_packets(batch, first_packet, n_packets, n_batches, part)
        for pid in range(lo, hi):
            state = packet_stream(seed_key, 0, pid)
            state, u1 = uniform(state)
            state, u2 = uniform(state)
            rr = math.sqrt(u1)
            ux0, uy0 = rr * math.cos(2.0 * math.pi * u2), rr * math.sin(2.0 * math.pi * u2)
            x, y, z = r0 * ux0, r0 * uy0, 0.0
            norm = 1.0 / math.sqrt(1.0 + slope * slope * rr * rr)
            dx, dy, dz = slope * ux0 * norm, slope * uy0 * norm, norm
            w, t = 1.0, 0.0
            n_scat = 0
            nxt = 0  # first plane not yet reached; n_planes + 1 once reflected
            estimating = True  # False once the packet's share went to the ghosts
            energy[batch, EMITTED] += 1.0
            while True:
                state, s_free, s_time, s_exit, sd, sp = flight(state, x, y, z, dx, dy, dz, t, b, speed, t_end, n)
                s_plane = (depth[n_planes - 1] - sp) / sd if (n_planes > 0 and sd > 0.0) else math.inf
                step = min(s_free, s_time, s_exit, s_plane)
                # first arrivals at the nearer planes (scenes with a nearer target) along this step
                state, nxt = first_arrivals(state, batch, nxt, n_planes - 1, estimating, n_scat == 0, x, y, z, dx,
                                            dy, dz, t, w, sd, sp, step, geo, water, scene, times, tallies)
                w_new = w * math.exp(-a * step)
                energy[batch, ABSORBED] += w - w_new
                w = w_new
                x += step * dx
                y += step * dy
                z += step * dz
                t += step / speed
                if step == s_time:
                    energy[batch, ESCAPED_TIME] += w
                    break
                if step == s_exit:
                    ex, ey = x - ap_x, y
                    if ex * ex + ey * ey <= ap_r * ap_r and -dz >= fov_cos:
                        energy[batch, RECEIVED] += w
                        i = int(t / dt)
                        if i < n_t:
                            counted[batch, i] += w
                    else:
                        energy[batch, ESCAPED_BEHIND] += w
                    break
                if step == s_plane:
                    k = n_planes - 1
                    if estimating:  # the farthest target: every hit is estimated (multiple bounces)
                        state = target_hit(state, batch, k, x, y, z, t, w, n_scat == 0 and nxt <= k, geo, c, speed,
                                           scene, times, tallies[2], tallies[3], tallies[4])
                    nxt = n_planes + 1  # reflected: later events make no column estimate
                    energy[batch, TARGET_ABSORBED] += w * (1.0 - reflectance)
                    w *= reflectance
                    state, v1 = uniform(state)
                    state, v2 = uniform(state)
                    st, ct = math.sqrt(v1), math.sqrt(1.0 - v1)  # Lambertian: cosine-weighted about n
                    cp, sp2 = math.cos(2.0 * math.pi * v2), math.sin(2.0 * math.pi * v2)
                    dx = st * cp * e1[0] + st * sp2 * e2[0] + ct * n[0]
                    dy = st * cp * e1[1] + st * sp2 * e2[1] + ct * n[1]
                    dz = st * cp * e1[2] + st * sp2 * e2[2] + ct * n[2]
                    continue
                # scattering event
                n_scat += 1
                in_x, in_y, in_z = dx, dy, dz
                state, dx, dy, dz = turn(state, dx, dy, dz, phase[0])
                if estimating and nxt <= n_planes:
                    state = column_estimate(state, batch, nxt, n_scat == 1, x, y, z, in_x, in_y, in_z, w, t,
                                            cones(x, y, z, geo)[6], geo, c, speed, phase, times, column, tallies[1])
                    if ghosts:
                        state, ax, ay, az, alpha_w = launch_ghosts(state, batch, x, y, z, in_x, in_y, in_z, w, t, nxt,
                                                                   n_scat, geo, water, scene, phase, times, tallies,
                                                                   stack)
                        if angle(dx, dy, dz, ax, ay, az) <= alpha_w:
                            estimating = False  # this share of the light belongs to the ghosts
