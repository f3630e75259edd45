"""Compiled estimators of the Monte Carlo: what a scattering event and a target hit send to the receiver.

- **Column, local estimate** at a scattering event: w p(Theta) A cos(theta_r) / d^2 exp(-c d) towards a
  point q of the aperture (MULS Eq. 4 for one event), when the event lies in q's field of view, for
  directions beyond theta_c of the incident one. q is drawn on the smaller of two discs (the aperture, or
  the disc of aperture points whose field holds the event) and A is that disc's area, which bounds the
  estimate by pi tan^2(theta_r/2) next to the window.
- **Target, unscattered return** at a hit of a Lambertian plane: w (rho/pi) cos(theta_e) A cos(theta_r) /
  d^2 exp(-c d) (MULS Eq. 7 for one hit); the hit is also binned for the scattered return
  (:mod:`.reciprocity`).

Arguments shared by the kernels: ``geo`` (see :mod:`.transport`), ``phase`` = (sampling table, ln p table,
ln theta of its first point, 1 / its step), ``scene`` = (plane normal n towards the instrument, in-plane
axes e1, e2, penetration depth of each plane (K,), grid origins (K, 3), ring edges (K, n_r + 1), grid start
times (K,), azimuth sectors, reflectance), ``times`` = (histogram step, histogram length, grid step, grid
length, end of the run).
"""

from __future__ import annotations

import math

import numba

from ..phase import value_at
from .reciprocity import grid_cell
from .sampling import angle, aperture_point


@numba.njit(cache=True, inline="always")
def cones(x, y, z, geo):
    """At an event (x, y, z): the unit vector to the aperture centre, the ghost cone's half-angle and theta_c.

    theta_c = min(CONE_MAX_RAD, CONE_APERTURES r_ap / d): the forward cone the local estimate leaves out;
    the ghost cone: GHOST_CONE_FOV tan(theta_r/2) + GHOST_CONE_APERTURE r_ap / d (see :mod:`.transport`).
    """
    ex, ey, ez = geo[2] - x, -y, -z
    d = math.sqrt(ex * ex + ey * ey + ez * ez)
    theta_c = min(geo[7], geo[6] * geo[3] / d)
    alpha = min(0.5 * math.pi, geo[11] * geo[4] + geo[13] * geo[3] / d)
    return ex / d, ey / d, ez / d, alpha, theta_c


@numba.njit(cache=True)
def column_estimate(state, batch, world, first_order, x, y, z, dx, dy, dz, w, t, theta_c, geo, c, speed, phase,
                    times, column, column1):
    """Local estimate of a scattering event towards the aperture, for directions beyond theta_c.

    Adds to column[batch, world] (and column1 for a first scattering) at the arrival time bin.
    """
    state, area, qx, qy = aperture_point(state, x, y, z, geo[2], geo[3], geo[4])
    if area > 0.0:
        vx, vy, vz = qx - x, qy - y, -z
        d = math.sqrt(vx * vx + vy * vy + vz * vz)
        theta = angle(dx, dy, dz, vx, vy, vz)
        if theta >= theta_c:
            # local estimate: w p(Theta) A cos(theta_r) / d^2 exp(-c d) (MULS Eq. 4 for one event)
            est = w * value_at(phase[1], phase[2], phase[3], theta) * area * (z / d) / (d * d) * math.exp(-c * d)
            i = int((t + d / speed) / times[0])
            if i < int(times[1]):
                column[batch, world, i] += est
                if first_order:
                    column1[batch, world, i] += est
    return state


@numba.njit(cache=True)
def target_hit(state, batch, k, x, y, z, t, w, direct, geo, c, speed, scene, times, target, target_direct, hits):
    """Estimates at a hit of plane k: the unscattered return, and the hit binned for reciprocity.

    target, target_direct (B, K, T): the local estimate (target_direct only when ``direct``, the beam not
    scattered either); hits (B, K, cells, G): (rho/pi) w by receiver-field cell and grid time.
    """
    n, e1, e2, _, origin, edges, grid_start, n_phi, reflectance = scene
    state, area, qx, qy = aperture_point(state, x, y, z, geo[2], geo[3], geo[4])
    if area > 0.0:
        vx, vy, vz = qx - x, qy - y, -z
        d = math.sqrt(vx * vx + vy * vy + vz * vz)
        cos_e = (n[0] * vx + n[1] * vy + n[2] * vz) / d
        if cos_e > 0.0:
            # Lambertian local estimate: w (rho/pi) cos(theta_e) A cos(theta_r) / d^2 exp(-c d) (MULS Eq. 7)
            est = w * reflectance / math.pi * cos_e * area * (z / d) / (d * d) * math.exp(-c * d)
            i = int((t + d / speed) / times[0])
            if i < int(times[1]):
                target[batch, k, i] += est
                if direct:
                    target_direct[batch, k, i] += est
    cell = grid_cell(k, x, y, z, origin, e1, e2, edges, n_phi)
    j = int(math.floor((t - grid_start[k]) / times[2]))
    if cell >= 0 and 0 <= j < int(times[3]):
        hits[batch, k, cell, j] += w * reflectance / math.pi
    return state
