"""A semi-analytic Monte Carlo reference for the lidar return: multiple scattering, exact transceiver geometry.

MULS, like every lidar-equation model, counts single scattering only (Eqs. 4 and 7) and folds forward
scattering into an attenuation coefficient (Eq. 6). This module traces photon packets through the water
instead, with the instrument's own beam, aperture, offset and field of view, and says where the lidar
equation holds and by how much it misses.

Packets and estimators
----------------------
- **Beam.** A packet starts on the exit pupil (a disc of the beam diameter at z = 0) and leaves along a ray
  of the diverging beam: the point (x, y) = r0 (ux, uy) of the unit disc leaves with slope tan(theta_t/2)
  (ux, uy), so the spot at range z is a uniform disc of radius r0 + z tan(theta_t/2), as Eq. 11 assumes.
- **Transport.** Free paths are drawn with the scattering coefficient b (every event scatters) and
  absorption is the packet's weight, exp(-a s) over a path s. Scattering angles come from a tabulated,
  normalised phase function (:mod:`muls.phase`) by inverse CDF, the azimuth is uniform.
- **Column: local estimate at every scattering event** before the packet first reaches the target:
  w p(Theta) A cos(theta_r) / d^2 exp(-c d) towards a point q of the receiver aperture, when the event lies
  in the field of view of q (a cone of full angle ``fov_full_rad`` around +z). q is drawn uniformly on the
  smaller of two discs (the aperture, or the disc of aperture points whose field contains the event) and A
  is that disc's area; the estimate is then bounded by pi tan^2(theta_r/2), which keeps its variance finite
  next to the window. With one first scattering this is MULS Eq. 4 with c as the attenuation.
- **Target, unscattered return: local estimate at the hit** of a Lambertian plane (reflectance rho, range,
  tilt): w (rho/pi) cos(theta_e) A cos(theta_r) / d^2 exp(-c d), theta_e the angle of the receiver from
  the plane's normal (for a lidar it equals the incidence angle of Eq. 7). With an unscattered beam this is
  Eq. 7 with c.
- **Target, scattered return: reciprocity.** Light that scatters on its way back is most of the echo in
  turbid water (through b z = 12 the unscattered return is 10^-6 of it), and estimating it from reflected
  packets would need each of them to find the receiver. Instead a second set of packets leaves the receiver
  (uniform over its aperture, uniform in projected solid angle within its field of view, total weight its
  etendue A pi sin^2(theta_r/2)) and the scattered ones are tallied where they first reach the target: this
  is the receiver's field E_R(x, t2) (a radial grid around the receiver axis, x sectors when the plane is
  tilted). By reciprocity a Lambertian patch of radiance L delivers L E_R dA to the detector, so every beam
  hit adds w (rho/pi) E_R(x, t - t1). Beam hits are binned on the same grid and convolved in time.
- **Counting.** A packet that crosses the aperture plane inside the aperture and within the field of view
  is counted as received: a second estimator of the same signal (tested against the others).

After a target hit the packet goes on, reflected into a cosine-weighted direction with weight rho w
(w (1 - rho) is absorbed by the target); its later scattering makes no local estimate, because the
reciprocity estimator already holds the scattered return, and a second hit of the target is estimated again
(multiple bounces, for the farthest target only, see below). The half-space behind the instrument (z < 0) is
not simulated: light that crosses the plane z = 0 outside the aperture has escaped. Energy is booked as
emitted = absorbed (water) + escaped (behind the instrument, or alive at the end of the time window) +
received (counted) + absorbed by the target, to rounding.

Several target ranges in one run
--------------------------------
A packet's path is the same in every scene until it first reaches the target's plane, so one run serves
parallel planes at several ranges: each plane records the first arrival of every packet (beam and
receiver), the column of the scene with the target at range R_k keeps the events before the packet first
reached plane k, and the packet is reflected only by the farthest plane. Energy bookkeeping, counting and
multiple bounces describe that farthest scene.

Randomness and errors
---------------------
Every packet draws from its own counter-based stream (SplitMix64 of seed, stream and packet number), and
packets are split into a fixed number of batches, each traced in packet order by one thread: a seed fixes
the result bit for bit whatever the number of threads. The standard error of every time bin comes from the
spread of the batch estimates (beam batches, plus receiver batches for the scattered return).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numba
import numpy as np
from scipy.signal import fftconvolve

from . import radiometry
from .errors import ParameterError, check_fraction, check_positive
from .instrument import Instrument
from .noise import GAMMA, splitmix64
from .phase import PhaseFunction, check_phase, sample_angle, value_at
from .presets import instrument_preset, water_preset
from .radiometry import lambertian_weight, target_factor
from .studies import maxrange_study
from .water import Water
from .waveform import OpticalModel

# ----------------------------------------------------------------------------------------------------------
# Settings

#: Time step of the Monte Carlo histograms [s] (the digitiser samples at 1 ns).
TIME_STEP_S = 0.5e-9
#: Time step of the reciprocity grids (beam hits, receiver field) [s].
GRID_TIME_STEP_S = 1e-9
#: How long after the farthest echo starts the simulation runs [s]: the echo's multiply scattered tail.
TAIL_S = 150e-9
#: Statistical batches (beam and receiver packets each): standard errors come from their spread.
BATCHES = 20
#: Receiver packets are this fraction of the beam packets by default: the scattered return they estimate
#: is smooth, and its error is then well below the column's.
RECEIVER_SHARE = 4
#: Radial grid of the receiver field on a target plane: this many equal rings out to twice the receiver
#: footprint plus the offset, then rings growing by RING_GROWTH out to OUTER_RANGE_FACTOR x range + 1 m.
INNER_RINGS = 60
RING_GROWTH = 1.12
OUTER_RANGE_FACTOR = 1.5
#: Azimuth sectors of that grid when the target is tilted (the field is then not round).
TILTED_SECTORS = 12
MAX_TILT_RAD = math.radians(60.0)
#: Forward cone of the local estimates: at an event, directions within
#: theta_c = min(CONE_MAX_RAD, CONE_APERTURES x aperture radius / distance to the aperture) of the incident
#: direction are left to counting (the packet or ghost is counted if its next flight lands in the aperture
#: within the field of view), because the forward peak of p (10^3 to 10^10 per sr below 0.1 deg) would
#: give rare, huge estimates. The split is exact: together the two cover every direction once.
CONE_APERTURES = 0.3
CONE_MAX_RAD = 0.03
#: Ghosts (see _trace_beam): the cone towards the aperture has the half-angle
#: GHOST_CONE_FOV tan(theta_r/2) + GHOST_CONE_APERTURE r_ap / d (a line within tan(theta_r/2) + r_ap / d of
#: the way to the aperture stays in the receiver's view all along); a ghost's direction is drawn from p
#: with probability GHOST_MIX and uniformly in the cone otherwise; once no longer aimed at the aperture a
#: ghost survives each scattering with probability GHOST_SURVIVAL (Russian roulette). Chosen on the pond
#: at 10 m: of the settings tried, these gave the smallest error of the column for the time spent.
GHOST_MIX = 0.5
GHOST_SURVIVAL = 0.2
GHOST_CONE_FOV = 1.5
GHOST_CONE_APERTURE = 4.0

# Energy budget columns.
EMITTED, ABSORBED, ESCAPED_BEHIND, ESCAPED_TIME, RECEIVED, TARGET_ABSORBED = range(6)
ENERGY_KEYS = ("emitted", "absorbed_by_water", "escaped_behind_instrument", "escaped_time_window",
               "received_counted", "absorbed_by_target")


# ----------------------------------------------------------------------------------------------------------
# Counter-based random numbers: one SplitMix64 stream per packet.

_STREAM = np.uint64(0xD1B54A32D192ED03)
_INV53 = 1.0 / 9007199254740992.0


@numba.njit(cache=True, inline="always")
def _stream(seed_key, stream, packet):
    """Initial state of packet ``packet`` of stream ``stream`` (0 beam, 1 receiver)."""
    return splitmix64(seed_key ^ splitmix64(np.uint64(packet) * GAMMA + np.uint64(stream) * _STREAM))


@numba.njit(cache=True, inline="always")
def _uniform(state):
    """(next state, uniform in [0, 1))."""
    state = state + GAMMA
    return state, float(splitmix64(state) >> np.uint64(11)) * _INV53


# ----------------------------------------------------------------------------------------------------------
# Geometry helpers


@numba.njit(cache=True, inline="always")
def _scatter(ux, uy, uz, theta, phi):
    """Direction turned by polar angle ``theta`` and azimuth ``phi`` from the unit vector (ux, uy, uz)."""
    st, ct = math.sin(theta), math.cos(theta)
    sp, cp = math.sin(phi), math.cos(phi)
    if abs(uz) > 1.0 - 1e-12:
        return st * cp, st * sp, ct if uz > 0.0 else -ct
    tmp = math.sqrt(1.0 - uz * uz)
    nx = st * (ux * uz * cp - uy * sp) / tmp + ux * ct
    ny = st * (uy * uz * cp + ux * sp) / tmp + uy * ct
    nz = -st * cp * tmp + uz * ct
    norm = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    return nx * norm, ny * norm, nz * norm


@numba.njit(cache=True, inline="always")
def _angle(ax, ay, az, bx, by, bz):
    """Angle [rad] between two vectors (atan2 of |a x b| and a . b: exact at small angles)."""
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    return math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz)


@numba.njit(cache=True)
def _aperture_point(state, px, py, pz, ap_x, ap_r, fov_tan):
    """A point q of the aperture that sees (px, py, pz) within its field of view, and the area it stands for.

    The aperture points whose field contains the point form a disc of radius pz tan(theta_r/2) around
    (px, py); q is drawn on the smaller of that disc and the aperture, and kept if it lies in the other.
    Returns (state, area [m^2] or 0 when q does not see the point, qx, qy).
    """
    rf = pz * fov_tan
    dx, dy = px - ap_x, py
    if dx * dx + dy * dy > (rf + ap_r) * (rf + ap_r):
        return state, 0.0, 0.0, 0.0
    state, u1 = _uniform(state)
    state, u2 = _uniform(state)
    rr = math.sqrt(u1)
    ca, sa = math.cos(2.0 * math.pi * u2), math.sin(2.0 * math.pi * u2)
    if rf < ap_r:
        qx, qy = px + rf * rr * ca, py + rf * rr * sa
        ex, ey = qx - ap_x, qy
        if ex * ex + ey * ey > ap_r * ap_r:
            return state, 0.0, 0.0, 0.0
        return state, math.pi * rf * rf, qx, qy
    qx, qy = ap_x + ap_r * rr * ca, ap_r * rr * sa
    ex, ey = qx - px, qy - py
    if ex * ex + ey * ey > rf * rf:
        return state, 0.0, 0.0, 0.0
    return state, math.pi * ap_r * ap_r, qx, qy


@numba.njit(cache=True)
def _grid_cell(k, x, y, z, origin, e1, e2, edges, n_phi):
    """Index of the receiver-field cell of plane k holding the point (x, y, z) of that plane, or -1."""
    rx, ry, rz = x - origin[k, 0], y - origin[k, 1], z - origin[k, 2]
    u = rx * e1[0] + ry * e1[1] + rz * e1[2]
    v = rx * e2[0] + ry * e2[1] + rz * e2[2]
    r = math.sqrt(u * u + v * v)
    n_r = edges.shape[1] - 1
    if r >= edges[k, n_r]:
        return -1
    lo, hi = 0, n_r
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if edges[k, mid] <= r:
            lo = mid
        else:
            hi = mid
    if n_phi == 1:
        return lo
    f = (math.atan2(v, u) + math.pi) / (2.0 * math.pi)
    j = min(int(f * n_phi), n_phi - 1)
    return lo * n_phi + j


# ----------------------------------------------------------------------------------------------------------
# Kernels. ``geo`` = (beam radius, beam slope, aperture x, aperture radius, tan and cos of the half field of
# view, CONE_APERTURES, CONE_MAX_RAD, ghosts on (1) or off (0), GHOST_MIX, GHOST_SURVIVAL, GHOST_CONE_FOV,
# unused, GHOST_CONE_APERTURE); ``water`` = (a, b, c, speed); plane normal ``n`` (towards the
# instrument), in-plane axes e1, e2, penetration depth S_k = -n . P_k of each plane (ascending), grid
# origins (K, 3), ring edges (K, n_r + 1); ``times`` = (histogram step, histogram length, grid step, grid
# length, end of the run). Tallies are per batch; see _trace_beam.


@numba.njit(cache=True, inline="always")
def _cones(x, y, z, geo):
    """At an event (x, y, z): the unit vector to the aperture centre, the ghost cone's half-angle and theta_c.

    theta_c: the forward cone of the local estimate (CONE_*); the ghost cone: GHOST_CONE_*.
    """
    ex, ey, ez = geo[2] - x, -y, -z
    d = math.sqrt(ex * ex + ey * ey + ez * ez)
    theta_c = min(geo[7], geo[6] * geo[3] / d)
    alpha = min(0.5 * math.pi, geo[11] * geo[4] + geo[13] * geo[3] / d)
    return ex / d, ey / d, ez / d, alpha, theta_c


@numba.njit(cache=True)
def _column_estimate(state, batch, world, first_order, x, y, z, dx, dy, dz, w, t, theta_c, geo, c, speed,
                     ln_p, ln_theta0, inv_step, dt, n_t, column, column1):
    """Local estimate of a scattering event towards the aperture, for directions beyond theta_c."""
    state, area, qx, qy = _aperture_point(state, x, y, z, geo[2], geo[3], geo[4])
    if area > 0.0:
        vx, vy, vz = qx - x, qy - y, -z
        d = math.sqrt(vx * vx + vy * vy + vz * vz)
        theta = _angle(dx, dy, dz, vx, vy, vz)
        if theta >= theta_c:
            # local estimate: w p(Theta) A cos(theta_r) / d^2 exp(-c d) (MULS Eq. 4 for one event)
            est = w * value_at(ln_p, ln_theta0, inv_step, theta) * area * (z / d) / (d * d) * math.exp(-c * d)
            i = int((t + d / speed) / dt)
            if i < n_t:
                column[batch, world, i] += est
                if first_order:
                    column1[batch, world, i] += est
    return state


@numba.njit(cache=True)
def _target_hit(state, batch, k, x, y, z, t, w, direct, geo, c, speed, n, e1, e2, origin, edges, n_phi,
                grid_start, reflectance, dt, n_t, gdt, n_g, target, target_direct, hits):
    """Estimates at a packet's hit of plane k: unscattered return, and the hit binned for reciprocity."""
    state, area, qx, qy = _aperture_point(state, x, y, z, geo[2], geo[3], geo[4])
    if area > 0.0:
        vx, vy, vz = qx - x, qy - y, -z
        d = math.sqrt(vx * vx + vy * vy + vz * vz)
        cos_e = (n[0] * vx + n[1] * vy + n[2] * vz) / d
        if cos_e > 0.0:
            # Lambertian local estimate: w (rho/pi) cos(theta_e) A cos(theta_r) / d^2 exp(-c d) (MULS Eq. 7)
            est = w * reflectance / math.pi * cos_e * area * (z / d) / (d * d) * math.exp(-c * d)
            i = int((t + d / speed) / dt)
            if i < n_t:
                target[batch, k, i] += est
                if direct:
                    target_direct[batch, k, i] += est
    cell = _grid_cell(k, x, y, z, origin, e1, e2, edges, n_phi)
    j = int(math.floor((t - grid_start[k]) / gdt))
    if cell >= 0 and 0 <= j < n_g:
        hits[batch, k, cell, j] += w * reflectance / math.pi
    return state


@numba.njit(cache=True)
def _ghost(state, batch, x, y, z, dx, dy, dz, w, t, nxt, n_scat, in_x, in_y, in_z, theta_c, geo, water, n, e1,
           e2, depth, origin, edges, n_phi, grid_start, reflectance, sample_theta, ln_p, ln_theta0, inv_step,
           times, column, column1, target, target_direct, hits):
    """Trace a ghost: the share of a scattering event's light sent towards the aperture (see _trace_beam).

    It starts at the event (x, y, z) in direction (dx, dy, dz) with weight w, and makes every estimate a
    packet makes, spawns no ghost, stops at the farthest plane, and plays Russian roulette once it is no
    longer aimed at the aperture. Its first flight counts only within theta_c of the event's incident
    direction (in_x, in_y, in_z): the event's local estimate holds the rest.
    """
    n_planes = depth.shape[0]
    a, b, c, speed = water[0], water[1], water[2], water[3]
    dt, n_t, gdt, n_g, t_end = times[0], int(times[1]), times[2], int(times[3]), times[4]
    ev_x, ev_y, ev_z = x, y, z
    world = nxt
    while True:
        state, u = _uniform(state)
        s_free = -math.log(1.0 - u) / b if b > 0.0 else math.inf
        s_time = (t_end - t) * speed
        s_exit = -z / dz if dz < 0.0 else math.inf
        sd = -(n[0] * dx + n[1] * dy + n[2] * dz)
        sp = -(n[0] * x + n[1] * y + n[2] * z)
        step = min(s_free, s_time, s_exit)
        while nxt < n_planes and sd > 0.0 and sp + sd * step >= depth[nxt]:
            sk = max(0.0, (depth[nxt] - sp) / sd)
            state = _target_hit(state, batch, nxt, x + sk * dx, y + sk * dy, z + sk * dz, t + sk / speed,
                                w * math.exp(-a * sk), False, geo, c, speed, n, e1, e2, origin, edges, n_phi,
                                grid_start, reflectance, dt, n_t, gdt, n_g, target, target_direct, hits)
            nxt += 1
        if nxt >= n_planes and n_planes > 0:
            return state  # the farthest target: its return is estimated, the ghost ends
        w *= math.exp(-a * step)
        x += step * dx
        y += step * dy
        z += step * dz
        t += step / speed
        if step == s_time:
            return state
        if step == s_exit:
            ex, ey = x - geo[2], y
            if ex * ex + ey * ey <= geo[3] * geo[3] and -dz >= geo[5]:
                if _angle(in_x, in_y, in_z, x - ev_x, y - ev_y, z - ev_z) < theta_c:
                    i = int(t / dt)
                    if i < n_t:
                        column[batch, world, i] += w
                        if n_scat == 1:
                            column1[batch, world, i] += w
            return state
        n_scat += 1
        world = nxt
        ax, ay, az, alpha, theta_c = _cones(x, y, z, geo)
        state = _column_estimate(state, batch, world, n_scat == 1, x, y, z, dx, dy, dz, w, t, theta_c, geo, c,
                                 speed, ln_p, ln_theta0, inv_step, dt, n_t, column, column1)
        in_x, in_y, in_z, ev_x, ev_y, ev_z = dx, dy, dz, x, y, z
        state, v1 = _uniform(state)
        state, v2 = _uniform(state)
        dx, dy, dz = _scatter(dx, dy, dz, sample_angle(sample_theta, v1), 2.0 * math.pi * v2)
        if _angle(dx, dy, dz, ax, ay, az) > alpha:
            state, v3 = _uniform(state)
            if v3 >= geo[10]:
                return state
            w /= geo[10]


@numba.njit(cache=True, parallel=True)
def _trace_beam(seed_key, first_packet, n_packets, geo, water, n, e1, e2, depth, origin, edges, n_phi, grid_start,
                reflectance, sample_theta, ln_p, ln_theta0, inv_step, times,
                column, column1, target, target_direct, hits, counted, energy):
    """Trace ``n_packets`` beam packets in ``column.shape[0]`` batches (one thread per batch, packet order).

    Tallies per batch (sums of packet weights, emitted energy 1 per packet):
    column (B, K+1, T), column1 (B, K+1, T): local estimates of events before plane k is first reached
    (index k; K = beyond every plane), all orders and first scattering only; target (B, K, T),
    target_direct (B, K, T): unscattered-return estimate at the hits of plane k, all outbound orders and
    unscattered beam only; hits (B, K, cells, G): (rho/pi) w of the hits binned on the receiver grid and in
    time from grid_start[k]; counted (B, T); energy (B, 6).

    Ghosts (geo[8] = 1): at every scattering event a ghost takes over the light scattered into a cone
    towards the aperture. Its direction is drawn from a mixture, share geo[9] from p and the rest uniform in
    the cone, and directions outside the cone are dropped; its weight is w p / mixture density, at most
    w / geo[9]. The packet itself still scatters by p, and if it goes into the cone it stops estimating
    (the ghost holds that share) but is still traced for the energy budget and counting. The light that
    returns to the receiver through the forward peak of p near the aperture is rare for packets and
    common for ghosts; together they count every path once.
    """
    n_batches = column.shape[0]
    n_planes = depth.shape[0]
    r0, slope, ap_x, ap_r, fov_cos = geo[0], geo[1], geo[2], geo[3], geo[5]
    ghosts, mix = geo[8] > 0.0, geo[9]
    a, b, c, speed = water[0], water[1], water[2], water[3]
    dt, n_t, gdt, n_g, t_end = times[0], int(times[1]), times[2], int(times[3]), times[4]
    for batch in numba.prange(n_batches):
        first = batch * n_packets // n_batches
        last = (batch + 1) * n_packets // n_batches
        for pid in range(first_packet + first, first_packet + last):
            state = _stream(seed_key, 0, pid)
            state, u1 = _uniform(state)
            state, u2 = _uniform(state)
            rr = math.sqrt(u1)
            ux0, uy0 = rr * math.cos(2.0 * math.pi * u2), rr * math.sin(2.0 * math.pi * u2)
            x, y, z = r0 * ux0, r0 * uy0, 0.0
            norm = 1.0 / math.sqrt(1.0 + slope * slope * rr * rr)
            dx, dy, dz = slope * ux0 * norm, slope * uy0 * norm, norm
            w, t = 1.0, 0.0
            n_scat = 0
            nxt = 0  # first plane not yet reached; n_planes + 1 once reflected
            estimating = True  # False once the packet's share went to a ghost
            last_world = -1  # scene of the last scattering event (-1: none, or after a reflection)
            theta_c = 0.0
            in_x, in_y, in_z, ev_x, ev_y, ev_z = 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
            energy[batch, EMITTED] += 1.0
            while True:
                state, u = _uniform(state)
                s_free = -math.log(1.0 - u) / b if b > 0.0 else math.inf
                s_time = (t_end - t) * speed
                s_exit = -z / dz if dz < 0.0 else math.inf
                sd = -(n[0] * dx + n[1] * dy + n[2] * dz)
                sp = -(n[0] * x + n[1] * y + n[2] * z)
                s_plane = (depth[n_planes - 1] - sp) / sd if (n_planes > 0 and sd > 0.0) else math.inf
                step = min(s_free, s_time, s_exit, s_plane)
                # first arrivals at the nearer planes (scenes with a nearer target) along this step
                while nxt < n_planes - 1 and sd > 0.0 and sp + sd * step >= depth[nxt]:
                    if estimating:
                        sk = max(0.0, (depth[nxt] - sp) / sd)
                        state = _target_hit(state, batch, nxt, x + sk * dx, y + sk * dy, z + sk * dz,
                                            t + sk / speed, w * math.exp(-a * sk), n_scat == 0, geo, c, speed, n,
                                            e1, e2, origin, edges, n_phi, grid_start, reflectance, dt, n_t, gdt,
                                            n_g, target, target_direct, hits)
                    nxt += 1
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
                            # the forward cone of the last scattering event, which its local estimate left out
                            if (estimating and last_world >= 0
                                    and _angle(in_x, in_y, in_z, x - ev_x, y - ev_y, z - ev_z) < theta_c):
                                column[batch, last_world, i] += w
                                if n_scat == 1:
                                    column1[batch, last_world, i] += w
                    else:
                        energy[batch, ESCAPED_BEHIND] += w
                    break
                if step == s_plane:
                    k = n_planes - 1
                    if estimating:  # the farthest target: every hit is estimated (multiple bounces)
                        state = _target_hit(state, batch, k, x, y, z, t, w, n_scat == 0 and nxt <= k, geo, c,
                                            speed, n, e1, e2, origin, edges, n_phi, grid_start, reflectance,
                                            dt, n_t, gdt, n_g, target, target_direct, hits)
                    nxt = n_planes + 1
                    last_world = -1
                    energy[batch, TARGET_ABSORBED] += w * (1.0 - reflectance)
                    w *= reflectance
                    state, v1 = _uniform(state)
                    state, v2 = _uniform(state)
                    st, ct = math.sqrt(v1), math.sqrt(1.0 - v1)  # Lambertian: cosine-weighted about n
                    cp, sp2 = math.cos(2.0 * math.pi * v2), math.sin(2.0 * math.pi * v2)
                    dx = st * cp * e1[0] + st * sp2 * e2[0] + ct * n[0]
                    dy = st * cp * e1[1] + st * sp2 * e2[1] + ct * n[1]
                    dz = st * cp * e1[2] + st * sp2 * e2[2] + ct * n[2]
                    continue
                # scattering event
                n_scat += 1
                last_world = nxt if (estimating and nxt <= n_planes) else -1
                if last_world >= 0:
                    ax, ay, az, alpha, theta_c = _cones(x, y, z, geo)
                    state = _column_estimate(state, batch, nxt, n_scat == 1, x, y, z, dx, dy, dz, w, t, theta_c,
                                             geo, c, speed, ln_p, ln_theta0, inv_step, dt, n_t, column, column1)
                    in_x, in_y, in_z, ev_x, ev_y, ev_z = dx, dy, dz, x, y, z
                    if ghosts:
                        state, v1 = _uniform(state)
                        state, v2 = _uniform(state)
                        state, v3 = _uniform(state)
                        if v1 < mix:
                            gx, gy, gz = _scatter(dx, dy, dz, sample_angle(sample_theta, v2), 2.0 * math.pi * v3)
                        else:
                            ca = 1.0 - v2 * (1.0 - math.cos(alpha))
                            gx, gy, gz = _scatter(ax, ay, az, math.acos(ca), 2.0 * math.pi * v3)
                        if _angle(gx, gy, gz, ax, ay, az) <= alpha:
                            q = 1.0 / (2.0 * math.pi * (1.0 - math.cos(alpha)))
                            pv = value_at(ln_p, ln_theta0, inv_step, _angle(dx, dy, dz, gx, gy, gz))
                            w_ghost = w * pv / ((1.0 - mix) * q + mix * pv)
                            state = _ghost(state, batch, x, y, z, gx, gy, gz, w_ghost,
                                           t, nxt, n_scat, dx, dy, dz, theta_c, geo, water, n, e1, e2, depth,
                                           origin, edges, n_phi, grid_start, reflectance, sample_theta, ln_p,
                                           ln_theta0, inv_step, times, column, column1, target, target_direct, hits)
                state, v1 = _uniform(state)
                state, v2 = _uniform(state)
                dx, dy, dz = _scatter(dx, dy, dz, sample_angle(sample_theta, v1), 2.0 * math.pi * v2)
                if ghosts and last_world >= 0 and _angle(dx, dy, dz, ax, ay, az) <= alpha:
                    estimating = False  # this share of the light belongs to the ghost
                    last_world = -1


@numba.njit(cache=True, parallel=True)
def _trace_receiver(seed_key, first_packet, n_packets, geo, water, n, e1, e2, depth, origin, edges, n_phi, grid_start,
                    sample_theta, times, field):
    """Trace receiver packets (unit weight each) to the planes; tally the scattered ones' first arrivals.

    field (B, K, cells, G): sum of packet weights over the cell's area [1/m^2] by arrival time from
    grid_start[k]; the caller scales by the etendue per packet.
    """
    n_batches = field.shape[0]
    n_planes = depth.shape[0]
    ap_x, ap_r, fov_tan = geo[2], geo[3], geo[4]
    a, b, speed = water[0], water[1], water[3]
    gdt, n_g = times[2], int(times[3])
    t_end = grid_start[n_planes - 1] + n_g * gdt
    sin2 = fov_tan * fov_tan / (1.0 + fov_tan * fov_tan)
    for batch in numba.prange(n_batches):
        first = batch * n_packets // n_batches
        last = (batch + 1) * n_packets // n_batches
        for pid in range(first_packet + first, first_packet + last):
            state = _stream(seed_key, 1, pid)
            state, u1 = _uniform(state)
            state, u2 = _uniform(state)
            state, u3 = _uniform(state)
            state, u4 = _uniform(state)
            rr = ap_r * math.sqrt(u1)
            x, y, z = ap_x + rr * math.cos(2.0 * math.pi * u2), rr * math.sin(2.0 * math.pi * u2), 0.0
            st = math.sqrt(u3 * sin2)  # uniform in projected solid angle within the field of view
            ct = math.sqrt(1.0 - st * st)
            dx, dy, dz = st * math.cos(2.0 * math.pi * u4), st * math.sin(2.0 * math.pi * u4), ct
            w, t = 1.0, 0.0
            n_scat = 0
            nxt = 0
            while True:
                state, u = _uniform(state)
                s_free = -math.log(1.0 - u) / b if b > 0.0 else math.inf
                s_time = (t_end - t) * speed
                s_exit = -z / dz if dz < 0.0 else math.inf
                sd = -(n[0] * dx + n[1] * dy + n[2] * dz)
                sp = -(n[0] * x + n[1] * y + n[2] * z)
                step = min(s_free, s_time, s_exit)
                while nxt < n_planes and sd > 0.0 and sp + sd * step >= depth[nxt]:
                    sk = max(0.0, (depth[nxt] - sp) / sd)
                    if n_scat > 0:
                        hx, hy, hz = x + sk * dx, y + sk * dy, z + sk * dz
                        cell = _grid_cell(nxt, hx, hy, hz, origin, e1, e2, edges, n_phi)
                        j = int(math.floor((t + sk / speed - grid_start[nxt]) / gdt))
                        if cell >= 0 and 0 <= j < n_g:
                            ring = cell // n_phi
                            ring_area = math.pi * (edges[nxt, ring + 1] ** 2 - edges[nxt, ring] ** 2) / n_phi
                            field[batch, nxt, cell, j] += w * math.exp(-a * sk) / ring_area
                    nxt += 1
                if nxt >= n_planes:
                    break
                w *= math.exp(-a * step)
                x += step * dx
                y += step * dy
                z += step * dz
                t += step / speed
                if step == s_time or step == s_exit:
                    break
                n_scat += 1
                state, v1 = _uniform(state)
                state, v2 = _uniform(state)
                dx, dy, dz = _scatter(dx, dy, dz, sample_angle(sample_theta, v1), 2.0 * math.pi * v2)


# ----------------------------------------------------------------------------------------------------------
# Parameter objects and the run


@dataclass(frozen=True)
class TargetPlanes:
    """Flat Lambertian targets: one scene per range, all traced in one run (see the module doc).

    ranges_m: ascending ranges [m] where each plane crosses the beam axis (empty: no target, the column
    alone); reflectance: Lambertian reflectance rho in [0, 1]; tilt_rad: rotation of the planes about the
    axis perpendicular to the offset (0: normal incidence), at most 60 deg.
    """

    ranges_m: tuple[float, ...] = ()
    reflectance: float = 0.1
    tilt_rad: float = 0.0

    def __post_init__(self):
        r = tuple(float(v) for v in np.atleast_1d(np.asarray(self.ranges_m, float)))
        if any(not (math.isfinite(v) and v > 0.0) for v in r) or any(b <= a for a, b in zip(r, r[1:])):
            raise ParameterError(f"ranges_m = {list(r)!r}: must be finite, > 0 and strictly ascending [m]")
        object.__setattr__(self, "ranges_m", r)
        check_fraction("reflectance", self.reflectance)
        if not (0.0 <= self.tilt_rad <= MAX_TILT_RAD):
            raise ParameterError(f"tilt_rad = {self.tilt_rad!r}: must lie in [0, {MAX_TILT_RAD:.4f}] (0 to 60 deg)")

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the planes, pointing back towards the instrument."""
        return np.array([math.sin(self.tilt_rad), 0.0, -math.cos(self.tilt_rad)])

    @property
    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Two unit vectors in the planes: e1 in the plane of the tilt, e2 = +y."""
        return np.array([math.cos(self.tilt_rad), 0.0, math.sin(self.tilt_rad)]), np.array([0.0, 1.0, 0.0])


@dataclass(frozen=True)
class MonteCarloResult:
    """Tallies of one run, as per-batch estimates of the received energy per emitted energy and time bin.

    Arrays are (batches, scenes, n_t) over time bins [i dt, (i+1) dt) after emission; scene k has the
    target at ``ranges_m[k]`` (or, without targets, one scene: the column alone). They are energies at
    the receiver aperture, before the receiver's optics (multiply by ``two_way_transmission``).

    column, column_first: water column, all orders and first scattering only; target_le: the target with an
    unscattered return (local estimate at the hit); target_direct: the part of it with an unscattered beam
    too (the lidar-equation target of Eq. 7 with c); scattered_return: (scenes, n_t) the target with a
    scattered return (reciprocity), scattered_beam / scattered_receiver: its per-batch estimates from the
    beam and from the receiver packets; counted: (batches, n_t) packets that crossed the aperture within the
    field of view (the farthest scene); energy: the energy budget of the farthest scene, fractions of the
    emitted energy; scene_end_s: (scenes,) end of the window in which each scene's target is complete.
    """

    time_step_s: float
    ranges_m: tuple[float, ...]
    speed_m_s: float
    column: np.ndarray
    column_first: np.ndarray
    target_le: np.ndarray
    target_direct: np.ndarray
    scattered_return: np.ndarray
    scattered_beam: np.ndarray
    scattered_receiver: np.ndarray
    counted: np.ndarray
    energy: dict
    scene_end_s: np.ndarray
    packets: int
    receiver_packets: int
    seconds: float
    settings: dict = field(default_factory=dict)

    @property
    def n_t(self) -> int:
        return int(self.column.shape[2])

    @property
    def time_s(self) -> np.ndarray:
        """(n_t,) bin centres [s]."""
        return (np.arange(self.n_t) + 0.5) * self.time_step_s

    def scene(self, range_m: float) -> int:
        """Index of the scene with the target at ``range_m``."""
        for k, r in enumerate(self.ranges_m):
            if abs(r - range_m) <= 1e-9 * max(1.0, r):
                return k
        raise ParameterError(f"range_m = {range_m!r}: this run has targets at {list(self.ranges_m)}")

    def target(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(mean (n_t,), variance of the mean (n_t,)) of scene k's target echo, cut at the scene's window."""
        beam = self.target_le[:, k] + self.scattered_beam[:, k]
        mean = self.target_le[:, k].mean(axis=0) + self.scattered_return[k]
        var = _var_of_mean(beam) + _var_of_mean(self.scattered_receiver[:, k])
        keep = self.time_s < self.scene_end_s[k]
        return np.where(keep, mean, 0.0), np.where(keep, var, 0.0)

    def total(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(mean, variance of the mean) of column plus target of scene k, per time bin."""
        keep = self.time_s < self.scene_end_s[k] if self.ranges_m else np.ones(self.n_t, bool)
        beam = self.column[:, k] + (self.target_le[:, k] + self.scattered_beam[:, k] if self.ranges_m else 0.0)
        mean = beam.mean(axis=0) + (self.scattered_return[k] if self.ranges_m else 0.0)
        var = _var_of_mean(beam) + (_var_of_mean(self.scattered_receiver[:, k]) if self.ranges_m else 0.0)
        return np.where(keep, mean, 0.0), np.where(keep, var, 0.0)


def _var_of_mean(per_batch: np.ndarray) -> np.ndarray:
    """Variance of the mean of equally sized batch estimates (axis 0)."""
    return per_batch.var(axis=0, ddof=1) / per_batch.shape[0]


def _seed_key(seed: int) -> np.uint64:
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ParameterError(f"seed = {seed!r}: must be an integer >= 0")
    with np.errstate(over="ignore"):
        return np.uint64((int(seed) * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) % (1 << 64))


def _ring_edges(instrument: Instrument, planes: TargetPlanes) -> np.ndarray:
    """(K, n_r + 1) ring radii [m] of the receiver-field grid of each plane, around the receiver axis."""
    g = instrument.geometry
    d, r_ap = g.offset_m, 0.5 * g.receiver_diameter_m
    tan_h = math.tan(0.5 * g.fov_full_rad)
    inner, outer_end = [], []
    for z in planes.ranges_m:
        footprint = (z + d * math.tan(planes.tilt_rad)) * tan_h + r_ap
        inner.append(np.linspace(0.0, 2.0 * footprint + d + r_ap, INNER_RINGS + 1))
        outer_end.append(OUTER_RANGE_FACTOR * z + 1.0)
    n_out = max(int(math.ceil(math.log(e / i[-1]) / math.log(RING_GROWTH))) for i, e in zip(inner, outer_end))
    n_out = max(n_out, 1)
    return np.array([np.concatenate([i, i[-1] * RING_GROWTH ** np.arange(1, n_out + 1)]) for i in inner])


def run_monte_carlo(instrument: Instrument, water: Water, targets: TargetPlanes = TargetPlanes(),
                    phase: str | PhaseFunction = "petzold", packets: int = 200_000,
                    receiver_packets: int | None = None, seed: int = 0, batches: int = BATCHES,
                    time_step_s: float = TIME_STEP_S, tail_s: float = TAIL_S,
                    end_s: float | None = None, peak_truncation_rad: float = 0.0,
                    cone_apertures: float = CONE_APERTURES, cone_max_rad: float = CONE_MAX_RAD,
                    ghosts: bool = True, first_packet: int = 0) -> MonteCarloResult:
    """Trace ``packets`` beam packets (and ``receiver_packets``, default a quarter as many, from the receiver).

    instrument: its beam diameter and divergence, aperture area, offset and field of view are used;
    water: a, b and its group velocity; phase: a :class:`muls.phase.PhaseFunction` or its name;
    end_s: end of the simulated time [s] (default: the farthest target's echo plus ``tail_s``; required
    without targets). Packets are rounded up to a multiple of ``batches``.
    """
    phase = check_phase(phase)
    if isinstance(batches, bool) or int(batches) != batches or batches < 2:
        raise ParameterError(f"batches = {batches!r}: must be an integer >= 2")
    batches = int(batches)
    for key, v in (("packets", packets), ("receiver_packets", receiver_packets)):
        if v is not None and (isinstance(v, bool) or int(v) != v or v < 1):
            raise ParameterError(f"{key} = {v!r}: must be an integer >= 1")
    packets = -(-int(packets) // batches) * batches
    if receiver_packets is None:
        receiver_packets = max(batches, packets // RECEIVER_SHARE)
    receiver_packets = -(-int(receiver_packets) // batches) * batches
    check_positive("time_step_s", time_step_s)
    check_positive("tail_s", tail_s)
    speed = water.speed_m_s
    planes = targets
    K = len(planes.ranges_m)
    if end_s is None:
        if K == 0:
            raise ParameterError("end_s: give the end of the simulated time [s] when there is no target")
        end_s = 2.0 * planes.ranges_m[-1] / speed + tail_s
    check_positive("end_s", end_s)
    g = instrument.geometry
    r_ap = 0.5 * g.receiver_diameter_m
    half = 0.5 * g.fov_full_rad
    geo = np.array([0.5 * g.beam_diameter_m, math.tan(0.5 * g.beam_divergence_full_rad), g.offset_m, r_ap,
                    math.tan(half), math.cos(half), cone_apertures, cone_max_rad, 1.0 if ghosts else 0.0,
                    GHOST_MIX, GHOST_SURVIVAL, GHOST_CONE_FOV, 0.0, GHOST_CONE_APERTURE])
    b = water.scattering_per_m
    if peak_truncation_rad > 0.0:
        b *= 1.0 - phase.forward_fraction(peak_truncation_rad)
        phase = phase.truncated(peak_truncation_rad)
    wat = np.array([water.absorption_per_m, b, water.absorption_per_m + b, speed])
    n = planes.normal
    e1, e2 = planes.axes
    tau = planes.tilt_rad
    ranges = np.array(planes.ranges_m, float)
    depth = ranges * math.cos(tau)
    origin = np.stack([np.full(K, g.offset_m), np.zeros(K), ranges + g.offset_m * math.tan(tau)], axis=1)
    edges = _ring_edges(instrument, planes) if K else np.zeros((0, 2))
    n_phi = TILTED_SECTORS if tau > 0.0 else 1
    reach = g.offset_m + r_ap + 0.5 * g.beam_diameter_m
    grid_start = np.maximum(0.0, depth - reach * math.sin(tau)) / speed
    n_t = int(math.ceil(end_s / time_step_s))
    n_g = int(math.ceil(tail_s / GRID_TIME_STEP_S))
    times = np.array([time_step_s, n_t, GRID_TIME_STEP_S, n_g, end_s])
    cells = (edges.shape[1] - 1) * n_phi if K else 0
    ln_p, ln_theta0, inv_step = phase.log_table
    key = _seed_key(seed)

    column = np.zeros((batches, K + 1, n_t))
    column1 = np.zeros((batches, K + 1, n_t))
    target = np.zeros((batches, K, n_t))
    target_direct = np.zeros((batches, K, n_t))
    hits = np.zeros((batches, K, cells, n_g))
    counted = np.zeros((batches, n_t))
    energy = np.zeros((batches, 6))
    field_r = np.zeros((batches, K, cells, n_g))
    t0 = time.perf_counter()
    _trace_beam(key, first_packet, packets, geo, wat, n, e1, e2, depth, origin, edges, n_phi, grid_start, planes.reflectance,
                phase.sample_theta_rad, ln_p, ln_theta0, inv_step, times, column, column1, target,
                target_direct, hits, counted, energy)
    if K:
        _trace_receiver(key, first_packet, receiver_packets, geo, wat, n, e1, e2, depth, origin, edges, n_phi, grid_start,
                        phase.sample_theta_rad, times, field_r)
    seconds = time.perf_counter() - t0

    per_beam = packets // batches
    per_receiver = receiver_packets // batches
    etendue = math.pi * r_ap**2 * math.pi * math.sin(half) ** 2
    hits /= per_beam
    field_r *= etendue / per_receiver
    scattered, scattered_beam, scattered_receiver = _reciprocity(hits, field_r, grid_start, time_step_s, n_t)
    if K:
        column = np.cumsum(column, axis=1)[:, :K]  # scene k: events before plane k was first reached
        column1 = np.cumsum(column1, axis=1)[:, :K]
    budget = energy.sum(axis=0) / packets
    return MonteCarloResult(
        time_step_s=float(time_step_s), ranges_m=planes.ranges_m, speed_m_s=speed,
        column=column / per_beam, column_first=column1 / per_beam, target_le=target / per_beam,
        target_direct=target_direct / per_beam, scattered_return=scattered, scattered_beam=scattered_beam,
        scattered_receiver=scattered_receiver, counted=counted / per_beam,
        energy={k: float(v) for k, v in zip(ENERGY_KEYS, budget)},
        scene_end_s=2.0 * grid_start + n_g * GRID_TIME_STEP_S if K else np.array([end_s]),
        packets=packets, receiver_packets=receiver_packets if K else 0, seconds=seconds,
        settings={"water": water.name, "instrument": instrument.name, "phase": phase.name,
                  "reflectance": planes.reflectance, "tilt_rad": planes.tilt_rad, "seed": int(seed),
                  "batches": batches, "end_s": float(end_s), "tail_s": float(tail_s)},
    )


def _reciprocity(hits, field_r, grid_start, dt, n_t):
    """The scattered return sum_cells (beam hits (*) receiver field) in time, on the histogram grid.

    hits (B, K, cells, G) and field_r (B, K, cells, G) are per-batch estimates on the grid time step from
    grid_start[k]. Returns the mean (K, n_t) and the per-batch estimates from each side (B, K, n_t).
    """
    B, K, _, G = hits.shape
    mean = np.zeros((K, n_t))
    beam = np.zeros((B, K, n_t))
    receiver = np.zeros((field_r.shape[0], K, n_t))
    nfft = 2 * G
    for k in range(K):
        fh = np.fft.rfft(hits[:, k], nfft, axis=-1)  # (B, cells, nfft/2+1)
        fr = np.fft.rfft(field_r[:, k], nfft, axis=-1)
        fh_mean, fr_mean = fh.mean(axis=0), fr.mean(axis=0)
        conv_mean = np.fft.irfft((fh_mean * fr_mean).sum(axis=0), nfft)[: G - 1]
        conv_beam = np.fft.irfft((fh * fr_mean[None]).sum(axis=1), nfft, axis=-1)[:, : G - 1]
        conv_rec = np.fft.irfft((fh_mean[None] * fr).sum(axis=1), nfft, axis=-1)[:, : G - 1]
        start = 2.0 * grid_start[k]
        mean[k] = _deposit_triangles(conv_mean[None], start, GRID_TIME_STEP_S, dt, n_t)[0]
        beam[:, k] = _deposit_triangles(conv_beam, start, GRID_TIME_STEP_S, dt, n_t)
        receiver[:, k] = _deposit_triangles(conv_rec, start, GRID_TIME_STEP_S, dt, n_t)
    return mean, beam, receiver


def _triangle_cdf(x):
    """CDF of the sum of two uniform [0, 1) variables at x."""
    x = np.clip(x, 0.0, 2.0)
    return np.where(x < 1.0, 0.5 * x * x, 1.0 - 0.5 * (2.0 - x) ** 2)


def _deposit_triangles(mass, start_s, grid_dt, dt, n_t):
    """Histogram (rows, n_t) of masses (rows, M): mass m spreads over [start + m g, start + (m + 2) g)."""
    rows, M = mass.shape
    out = np.zeros((rows, n_t))
    t0 = start_s + np.arange(M) * grid_dt
    first = np.floor(t0 / dt).astype(np.int64)
    for o in range(int(math.ceil(2.0 * grid_dt / dt)) + 1):
        j = first + o
        share = _triangle_cdf(((j + 1) * dt - t0) / grid_dt) - _triangle_cdf((j * dt - t0) / grid_dt)
        ok = (j >= 0) & (j < n_t)
        np.add.at(out, (slice(None), j[ok]), mass[:, ok] * share[ok])
    return out


# ----------------------------------------------------------------------------------------------------------
# Waveforms: the Monte Carlo impulse responses through the emitted pulse, beside MULS


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
        var = _var_of_mean(pb)
        if receiver is not None:
            pr = to_power_w(receiver, instrument, dt)
            mean = mean - to_power_w(beam_mean_offset, instrument, dt) + to_power_w(extra_mean, instrument, dt)
            var = var + _var_of_mean(pr)
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


#: Beam packets of ``muls multiscatter`` by default: the pond at 10 m then has every bin within 100 times
#: of the column's and of the echo's peak below 5 % relative error (docs/multiple-scattering.md).
DEFAULT_PACKETS = 4_000_000


def multiscatter_study(water: str | Water = "pond", range_m: float = 10.0, geometry: str = "mul2023",
                       packets: int = DEFAULT_PACKETS, seed: int = 0, phase: str = "petzold",
                       reflectance: float = 0.1, attenuation_model: str | None = None) -> dict:
    """The Monte Carlo waveform of one pulse on a flat plate beside MULS's, for ``muls multiscatter``.

    water: preset name or Water (MULS uses it as configured: its attenuation and backscatter rules, the
    attenuation replaced by ``attenuation_model`` when given); geometry: ``mul2023`` (receiver 130 mm beside
    the beam) or ``coaxial``. Returns the keys of the JSON output (``time_ns``, ``mc_w``, ``mc_rel_err``,
    ``muls_w``, ``target``, ``column_peak_ratio``, ``effective_attenuation_per_m``, ``packets``, ``seconds``)
    and ``details`` (parts, rules, budget).
    """
    w = water if isinstance(water, Water) else water_preset(water)
    if attenuation_model is not None:
        w = w.with_models(attenuation_model=attenuation_model)
    check_positive("range_m", range_m)
    if geometry not in ("mul2023", "coaxial"):
        raise ParameterError(f"geometry = {geometry!r}: must be 'mul2023' or 'coaxial'")
    instrument = instrument_preset(geometry)
    t0 = time.perf_counter()
    result = run_monte_carlo(instrument, w, TargetPlanes((float(range_m),), reflectance), phase=phase,
                             packets=packets, seed=seed)
    mc = mc_power_w(result, 0, instrument)
    keep = result.time_s < result.scene_end_s[0]
    t = result.time_s[keep]
    muls = muls_power_w(instrument, w, range_m, reflectance, t)
    total, total_err = (v[keep] for v in mc["total"])
    e_scale = instrument.transmitter.pulse_energy_j * two_way_transmission(instrument)
    tm, tv = result.target(0)
    mc_energy = float(tm.sum()) * e_scale
    mc_energy_err = float(math.sqrt(tv.sum())) * e_scale
    muls_total = muls["column"] + muls["target"]
    col_mc, col_muls = mc["column"][0][keep], muls["column"]
    geometry_ratio = float(geometry_factor(instrument, [range_m], seed=seed)[0])
    k_eff = effective_attenuation_per_m(instrument, range_m, reflectance, w, mc_energy, geometry_ratio)
    seconds = time.perf_counter() - t0
    rules = {rule: w.with_models(attenuation_model=rule).two_way_attenuation_per_m for rule in ("k_lidar", "c", "kd")}
    ph = check_phase(phase)
    return {
        "time_ns": _round(t * 1e9, 4),
        "mc_w": _round(total),
        "mc_rel_err": [None if v <= 0.0 else round(float(e / v), 5) for v, e in zip(total, total_err)],
        "muls_w": _round(muls_total),
        "target": {"mc_energy_j": mc_energy, "muls_energy_j": muls["target_energy_j"],
                   "ratio": mc_energy / muls["target_energy_j"] if muls["target_energy_j"] > 0 else None},
        "column_peak_ratio": float(col_mc.max() / col_muls.max()) if col_muls.max() > 0 else None,
        "effective_attenuation_per_m": k_eff,
        "packets": result.packets,
        "seconds": round(seconds, 2),
        "details": {
            "water": w.name, "range_m": float(range_m), "geometry": geometry, "reflectance": float(reflectance),
            "phase": ph.name, "seed": int(seed), "receiver_packets": result.receiver_packets,
            "mc_column_w": _round(col_mc), "mc_column_first_w": _round(mc["column_first"][0][keep]),
            "mc_target_w": _round(mc["target"][0][keep]), "mc_target_err_w": _round(mc["target"][1][keep]),
            "mc_column_err_w": _round(mc["column"][1][keep]),
            "muls_column_w": _round(col_muls), "muls_target_w": _round(muls["target"]),
            "mc_target_energy_err_j": mc_energy_err, "geometry_ratio": geometry_ratio,
            "mc_column_peak_time_ns": float(t[np.argmax(col_mc)] * 1e9),
            "muls_column_peak_time_ns": float(t[np.argmax(col_muls)] * 1e9),
            "column_first_peak_ratio": float(mc["column_first"][0][keep].max() / col_muls.max()) if col_muls.max() > 0 else None,
            "attenuation_rules_per_m": {"muls_" + r: v for r, v in rules.items()} | {"muls_model": w.attenuation_model},
            "beta_pi_ratio": ph.value_at_pi_per_sr * w.scattering_per_m / w.beta_pi_per_m_sr if w.beta_pi_per_m_sr > 0 else None,
            "energy_budget": result.energy,
        },
    }


def _round(a, digits: int | None = None) -> list:
    a = np.asarray(a, float)
    if digits is None:
        return [float(f"{v:.6g}") for v in a.tolist()]
    return np.round(a, digits).tolist()


# ----------------------------------------------------------------------------------------------------------
# Tabulated correction of MULS from the Monte Carlo


def _same_phase(water: Water, phase: PhaseFunction) -> Water:
    """``water`` with beta_pi = b p(pi) of ``phase``: MULS's single scattering with the Monte Carlo's phase."""
    return replace(water, beta_pi_measured_per_m_sr=water.scattering_per_m * phase.value_at_pi_per_sr,
                   backscatter_model="measured")


@dataclass(frozen=True)
class MultipleScatteringCorrection:
    """Monte Carlo over MULS for one water and instrument, tabulated, applied by interpolation.

    ranges_m (K,), target_ratio (K,), target_rel_err (K,): echo energy of a flat plate at normal incidence,
    Monte Carlo over MULS Eq. 7 as the water is configured (its attenuation rule); interpolated linearly
    in ln(ratio) between ranges, the end values held outside. time_s (n,), column_ratio (n,): the water
    column, Monte Carlo over MULS Eq. 4 with the water's attenuation rule and the Monte Carlo's own beta_pi
    (b p(pi)), so that the factor corrects the propagation and leaves MULS's backscatter value alone;
    defined where MULS's column is above COLUMN_FLOOR of its peak, the nearest defined value elsewhere.
    column_w (n,): the Monte Carlo column itself [W] rescaled to MULS's beta_pi, which also lights
    MULS's blind zone (a factor cannot).
    """

    water: str
    instrument: str
    ranges_m: np.ndarray
    target_ratio: np.ndarray
    target_rel_err: np.ndarray
    time_s: np.ndarray
    column_ratio: np.ndarray
    column_w: np.ndarray
    packets: int

    #: The column factor is taken where MULS's column exceeds this share of its peak.
    COLUMN_FLOOR = 1e-4

    @classmethod
    def build(cls, instrument: Instrument, water: Water, ranges_m, packets: int = 1_000_000, seed: int = 0,
              phase: str | PhaseFunction = "petzold") -> MultipleScatteringCorrection:
        """Run the Monte Carlo once for all ``ranges_m`` (a flat 0.1 plate) and tabulate the ratios."""
        phase = check_phase(phase)
        targets = TargetPlanes(tuple(sorted(float(r) for r in np.atleast_1d(ranges_m))), 0.1)
        result = run_monte_carlo(instrument, water, targets, phase=phase, packets=packets, seed=seed)
        return cls.from_result(result, instrument, water, phase)

    @classmethod
    def from_result(cls, result: MonteCarloResult, instrument: Instrument, water: Water,
                    phase: str | PhaseFunction = "petzold", scenes=None) -> MultipleScatteringCorrection:
        """Tabulate from an existing run (``scenes``: indices of the ranges to keep; default all)."""
        phase = check_phase(phase)
        if not result.ranges_m:
            raise ParameterError("the Monte Carlo run has no target ranges to tabulate")
        scenes = list(range(len(result.ranges_m))) if scenes is None else list(scenes)
        rho = float(result.settings["reflectance"])
        e_scale = instrument.transmitter.pulse_energy_j * two_way_transmission(instrument)
        ratio, rel = [], []
        for k in scenes:
            r = result.ranges_m[k]
            tm, tv = result.target(k)
            muls = instrument.transmitter.pulse_energy_j * float(
                target_factor(instrument, water, r, lambertian_weight(instrument, r, rho)))  # MULS Eq. 7
            ratio.append(tm.sum() * e_scale / muls)
            rel.append(math.sqrt(tv.sum()) / tm.sum())
        far = len(result.ranges_m) - 1
        keep = result.time_s < 2.0 * result.ranges_m[far] / result.speed_m_s
        t = result.time_s[keep]
        mc_col = mc_power_w(result, far, instrument)["column"][0][keep]
        ref = OpticalModel.build(instrument, _same_phase(water, phase)).column_power_w(t, cut_m=result.ranges_m[far])
        defined = ref > cls.COLUMN_FLOOR * ref.max()
        col_ratio = np.interp(t, t[defined], mc_col[defined] / ref[defined])
        scale = water.beta_pi_per_m_sr / (water.scattering_per_m * phase.value_at_pi_per_sr) \
            if water.scattering_per_m > 0 else 1.0
        return cls(water.name, instrument.name, np.array([result.ranges_m[k] for k in scenes]), np.array(ratio),
                   np.array(rel), t, col_ratio, mc_col * scale, result.packets)

    def target_factor(self, range_m):
        """MC / MULS echo energy at ``range_m`` [m] (any shape)."""
        r = np.asarray(range_m, float)
        return np.exp(np.interp(np.log(r), np.log(self.ranges_m), np.log(self.target_ratio)))

    def column_factor(self, time_s):
        """MC / MULS water-column power at ``time_s`` [s] after emission (any shape)."""
        return np.interp(np.asarray(time_s, float), self.time_s, self.column_ratio)

    def column_power_w(self, time_s):
        """The Monte Carlo column [W] at ``time_s``, with MULS's beta_pi (0 beyond the tabulated time)."""
        return np.interp(np.asarray(time_s, float), self.time_s, self.column_w, right=0.0)


# ----------------------------------------------------------------------------------------------------------
# Study: where single scattering fails, and by how much

#: Waters of the study (the paper's two test waters and the three Petzold waters of its Table 3).
STUDY_WATERS = ("pond", "pool", "clean_ocean", "coastal_ocean", "turbid_harbor")
#: Target ranges of the correction tables [m], and ranges between them where the interpolation is checked.
STUDY_RANGES_M = (2.0, 2.25, 2.5, 2.75, 3.0, 3.5, 4.0, 5.0, 7.5, 10.0, 12.5, 15.0, 20.0, 25.0, 30.0)
CHECK_RANGES_M = (2.125, 2.625, 3.25, 6.0, 8.75, 17.5)
#: Ranges scanned around MULS's maximum detectable range R_det for the detection question.
DETECTION_FACTORS = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0)
ATTENUATION_RULES = ("k_lidar", "c", "kd", "small_angle")
#: Beam packets per water of the study by default (docs/multiple-scattering.md gives the errors).
STUDY_PACKETS = 600_000


def _detection_range(ranges, mc_peak, level):
    """Smallest range where the Monte Carlo echo peak falls to ``level`` (log-linear between ranges)."""
    lp = np.log(np.maximum(mc_peak, 1e-300))
    below = np.nonzero(lp <= math.log(level))[0]
    if below.size == 0 or below[0] == 0:
        return None, "beyond the ranges run" if below.size == 0 else "below the nearest range run"
    i = below[0]
    f = (math.log(level) - lp[i - 1]) / (lp[i] - lp[i - 1])
    return float(ranges[i - 1] + f * (ranges[i] - ranges[i - 1])), "interpolated"


def multiscatter_waters_study(waters=STUDY_WATERS, ranges_m=STUDY_RANGES_M, packets: int = STUDY_PACKETS, seed: int = 0,
                              phase: str = "petzold", geometry: str = "mul2023", detection_shots: int = 200,
                              check_ranges_m=CHECK_RANGES_M, attenuation_model: str | None = None) -> dict:
    """Monte Carlo over MULS per water: column peak, target echo, implied detection range, correction table.

    For each water one Monte Carlo run serves flat 0.1 plates at all ``ranges_m``, at ``check_ranges_m``
    (for the interpolation error of the correction) and around MULS's maximum detectable range R_det
    (``muls.studies.maxrange_study``, the MUL's total, ``detection_shots`` pulses per range). MULS is
    evaluated with each attenuation rule (k_lidar, c, kd, small_angle; beta_pi as the water is configured). The
    detection range the Monte Carlo implies is where its echo peak power falls to MULS's echo peak at R_det
    (the far channel's threshold is fixed by its dark noise, so a peak level is what detection needs).
    ``geometry`` per range is the echo without scattering over Eq. 7 (:func:`geometry_factor`), and the
    effective attenuation is taken against it, so that it holds the propagation alone.
    ``attenuation_model`` (default: each water's own) is the rule of MULS's maximum range, of the
    correction table and of the column's ``under_echo`` comparison.
    Returns {water: {...}, "settings": {...}}.
    """
    if geometry not in ("mul2023", "coaxial"):
        raise ParameterError(f"geometry = {geometry!r}: must be 'mul2023' or 'coaxial'")
    instrument = instrument_preset(geometry)
    ph = check_phase(phase)
    t_all = time.perf_counter()
    out = {}
    geo_ranges = sorted({float(r) for r in list(ranges_m) + list(check_ranges_m)})
    geo = dict(zip(geo_ranges, geometry_factor(instrument, geo_ranges, seed=seed)))
    for name in ([waters] if isinstance(waters, str) else list(waters)):
        w = water_preset(name)
        if attenuation_model is not None:
            w = w.with_models(attenuation_model=attenuation_model)
        t0 = time.perf_counter()
        r_det = (maxrange_study([name], shots=detection_shots, seed=seed, attenuation_model=w.attenuation_model)[name]
                 ["total_m"] if detection_shots else None)
        table = sorted(float(r) for r in ranges_m)
        extra = list(check_ranges_m) + ([r_det * f for f in DETECTION_FACTORS] if r_det else [])
        ranges = sorted({round(float(r), 3) for r in table + extra})
        result = run_monte_carlo(instrument, w, TargetPlanes(tuple(ranges), 0.1), phase=ph, packets=packets, seed=seed)
        e_scale = instrument.transmitter.pulse_energy_j * two_way_transmission(instrument)
        pulse_peak = float(instrument.pulse(instrument.pulse.peak_delay_s))
        rows = []
        for k, r in enumerate(ranges):
            tm, tv = result.target(k)
            mc_e = float(tm.sum()) * e_scale
            parts = mc_power_w(result, k, instrument)
            muls_e = {rule: instrument.transmitter.pulse_energy_j * float(target_factor(
                instrument, w.with_models(attenuation_model=rule), r, lambertian_weight(instrument, r, 0.1)))
                for rule in ATTENUATION_RULES}  # MULS Eq. 7 with each rule
            ratios = {rule: mc_e / v for rule, v in muls_e.items()}
            g = geo.get(r)
            rows.append({
                "range_m": r, "mc_energy_j": mc_e, "mc_rel_err": math.sqrt(tv.sum()) / tm.sum(), "geometry": g,
                "mc_peak_w": float(parts["target"][0].max()),
                "muls_peak_w": muls_e[w.attenuation_model] * pulse_peak,
                "ratio": ratios, "closest_rule": min(ratios, key=lambda q: abs(math.log(ratios[q]))),
                "effective_attenuation_per_m": effective_attenuation_per_m(instrument, r, 0.1, w, mc_e, g or 1.0),
            })
        # the column: the farthest scene holds every earlier time
        far = len(ranges) - 1
        mc = mc_power_w(result, far, instrument)
        t = result.time_s
        col, col_err = mc["column"]
        first = mc["column_first"][0]
        col_rules = {}
        for rule in ATTENUATION_RULES:
            ref = OpticalModel.build(instrument, w.with_models(attenuation_model=rule)).column_power_w(t, cut_m=ranges[far])
            same = OpticalModel.build(instrument, _same_phase(w.with_models(attenuation_model=rule), ph)).column_power_w(
                t, cut_m=ranges[far])
            col_rules[rule] = {"muls_peak_w": float(ref.max()), "peak_ratio": float(col.max() / ref.max()),
                               "peak_ratio_same_beta_pi": float(col.max() / same.max())}
        i_pk = int(np.argmax(col))
        under_echo = []
        muls_model = OpticalModel.build(instrument, w)
        for row in rows:  # the column beneath the echo: the 4 ns before the echo starts
            sel = (t < 2.0 * row["range_m"] / w.speed_m_s) & (t >= 2.0 * row["range_m"] / w.speed_m_s - 4e-9)
            muls_col = float(muls_model.column_power_w(t[sel], cut_m=np.inf).mean())
            mc_col, mc_err = float(col[sel].mean()), float(col_err[sel].mean())  # errors of neighbours correlate
            under_echo.append({"range_m": row["range_m"], "mc_w": mc_col, "mc_rel_err": mc_err / mc_col if mc_col > 0 else None,
                               "ratio": mc_col / muls_col if muls_col > 0 else None})
        # detection: MULS's echo peak at R_det is the level; where does the Monte Carlo echo fall to it?
        detection = None
        if r_det:
            level = rows[ranges.index(round(r_det, 3))]["muls_peak_w"]
            r_mc, how = _detection_range(np.array(ranges), np.array([q["mc_peak_w"] for q in rows]), level)
            detection = {"muls_m": r_det, "mc_implied_m": r_mc, "how": how, "level_w": level,
                         "ratio": None if r_mc is None else r_mc / r_det}
        # correction table from the table ranges, checked at the others
        idx_table = [ranges.index(round(r, 3)) for r in table]
        corr = MultipleScatteringCorrection.from_result(result, instrument, w, ph, scenes=idx_table)
        checks = []
        for r in check_ranges_m:
            k = ranges.index(round(float(r), 3))
            direct = rows[k]["ratio"][w.attenuation_model]
            checks.append({"range_m": float(r), "interpolated": float(corr.target_factor(r)), "monte_carlo": direct,
                           "error": float(corr.target_factor(r) / direct - 1.0),
                           "mc_rel_err": rows[k]["mc_rel_err"]})
        out[w.name] = {
            "ranges": [{**q, "ratio": {k: round(v, 6) for k, v in q["ratio"].items()}} for q in rows if q["range_m"] in table],
            "column": {
                "mc_peak_w": float(col.max()), "mc_peak_rel_err": float(col_err[i_pk] / col[i_pk]),
                "mc_peak_time_ns": float(t[i_pk] * 1e9), "mc_first_order_peak_w": float(first.max()),
                "rules": col_rules, "under_echo": [u for u in under_echo if u["range_m"] in table],
            },
            "detection": detection,
            "correction_check": checks,
            "attenuation_per_m": {rule: w.with_models(attenuation_model=rule).two_way_attenuation_per_m
                                  for rule in ("k_lidar", "c", "kd")},
            "model_rule": w.attenuation_model,
            "beta_pi_ratio": ph.value_at_pi_per_sr * w.scattering_per_m / w.beta_pi_per_m_sr,
            "packets": result.packets, "receiver_packets": result.receiver_packets,
            "seconds": round(time.perf_counter() - t0, 1), "monte_carlo_seconds": round(result.seconds, 1),
        }
    out["settings"] = {
        "waters": [water_preset(n).name for n in ([waters] if isinstance(waters, str) else waters)],
        "ranges_m": list(ranges_m), "check_ranges_m": list(check_ranges_m), "geometry": geometry, "phase": ph.name,
        "packets": int(packets), "seed": int(seed), "reflectance": 0.1, "detection_shots": detection_shots,
        "attenuation_model": attenuation_model,
        "seconds": round(time.perf_counter() - t_all, 1),
    }
    return out
