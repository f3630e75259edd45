"""Numba kernels of the ray stage (scanner_sim.raycast.cast_beams): one pass in, one pass out.

They fuse what numpy would do in a dozen temporaries (sub-ray generation; hit point, normal, incidence,
FOV cone and shadow-ray set-up), so the stage keeps most of Embree's throughput. Compiled on first use and
cached on disk. Geometry as in scanner_sim.beams: sub-ray j of pulse p starts at o_p + r_t (x_j u_p + y_j v_p)
and points along a_p + tan(theta_h) (x_j u_p + y_j v_p), normalised (MULS Eq. 11's r1 at every range).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, fastmath=False)
def subrays_local32(beam_local, beam_dir, u, v, xy, r_t, tan_h, origins, dirs):
    """Fill ``origins`` and ``dirs`` ((n m, 3) float32, pulse-major, local frame) with the sub-rays."""
    n, m = beam_local.shape[0], xy.shape[0]
    for p in range(n):
        for j in range(m):
            k = p * m + j
            x, y = xy[j, 0], xy[j, 1]
            dx = beam_dir[p, 0] + tan_h * (x * u[p, 0] + y * v[p, 0])
            dy = beam_dir[p, 1] + tan_h * (x * u[p, 1] + y * v[p, 1])
            dz = beam_dir[p, 2] + tan_h * (x * u[p, 2] + y * v[p, 2])
            inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
            for c in range(3):
                origins[k, c] = beam_local[p, c] + r_t * (x * u[p, c] + y * v[p, c])
            dirs[k, 0] = dx * inv
            dirs[k, 1] = dy * inv
            dirs[k, 2] = dz * inv


@njit(cache=True, fastmath=False, parallel=True)
def hit_attributes(ray, tri, tfar, m, beam_local, beam_dir, u, v, xy, r_t, tan_h, rx_local, rx_dir, face_normal,
                   face_reflectance, face_label, face_object, weights, local_origin, apex_behind, cos_half_fov,
                   eps, sh_o, sh_d, sh_len):
    """Per-hit geometry and material, the receiver FOV cone, and the shadow rays to cast (compacted).

    Returns pulse (k,) int64, subray (k,) int32, range_m (k,) float64, point (k, 3) float64 world, normal
    (k, 3) float32 facing the ray, cos_incidence (k,) float64, reflectance (k,), label (k,) int16, object
    (k,) int32, weight (k,), rx_dist (k,) float32 [m], seen (k,) float64 (1 in the cone with the receiver on
    the lit side). Fills one shadow ray per hit into the caller's (k, 3) / (k,) float32 buffers: origins
    (local, stepped ``eps`` off the surface), unit directions toward the aperture, and lengths (stopping
    ``eps`` short of the aperture; -1 where no shadow ray is needed, which Embree skips as an empty ray).
    """
    k = ray.shape[0]
    pulse = np.empty(k, np.int64)
    sub = np.empty(k, np.int32)
    rng = np.empty(k, np.float64)
    point = np.empty((k, 3), np.float64)
    normal = np.empty((k, 3), np.float32)
    incidence = np.empty(k, np.float64)
    refl = np.empty(k, np.float64)
    label = np.empty(k, np.int16)
    obj = np.empty(k, np.int32)
    weight = np.empty(k, np.float64)
    rx_dist = np.empty(k, np.float32)
    seen = np.zeros(k, np.float64)
    ox, oy, oz = local_origin[0], local_origin[1], local_origin[2]
    for i in prange(k):
        r = ray[i]
        f = tri[i]
        p = r // m
        j = r - p * m
        pulse[i] = p
        sub[i] = j
        refl[i] = face_reflectance[f]
        label[i] = face_label[f]
        obj[i] = face_object[f]
        weight[i] = weights[j]
        x, y = xy[j, 0], xy[j, 1]
        ax = x * u[p, 0] + y * v[p, 0]
        ay = x * u[p, 1] + y * v[p, 1]
        az = x * u[p, 2] + y * v[p, 2]
        dx = beam_dir[p, 0] + tan_h * ax
        dy = beam_dir[p, 1] + tan_h * ay
        dz = beam_dir[p, 2] + tan_h * az
        inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
        dx *= inv
        dy *= inv
        dz *= inv
        t = np.float64(tfar[i])
        rng[i] = t
        qx = beam_local[p, 0] + r_t * ax + t * dx
        qy = beam_local[p, 1] + r_t * ay + t * dy
        qz = beam_local[p, 2] + r_t * az + t * dz
        point[i, 0] = qx + ox
        point[i, 1] = qy + oy
        point[i, 2] = qz + oz
        nx, ny, nz = face_normal[f, 0], face_normal[f, 1], face_normal[f, 2]
        dn = nx * dx + ny * dy + nz * dz
        if dn > 0.0:  # orient the normal toward the incoming ray
            nx, ny, nz, dn = -nx, -ny, -nz, -dn
        normal[i, 0] = nx
        normal[i, 1] = ny
        normal[i, 2] = nz
        incidence[i] = -dn if -dn < 1.0 else 1.0  # cos(incidence); arccos in numpy (SIMD) afterwards
        # Receiver FOV cone: virtual apex behind the aperture (raycast.ReceiverCone).
        rx, ry, rz = rx_local[p, 0], rx_local[p, 1], rx_local[p, 2]
        kx, ky, kz = rx_dir[p, 0], rx_dir[p, 1], rx_dir[p, 2]
        wx = qx - (rx - apex_behind * kx)
        wy = qy - (ry - apex_behind * ky)
        wz = qz - (rz - apex_behind * kz)
        along = wx * kx + wy * ky + wz * kz
        tx, ty, tz = rx - qx, ry - qy, rz - qz
        dist = math.sqrt(tx * tx + ty * ty + tz * tz)
        rx_dist[i] = dist
        ok = along >= cos_half_fov * math.sqrt(wx * wx + wy * wy + wz * wz) and nx * tx + ny * ty + nz * tz > 0.0
        seen[i] = 1.0 if ok else 0.0
        sh_o[i, 0] = qx + eps * nx
        sh_o[i, 1] = qy + eps * ny
        sh_o[i, 2] = qz + eps * nz
        sh_d[i, 0] = tx / dist
        sh_d[i, 1] = ty / dist
        sh_d[i, 2] = tz / dist
        sh_len[i] = dist - 2.0 * eps if ok else -1.0
    return pulse, sub, rng, point, normal, incidence, refl, label, obj, weight, rx_dist, seen
