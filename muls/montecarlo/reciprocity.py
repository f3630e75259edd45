"""The target's scattered return by reciprocity: the receiver's field on each target plane, beam hits on the
same grid, and their convolution in time.

Light that scatters on its way back from the target is most of the echo in turbid water, and estimating
it from reflected packets would need each of them to find the receiver. Instead receiver packets leave
the aperture (uniform over it, uniform in projected solid angle within the field of view, total weight
the etendue A pi sin^2(theta_r/2)), and where the scattered ones first reach a plane they give the
receiver's field E_R(x, t2) on a radial grid around the receiver axis (with azimuth sectors when the plane
is tilted). A Lambertian patch of radiance L delivers L E_R dA to the detector, so a beam hit of weight w
at time t1 adds w (rho/pi) E_R(x, t - t1): the two grids are convolved in time here. The receiver packets
are traced here (compiled); the beam hits come from :mod:`.transport`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..infra.runtime import kernel
from .layout import APERTURE_RADIUS, APERTURE_X, FOV_TAN
from .sampling import batch_packets, flight, packet_stream, turn, uniform

#: Time step of the reciprocity grids (beam hits, receiver field) [s].
GRID_TIME_STEP_S = 1e-9
#: Radial grid of the receiver field on a target plane: this many equal rings out to twice the receiver
#: footprint plus the offset, then rings growing by RING_GROWTH out to OUTER_RANGE_FACTOR x range + 1 m.
INNER_RINGS = 60
RING_GROWTH = 1.12
OUTER_RANGE_FACTOR = 1.5
#: Azimuth sectors of that grid when the target is tilted (the field is then not round).
TILTED_SECTORS = 12


def ring_edges(ranges_m, tilt_rad: float, offset_m: float, aperture_radius_m: float, fov_full_rad: float) -> np.ndarray:
    """(K, n_r + 1) ring radii [m] of the receiver-field grid of each plane, around the receiver axis."""
    tan_h = math.tan(0.5 * fov_full_rad)
    inner, outer_end = [], []
    for z in ranges_m:
        footprint = (z + offset_m * math.tan(tilt_rad)) * tan_h + aperture_radius_m
        inner.append(np.linspace(0.0, 2.0 * footprint + offset_m + aperture_radius_m, INNER_RINGS + 1))
        outer_end.append(OUTER_RANGE_FACTOR * z + 1.0)
    n_out = max(int(math.ceil(math.log(e / i[-1]) / math.log(RING_GROWTH))) for i, e in zip(inner, outer_end))
    n_out = max(n_out, 1)
    return np.array([np.concatenate([i, i[-1] * RING_GROWTH ** np.arange(1, n_out + 1)]) for i in inner])


@kernel
def grid_cell(k, x, y, z, origin, e1, e2, edges, n_phi):
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


@kernel(parallel=True)
def trace_receiver(seed_key, first_packet, n_packets, geo, water, scene, sample_theta, times, field, part):
    """Trace receiver packets (unit weight each) to the planes; tally the scattered ones' first arrivals.

    field (B, K, cells, G): sum of packet weights over the cell's area [1/m^2] by arrival time from the
    grid start of plane k; the caller scales by the etendue per packet. part: (start, stop), the packets of each
    batch's share this call traces (:func:`muls.montecarlo.run.in_parts`).
    """
    n, e1, e2, depth, origin, edges, grid_start, n_phi, _ = scene
    n_batches = field.shape[0]
    n_planes = depth.shape[0]
    ap_x, ap_r, fov_tan = geo[APERTURE_X], geo[APERTURE_RADIUS], geo[FOV_TAN]
    a, b, speed = water[0], water[1], water[3]
    gdt, n_g = times[2], int(times[3])
    t_end = grid_start[n_planes - 1] + n_g * gdt
    sin2 = fov_tan * fov_tan / (1.0 + fov_tan * fov_tan)
    for batch in numba.prange(n_batches):
        lo, hi = batch_packets(batch, first_packet, n_packets, n_batches, part)
        for pid in range(lo, hi):
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


def scattered_return(hits, field_r, grid_start, dt, n_t):
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
