"""Compiled sampling helpers of the Monte Carlo: per-packet random streams, free paths, directions,
aperture points.

Every packet draws from its own counter-based stream (SplitMix64 of the seed, the stream and the packet
number, with :mod:`muls.infra.noise`'s finaliser and Weyl constant), so a seed fixes the result whatever the
number of threads.
"""

from __future__ import annotations

import math

import numpy as np

from ..infra.noise import GAMMA, splitmix64
from ..infra.runtime import kernel
from ..water.phase_kernels import sample_angle

#: Odd 64-bit constant separating the streams (0 beam, 1 receiver) and the streams of split copies.
STREAM_KEY = np.uint64(0xD1B54A32D192ED03)
_INV53 = 1.0 / 9007199254740992.0


@kernel(inline="always")
def packet_stream(seed_key, stream, packet):
    """Initial state of packet ``packet`` of stream ``stream`` (0 beam, 1 receiver)."""
    return splitmix64(seed_key ^ splitmix64(np.uint64(packet) * GAMMA + np.uint64(stream) * STREAM_KEY))


@kernel(inline="always")
def uniform(state):
    """(next state, uniform in [0, 1))."""
    state = state + GAMMA
    return state, float(splitmix64(state) >> np.uint64(11)) * _INV53


@kernel(inline="always")
def scatter(ux, uy, uz, theta, phi):
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


@kernel(inline="always")
def angle(ax, ay, az, bx, by, bz):
    """Angle [rad] between two vectors (atan2 of |a x b| and a . b: exact at small angles)."""
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    return math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz)


@kernel
def aperture_point(state, px, py, pz, ap_x, ap_r, fov_tan):
    """A point q of the aperture that sees (px, py, pz) within its field of view, and the area it stands for.

    The aperture points whose field contains the point form a disc of radius pz tan(theta_r/2) around
    (px, py); q is drawn on the smaller of that disc and the aperture, and kept if it lies in the other.
    Returns (state, area [m^2] or 0 when q does not see the point, qx, qy).
    """
    rf = pz * fov_tan
    dx, dy = px - ap_x, py
    if dx * dx + dy * dy > (rf + ap_r) * (rf + ap_r):
        return state, 0.0, 0.0, 0.0
    state, u1 = uniform(state)
    state, u2 = uniform(state)
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


@kernel(inline="always")
def batch_packets(batch, first_packet, n_packets, n_batches, part):
    """The packet numbers [lo, hi) that batch ``batch`` of ``n_batches`` traces, in order, within ``part`` = (start,
    stop), offsets into the batch's share: a batch's share is fixed by the counts alone, so a seed fixes the result
    whatever the thread count, and a run traced part after part adds its packets in the same order as one call."""
    lo = first_packet + batch * n_packets // n_batches
    hi = first_packet + (batch + 1) * n_packets // n_batches
    return min(hi, lo + part[0]), min(hi, lo + part[1])


@kernel(inline="always")
def free_path(state, b):
    """(state, a free path [m] drawn with the scattering coefficient ``b`` [1/m]: exponential of mean 1/b, inf when
    b = 0). Absorption is not drawn: it is the packet's weight, exp(-a s) over a path s."""
    state, u = uniform(state)
    return state, (-math.log(1.0 - u) / b if b > 0.0 else math.inf)


@kernel(inline="always")
def flight(state, x, y, z, dx, dy, dz, t, b, speed, t_end, n):
    """A free path and the distances to the flight's other ends.

    Returns (state, s_free (drawn with b), s_time (to the end of the run), s_exit (to the plane z = 0),
    the speed of approach to the target planes sd = -n . direction, and the penetration sp = -n . position).
    """
    state, s_free = free_path(state, b)
    s_time = (t_end - t) * speed
    s_exit = -z / dz if dz < 0.0 else math.inf
    sd = -(n[0] * dx + n[1] * dy + n[2] * dz)
    sp = -(n[0] * x + n[1] * y + n[2] * z)
    return state, s_free, s_time, s_exit, sd, sp


@kernel(inline="always")
def turn(state, dx, dy, dz, sample_theta):
    """Scatter the direction (dx, dy, dz) by an angle drawn from p and a uniform azimuth."""
    state, v1 = uniform(state)
    state, v2 = uniform(state)
    nx, ny, nz = scatter(dx, dy, dz, sample_angle(sample_theta, v1), 2.0 * math.pi * v2)
    return state, nx, ny, nz
