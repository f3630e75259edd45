"""The target's scattered return by reciprocity: the receiver's field on each target plane, beam hits on the
same grid, and their convolution in time.

Light that scatters on its way back from the target is most of the echo in turbid water, and estimating
it from reflected packets would need each of them to find the receiver. Instead receiver packets leave
the aperture (uniform over it, uniform in projected solid angle within the field of view, total weight
the etendue A pi sin^2(theta_r/2)), and where the scattered ones first reach a plane they give the
receiver's field E_R(x, t2) on a radial grid around the receiver axis (with azimuth sectors when the plane
is tilted). A Lambertian patch of radiance L delivers L E_R dA to the detector, so a beam hit of weight w
at time t1 adds w (rho/pi) E_R(x, t - t1): the two grids are convolved in time here.
"""

from __future__ import annotations

import math

import numba
import numpy as np

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


@numba.njit(cache=True)
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
