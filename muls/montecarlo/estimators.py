"""Compiled estimators of the Monte Carlo: what a scattering event and a target hit send to the receiver.

- **Column, local estimate** at a scattering event: w p(Theta) A cos(theta_r) / d^2 exp(-c d) towards a
  point q of the aperture (MULS Eq. 4 for one event), when the event lies in q's field of view, for
  directions beyond theta_c of the incident one. q is drawn on the smaller of two discs (the aperture, or
  the disc of aperture points whose field holds the event) and A is that disc's area, which bounds the
  estimate by pi tan^2(theta_r/2) next to the window.
- **Column, forward cone** (directions within theta_c of the incident one, where p reaches 10^3 to 10^10
  per sr and a local estimate would be rare and unbounded): one direction drawn from p restricted to the
  cone; if its straight flight lands in the aperture within the field of view it adds w F(theta_c)
  exp(-c s), F the share of p inside the cone and s the flight. Its expectation is the light that leaves
  the event inside the cone and reaches the receiver unscattered, so the two cover every direction once.
- **Target, unscattered return** at a hit of a Lambertian plane: w (rho/pi) cos(theta_e) A cos(theta_r) /
  d^2 exp(-c d) (MULS Eq. 7 for one hit); the hit is also binned for the scattered return
  (:mod:`.reciprocity`).

The arrays and tuples the kernels share (geo, water, times, scene, phase) are described in :mod:`.layout`.
"""

from __future__ import annotations

import math

from ..infra.runtime import kernel
from ..water.phase_kernels import cumulative_at, sample_angle, value_at
from .layout import (
    APERTURE_RADIUS,
    APERTURE_X,
    CONE_APERTURE,
    CONE_APERTURES,
    CONE_FOV,
    CONE_MAX,
    FOV_COS,
    FOV_HALF,
    FOV_TAN,
    WIDE_RAD,
)
from .reciprocity import grid_cell
from .sampling import angle, aperture_point, scatter, uniform


@kernel(inline="always")
def cones(x, y, z, geo):
    """At an event (x, y, z): the direction to the aperture centre and the cones around it and the beam.

    Returns (unit vector to the aperture centre (3), distance d to it [m], the ghosts' aiming cone
    alpha = CONE_FOV tan(theta_r/2) + CONE_APERTURE r_ap / d, their wide cone max(alpha, WIDE_RAD), and
    theta_c = min(CONE_MAX, CONE_APERTURES r_ap / d), the forward cone of the estimates) [rad].
    """
    ex, ey, ez = geo[APERTURE_X] - x, -y, -z
    d = math.sqrt(ex * ex + ey * ey + ez * ez)
    theta_c = min(geo[CONE_MAX], geo[CONE_APERTURES] * geo[APERTURE_RADIUS] / d)
    alpha = min(0.5 * math.pi, geo[CONE_FOV] * geo[FOV_TAN] + geo[CONE_APERTURE] * geo[APERTURE_RADIUS] / d)
    return ex / d, ey / d, ez / d, d, alpha, max(alpha, geo[WIDE_RAD]), theta_c


@kernel
def column_estimate(state, batch, world, first_order, x, y, z, dx, dy, dz, w, t, theta_c, geo, c, speed, phase,
                    times, column, column1):
    """Light a scattering event sends to the receiver unscattered: local estimate beyond theta_c, forward cone.

    (dx, dy, dz): the incident direction; w [1]: the weight; t [s]: the time of the event. Adds to
    column[batch, world] (and column1 for a first scattering) at the arrival time bins.
    """
    ap_x, ap_r = geo[APERTURE_X], geo[APERTURE_RADIUS]
    rf = z * geo[FOV_TAN]
    if (x - ap_x) * (x - ap_x) + y * y > (rf + ap_r) * (rf + ap_r):
        return state  # no aperture point has the event in its field of view
    dt, n_t = times[0], int(times[1])
    state, area, qx, qy = aperture_point(state, x, y, z, ap_x, ap_r, geo[FOV_TAN])
    if area > 0.0:
        vx, vy, vz = qx - x, qy - y, -z
        d = math.sqrt(vx * vx + vy * vy + vz * vz)
        theta = angle(dx, dy, dz, vx, vy, vz)
        if theta >= theta_c:
            # local estimate: w p(Theta) A cos(theta_r) / d^2 exp(-c d) (MULS Eq. 4 for one event)
            est = w * value_at(phase[1], phase[2], phase[3], theta) * area * (z / d) / (d * d) * math.exp(-c * d)
            i = int((t + d / speed) / dt)
            if i < n_t:
                column[batch, world, i] += est
                if first_order:
                    column1[batch, world, i] += est
    if -dz >= math.cos(geo[FOV_HALF] + theta_c):  # else no direction of the cone is inside the field of view
        f = cumulative_at(phase[0], theta_c)
        state, u1 = uniform(state)
        state, u2 = uniform(state)
        fx, fy, fz = scatter(dx, dy, dz, sample_angle(phase[0], u1 * f), 2.0 * math.pi * u2)
        if -fz >= geo[FOV_COS]:
            s = -z / fz
            hx, hy = x + s * fx - ap_x, y + s * fy
            if hx * hx + hy * hy <= ap_r * ap_r:
                est = w * f * math.exp(-c * s)  # the cone's share of p, unscattered over s
                i = int((t + s / speed) / dt)
                if i < n_t:
                    column[batch, world, i] += est
                    if first_order:
                        column1[batch, world, i] += est
    return state


@kernel
def target_hit(state, batch, k, x, y, z, t, w, direct, geo, c, speed, scene, times, target, target_direct, hits):
    """Estimates at a hit of plane k: the unscattered return, and the hit binned for reciprocity.

    target, target_direct (B, K, T): the local estimate (target_direct only when ``direct``, the beam not
    scattered either); hits (B, K, cells, G): (rho/pi) w by receiver-field cell and grid time.
    """
    n, e1, e2, _, origin, edges, grid_start, n_phi, reflectance = scene
    state, area, qx, qy = aperture_point(state, x, y, z, geo[APERTURE_X], geo[APERTURE_RADIUS], geo[FOV_TAN])
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
