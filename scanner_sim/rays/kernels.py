"""Numba kernels of the ray stage (scanner_sim.rays.cast.cast_beams): one pass in, one pass out.

They fuse what numpy would do in a dozen temporaries (sub-ray generation; hit point, normal, incidence,
receiver's view and shadow-ray set-up), so the stage keeps most of Embree's throughput. Compiled on first use and
cached on disk. Geometry as in scanner_sim.rays.beams: sub-ray j of pulse p starts at o_p + r_t (x_j u_p + y_j v_p)
and points along a_p + tan(theta_h) (x_j u_p + y_j v_p), normalised (MULS Eq. 11's r1 at every range).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from muls.infra.runtime import kernel
from muls.instrument.overlap_kernels import aperture_share
from scanner_sim.rays.echoes import echo_range_m


class PulseRays(NamedTuple):
    """Per pulse of a chunk, (n, 3) float64 in the scene's local frame: beam origin and unit direction, the
    beam's perpendicular basis u, v, the receiver aperture and its unit axis."""

    beam: np.ndarray
    beam_dir: np.ndarray
    u: np.ndarray
    v: np.ndarray
    rx: np.ndarray
    rx_dir: np.ndarray


class SubrayLayout(NamedTuple):
    """The beam's sub-rays: xy (m, 2) in the unit disc, weight (m,), beam radius r_t [m] at the window and
    tan of the half divergence."""

    xy: np.ndarray
    weight: np.ndarray
    r_t: float
    tan_h: float


class SceneFaces(NamedTuple):
    """Per-face attributes of the scene (normal (f, 3) local frame, reflectance, label, object, smooth surface),
    its local origin (3,) [m] and the step off a surface for shadow rays ``eps`` [m]."""

    normal: np.ndarray
    reflectance: np.ndarray
    label: np.ndarray
    object_id: np.ndarray
    surface_id: np.ndarray
    local_origin: np.ndarray
    eps: float


class ReceiverView(NamedTuple):
    """How the receiver sees a hit: ``finite`` (each aperture point sees its own field of view: the share of the
    aperture, :func:`muls.instrument.overlap_kernels.aperture_share`, of radius ``aperture_radius`` [m] and field
    ``tan_half_fov``) or,
    for MULS Eq. 11, the cone around the union of the fields, its virtual apex ``apex_behind`` [m] behind the
    aperture and its half-angle cosine ``cos_half_fov``."""

    finite: bool
    aperture_radius: float
    tan_half_fov: float
    apex_behind: float
    cos_half_fov: float

    @classmethod
    def of(cls, geometry) -> ReceiverView:
        """From a :class:`muls.instrument.overlap.TransceiverGeometry` (its ``overlap_model`` decides)."""
        half = 0.5 * geometry.fov_full_rad
        return cls(geometry.overlap_model != "eq11", geometry.aperture_radius_m, math.tan(half),
                   geometry.aperture_radius_m / math.tan(half), math.cos(half))


class ShadowRays(NamedTuple):
    """Shadow rays of one block: origin (b, 3), unit direction (b, 3) and length (b,), float32 local frame."""

    origin: np.ndarray
    direction: np.ndarray
    length: np.ndarray


@kernel(fastmath=False, nogil=True)
def subrays_local32(rays, p0, p1, layout, origins, dirs):
    """Fill ``origins`` and ``dirs`` ((n m, 3) float32, pulse-major, local frame) with the sub-rays of pulses
    p0 .. p1 - 1 of ``rays`` (:class:`PulseRays`)."""
    xy, r_t, tan_h = layout.xy, layout.r_t, layout.tan_h
    beam_local, beam_dir, u, v = rays.beam, rays.beam_dir, rays.u, rays.v
    m = xy.shape[0]
    for q in range(p1 - p0):
        p = p0 + q
        for j in range(m):
            k = q * m + j
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


@kernel(fastmath=False, nogil=True)
def hit_block(prim, tfar, ray0, base, rays, layout, faces, view, rows, shadows):
    """Turn one block of Embree first-hit results into hit rows, and set up their shadow rays.

    prim (b,) int32 / tfar (b,) float32: Embree's answer for rays ray0 .. ray0 + b - 1 (-1: miss) of the
    chunk's :class:`PulseRays` with the sub-rays of ``layout``. Hits are written in ray (scan) order at rows
    base, base + 1, ... of ``rows`` (:class:`scanner_sim.rays.hits.HitColumns`), every field but one as the hit
    record declares it: ``incidence_rad`` holds the cosine of the incidence angle, which the caller turns into
    the angle with numpy's vectorised arccos. ``receiver_weight`` is the share of the aperture that sees the hit
    (:class:`ReceiverView`: each aperture point's own field, or 1 inside Eq. 11's cone), 0 when the aperture is
    not on the lit side. Shadow ray c of the block (for hit row base + c) goes into ``shadows``
    (float32, local frame): from the hit stepped ``faces.eps`` off the surface toward the aperture, stopping
    ``eps`` short of it; length -1 (an empty ray Embree skips) when the receiver cannot see the hit. Returns the
    block's hit count.
    """
    beam_local, beam_dir, u, v, rx_local, rx_dir = rays
    xy, weights, r_t, tan_h = layout
    face_normal, eps = faces.normal, faces.eps
    m = xy.shape[0]
    c = 0
    ox, oy, oz = faces.local_origin[0], faces.local_origin[1], faces.local_origin[2]
    for b in range(prim.shape[0]):
        f = prim[b]
        if f < 0:
            continue
        r = ray0 + b
        i = base + c
        p = r // m
        j = r - p * m
        rows.pulse_index[i] = p
        rows.subray_index[i] = j
        rows.reflectance[i] = faces.reflectance[f]
        rows.label[i] = faces.label[f]
        rows.object_id[i] = faces.object_id[f]
        rows.surface_id[i] = faces.surface_id[f]
        rows.weight[i] = weights[j]
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
        t = np.float64(tfar[b])
        rows.range_m[i] = t
        qx = beam_local[p, 0] + r_t * ax + t * dx
        qy = beam_local[p, 1] + r_t * ay + t * dy
        qz = beam_local[p, 2] + r_t * az + t * dz
        rows.point[i, 0] = qx + ox
        rows.point[i, 1] = qy + oy
        rows.point[i, 2] = qz + oz
        nx, ny, nz = face_normal[f, 0], face_normal[f, 1], face_normal[f, 2]
        dn = nx * dx + ny * dy + nz * dz
        if dn > 0.0:  # orient the normal toward the incoming ray
            nx, ny, nz, dn = -nx, -ny, -nz, -dn
        rows.normal[i, 0] = nx
        rows.normal[i, 1] = ny
        rows.normal[i, 2] = nz
        rows.incidence_rad[i] = -dn if -dn < 1.0 else 1.0  # the cosine; arccos in numpy (SIMD) afterwards
        rx, ry, rz = rx_local[p, 0], rx_local[p, 1], rx_local[p, 2]
        kx, ky, kz = rx_dir[p, 0], rx_dir[p, 1], rx_dir[p, 2]
        tx, ty, tz = rx - qx, ry - qy, rz - qz
        dist = math.sqrt(tx * tx + ty * ty + tz * tz)
        # The return leg at float32 precision (0.5 um at 10 m), as Embree gives the outgoing one.
        rows.echo_range_m[i] = echo_range_m(t, np.float64(np.float32(dist)))
        along = -(tx * kx + ty * ky + tz * kz)  # the hit's distance in front of the aperture, along its axis
        if view.finite:
            share = aperture_share(view.aperture_radius, view.tan_half_fov, along,
                                   math.sqrt(max(dist * dist - along * along, 0.0)))
        else:  # Eq. 11's cone: virtual apex behind the aperture
            behind = along + view.apex_behind
            wx, wy, wz = qx - (rx - view.apex_behind * kx), qy - (ry - view.apex_behind * ky), qz - (rz - view.apex_behind * kz)
            share = 1.0 if behind >= view.cos_half_fov * math.sqrt(wx * wx + wy * wy + wz * wz) else 0.0
        ok = share > 0.0 and nx * tx + ny * ty + nz * tz > 0.0
        rows.receiver_weight[i] = share if ok else 0.0
        shadows.origin[c, 0] = qx + eps * nx
        shadows.origin[c, 1] = qy + eps * ny
        shadows.origin[c, 2] = qz + eps * nz
        shadows.direction[c, 0] = tx / dist
        shadows.direction[c, 1] = ty / dist
        shadows.direction[c, 2] = tz / dist
        shadows.length[c] = dist - 2.0 * eps if ok else -1.0
        c += 1
    return c


@kernel(nogil=True)
def clear_blocked(occluded, sh_len, receiver_weight, base):
    """receiver_weight[base + c] = 0 where shadow ray c hit something (empty rays, length <= 0, never count)."""
    for c in range(occluded.shape[0]):
        if occluded[c] >= 0 and sh_len[c] > 0.0:
            receiver_weight[base + c] = 0.0
