"""Compiled packet transport: beam packets with their ghosts, and receiver packets.

Free paths are drawn with the scattering coefficient b (every event scatters); absorption is the packet's
weight, exp(-a s) over a path s. Scattering angles come from the phase function's inverse CDF, the
azimuth is uniform. Packets are split into a fixed number of batches, each traced in packet order by one
thread, so that a seed fixes the result whatever the number of threads.

``geo`` = (beam radius, beam slope, aperture x, aperture radius, tan and cos of the half field of view,
CONE_APERTURES, CONE_MAX_RAD, ghosts on (1) or off (0), GHOST_MIX, GHOST_SURVIVAL, GHOST_CONE_FOV, unused,
GHOST_CONE_APERTURE); ``water`` = (a, b, c, speed); ``phase``, ``scene``, ``times``: see
:mod:`.estimators`.
"""

from __future__ import annotations

import math

import numba

from ..phase import sample_angle, value_at
from .estimators import column_estimate, cones, target_hit
from .reciprocity import grid_cell
from .sampling import angle, packet_stream, scatter, uniform

#: Forward cone of the local estimates: at an event, directions within
#: theta_c = min(CONE_MAX_RAD, CONE_APERTURES x aperture radius / distance to the aperture) of the incident
#: direction are left to counting (the packet or ghost is counted if its next flight lands in the aperture
#: within the field of view), because the forward peak of p (10^3 to 10^10 per sr below 0.1 deg) would
#: give rare, huge estimates. The split is exact: together the two cover every direction once.
CONE_APERTURES = 0.3
CONE_MAX_RAD = 0.03
#: Ghosts (see trace_beam): the cone towards the aperture has the half-angle
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


@numba.njit(cache=True, inline="always")
def flight(state, x, y, z, dx, dy, dz, t, b, speed, t_end, n):
    """A free path and the distances to the flight's other ends.

    Returns (state, s_free (drawn with b), s_time (to the end of the run), s_exit (to the plane z = 0),
    the speed of approach to the target planes sd = -n . direction, and the penetration sp = -n . position).
    """
    state, u = uniform(state)
    s_free = -math.log(1.0 - u) / b if b > 0.0 else math.inf
    s_time = (t_end - t) * speed
    s_exit = -z / dz if dz < 0.0 else math.inf
    sd = -(n[0] * dx + n[1] * dy + n[2] * dz)
    sp = -(n[0] * x + n[1] * y + n[2] * z)
    return state, s_free, s_time, s_exit, sd, sp


@numba.njit(cache=True, inline="always")
def turn(state, dx, dy, dz, sample_theta):
    """Scatter the direction (dx, dy, dz) by an angle drawn from p and a uniform azimuth."""
    state, v1 = uniform(state)
    state, v2 = uniform(state)
    nx, ny, nz = scatter(dx, dy, dz, sample_angle(sample_theta, v1), 2.0 * math.pi * v2)
    return state, nx, ny, nz


@numba.njit(cache=True)
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


@numba.njit(cache=True)
def ghost(state, batch, x, y, z, dx, dy, dz, w, t, nxt, n_scat, in_x, in_y, in_z, theta_c, geo, water, scene,
          phase, times, tallies):
    """Trace a ghost: the share of a scattering event's light sent towards the aperture (see trace_beam).

    It starts at the event (x, y, z) in direction (dx, dy, dz) with weight w, and makes every estimate a
    packet makes, spawns no ghost, stops at the farthest plane, and plays Russian roulette once it is no
    longer aimed at the aperture. Its first flight counts only within theta_c of the event's incident
    direction (in_x, in_y, in_z): the event's local estimate holds the rest.
    """
    column, column1 = tallies[0], tallies[1]
    n_planes = scene[3].shape[0]
    a, b, c, speed = water[0], water[1], water[2], water[3]
    dt, n_t, t_end = times[0], int(times[1]), times[4]
    ev_x, ev_y, ev_z = x, y, z
    world = nxt
    while True:
        state, s_free, s_time, s_exit, sd, sp = flight(state, x, y, z, dx, dy, dz, t, b, speed, t_end, scene[0])
        step = min(s_free, s_time, s_exit)
        state, nxt = first_arrivals(state, batch, nxt, n_planes, True, False, x, y, z, dx, dy, dz, t, w, sd, sp,
                                    step, geo, water, scene, times, tallies)
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
                if angle(in_x, in_y, in_z, x - ev_x, y - ev_y, z - ev_z) < theta_c:
                    i = int(t / dt)
                    if i < n_t:
                        column[batch, world, i] += w
                        if n_scat == 1:
                            column1[batch, world, i] += w
            return state
        n_scat += 1
        world = nxt
        ax, ay, az, alpha, theta_c = cones(x, y, z, geo)
        state = column_estimate(state, batch, world, n_scat == 1, x, y, z, dx, dy, dz, w, t, theta_c, geo, c,
                                speed, phase, times, column, column1)
        in_x, in_y, in_z, ev_x, ev_y, ev_z = dx, dy, dz, x, y, z
        state, dx, dy, dz = turn(state, dx, dy, dz, phase[0])
        if angle(dx, dy, dz, ax, ay, az) > alpha:
            state, v3 = uniform(state)
            if v3 >= geo[10]:
                return state
            w /= geo[10]


@numba.njit(cache=True, parallel=True)
def trace_beam(seed_key, first_packet, n_packets, geo, water, scene, phase, times, tallies):
    """Trace ``n_packets`` beam packets in ``tallies[0].shape[0]`` batches (one thread per batch, packet order).

    tallies = (column, column1, target, target_direct, hits, counted, energy), per batch (sums of packet
    weights, emitted energy 1 per packet): column (B, K+1, T), column1 (B, K+1, T): local estimates of
    events before plane k is first reached (index k; K = beyond every plane), all orders and first
    scattering only; target (B, K, T), target_direct (B, K, T): unscattered-return estimate at the hits of
    plane k, all outbound orders and unscattered beam only; hits (B, K, cells, G): (rho/pi) w of the hits
    binned on the receiver grid and in time from the grid start of plane k; counted (B, T); energy (B, 6).

    Ghosts (geo[8] = 1): at every scattering event a ghost takes over the light scattered into a cone
    towards the aperture. Its direction is drawn from a mixture, share geo[9] from p and the rest uniform in
    the cone, and directions outside the cone are dropped; its weight is w p / mixture density, at most
    w / geo[9]. The packet itself still scatters by p, and if it goes into the cone it stops estimating
    (the ghost holds that share) but is still traced for the energy budget and counting. The light that
    returns to the receiver through the forward peak of p near the aperture is rare for packets and
    common for ghosts; together they count every path once.
    """
    column, column1, counted, energy = tallies[0], tallies[1], tallies[5], tallies[6]
    n, e1, e2, depth = scene[0], scene[1], scene[2], scene[3]
    reflectance = scene[8]
    sample_theta, ln_p, ln_theta0, inv_step = phase
    n_batches = column.shape[0]
    n_planes = depth.shape[0]
    r0, slope, ap_x, ap_r, fov_cos = geo[0], geo[1], geo[2], geo[3], geo[5]
    ghosts, mix = geo[8] > 0.0, geo[9]
    a, b, c, speed = water[0], water[1], water[2], water[3]
    dt, n_t, t_end = times[0], int(times[1]), times[4]
    for batch in numba.prange(n_batches):
        first = batch * n_packets // n_batches
        last = (batch + 1) * n_packets // n_batches
        for pid in range(first_packet + first, first_packet + last):
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
            estimating = True  # False once the packet's share went to a ghost
            last_world = -1  # scene of the last scattering event (-1: none, or after a reflection)
            theta_c = 0.0
            in_x, in_y, in_z, ev_x, ev_y, ev_z = 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
            energy[batch, EMITTED] += 1.0
            while True:
                state, s_free, s_time, s_exit, sd, sp = flight(state, x, y, z, dx, dy, dz, t, b, speed, t_end, n)
                s_plane = (depth[n_planes - 1] - sp) / sd if (n_planes > 0 and sd > 0.0) else math.inf
                step = min(s_free, s_time, s_exit, s_plane)
                # first arrivals at the nearer planes (scenes with a nearer target) along this step
                state, nxt = first_arrivals(state, batch, nxt, n_planes - 1, estimating, n_scat == 0, x, y, z, dx, dy,
                                            dz, t, w, sd, sp, step, geo, water, scene, times, tallies)
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
                                    and angle(in_x, in_y, in_z, x - ev_x, y - ev_y, z - ev_z) < theta_c):
                                column[batch, last_world, i] += w
                                if n_scat == 1:
                                    column1[batch, last_world, i] += w
                    else:
                        energy[batch, ESCAPED_BEHIND] += w
                    break
                if step == s_plane:
                    k = n_planes - 1
                    if estimating:  # the farthest target: every hit is estimated (multiple bounces)
                        state = target_hit(state, batch, k, x, y, z, t, w, n_scat == 0 and nxt <= k, geo, c, speed,
                                           scene, times, tallies[2], tallies[3], tallies[4])
                    nxt = n_planes + 1
                    last_world = -1
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
                last_world = nxt if (estimating and nxt <= n_planes) else -1
                if last_world >= 0:
                    ax, ay, az, alpha, theta_c = cones(x, y, z, geo)
                    state = column_estimate(state, batch, nxt, n_scat == 1, x, y, z, dx, dy, dz, w, t, theta_c,
                                            geo, c, speed, phase, times, column, column1)
                    in_x, in_y, in_z, ev_x, ev_y, ev_z = dx, dy, dz, x, y, z
                    if ghosts:
                        state, v1 = uniform(state)
                        state, v2 = uniform(state)
                        state, v3 = uniform(state)
                        if v1 < mix:
                            gx, gy, gz = scatter(dx, dy, dz, sample_angle(sample_theta, v2), 2.0 * math.pi * v3)
                        else:
                            ca = 1.0 - v2 * (1.0 - math.cos(alpha))
                            gx, gy, gz = scatter(ax, ay, az, math.acos(ca), 2.0 * math.pi * v3)
                        if angle(gx, gy, gz, ax, ay, az) <= alpha:
                            q = 1.0 / (2.0 * math.pi * (1.0 - math.cos(alpha)))
                            pv = value_at(ln_p, ln_theta0, inv_step, angle(dx, dy, dz, gx, gy, gz))
                            w_ghost = w * pv / ((1.0 - mix) * q + mix * pv)
                            state = ghost(state, batch, x, y, z, gx, gy, gz, w_ghost, t, nxt, n_scat, dx, dy, dz,
                                          theta_c, geo, water, scene, phase, times, tallies)
                state, dx, dy, dz = turn(state, dx, dy, dz, sample_theta)
                if ghosts and last_world >= 0 and angle(dx, dy, dz, ax, ay, az) <= alpha:
                    estimating = False  # this share of the light belongs to the ghost
                    last_world = -1


@numba.njit(cache=True, parallel=True)
def trace_receiver(seed_key, first_packet, n_packets, geo, water, scene, sample_theta, times, field):
    """Trace receiver packets (unit weight each) to the planes; tally the scattered ones' first arrivals.

    field (B, K, cells, G): sum of packet weights over the cell's area [1/m^2] by arrival time from the
    grid start of plane k; the caller scales by the etendue per packet.
    """
    n, e1, e2, depth, origin, edges, grid_start, n_phi, _ = scene
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
            state = packet_stream(seed_key, 1, pid)
            state, u1 = uniform(state)
            state, u2 = uniform(state)
            state, u3 = uniform(state)
            state, u4 = uniform(state)
            rr = ap_r * math.sqrt(u1)
            x, y, z = ap_x + rr * math.cos(2.0 * math.pi * u2), rr * math.sin(2.0 * math.pi * u2), 0.0
            st = math.sqrt(u3 * sin2)  # uniform in projected solid angle within the field of view
            ct = math.sqrt(1.0 - st * st)
            dx, dy, dz = st * math.cos(2.0 * math.pi * u4), st * math.sin(2.0 * math.pi * u4), ct
            w, t = 1.0, 0.0
            n_scat = 0
            nxt = 0
            while True:
                state, s_free, s_time, s_exit, sd, sp = flight(state, x, y, z, dx, dy, dz, t, b, speed, t_end, n)
                step = min(s_free, s_time, s_exit)
                while nxt < n_planes and sd > 0.0 and sp + sd * step >= depth[nxt]:
                    sk = max(0.0, (depth[nxt] - sp) / sd)
                    if n_scat > 0:
                        hx, hy, hz = x + sk * dx, y + sk * dy, z + sk * dz
                        cell = grid_cell(nxt, hx, hy, hz, origin, e1, e2, edges, n_phi)
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
                state, dx, dy, dz = turn(state, dx, dy, dz, sample_theta)

