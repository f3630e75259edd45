"""Simple footprints as two echoes: where all of a pulse's sub-rays hit one smooth surface within
:data:`COLLAPSE_SPAN_M` of echo range (under the 0.11 m of range one 1 ns sample spans, a tenth of the 10 ns
pulse's 1.1 m), its echo, the pulse shape summed over the sub-ray echoes, is the pulse spread by a distribution
of delay far narrower than the pulse. The two-point Gauss quadrature of that distribution (its energy, mean,
variance and skewness) gives the same echo to the fourth order in the spread over the pulse width: two echoes where
``balanced`` has 19. Each keeps the footprint's energy share and beam share; the axis hit stays as cast, with no
energy, for the pulse's truth and coverage footprint. Every other pulse (an edge, two surfaces, a footprint
stretched over range at grazing incidence) keeps its sub-rays. Used by the ``auto`` level (:mod:`scanner_sim.rays.auto`).

The echo of each sub-ray is what :mod:`scanner_sim.rays.echoes` says it is, the same formulas the pass's hand-off
uses. Rows are :class:`~scanner_sim.rays.hits.HitColumns`, read and written by field name.
"""

from __future__ import annotations

import math

import numpy as np

from muls.infra.runtime import kernel
from muls.instrument.overlap_kernels import aperture_share
from scanner_sim.rays.echoes import echo_energy, echo_range_m
from scanner_sim.rays.hits import Hits, empty_columns, head

#: [m] Widest spread of a footprint's sub-ray echo ranges that is collapsed to two echoes. Through the instrument's
#: 200 MHz analog bandwidth, the two-point rule's echo then differs from the sum of the sub-ray echoes by under
#: 0.5 % of its peak (0.21 % for ranges spread evenly over the whole 0.10 m, 0.30 % in three lumps; 0.05-0.07 % at
#: 5 cm, the span before) and its peak moves under 0.5 mm of range (tests/scanner_sim/rays/test_collapse.py): far
#: under the noise of any echo the ranging accepts. Under the 0.11 m of one 1 ns sample: the two echoes lie within
#: one sample, as one hump, for the deciding-channel test.
COLLAPSE_SPAN_M = 0.10


def simple_pulses(hits: Hits) -> np.ndarray:
    """(n_pulses,) bool: every sub-ray of the pulse hit, all on one surface (``surface_id``), their echo ranges within
    :data:`COLLAPSE_SPAN_M` (``hits`` in scan order, pulse-major): the test
    :func:`collapse_simple` applies."""
    return _simple_flags(hits.pulse_index, hits.echo_range_m, hits.surface_id, hits.n_pulses, hits.n_subrays)


@kernel(nogil=True)
def _simple_flags(pulse, echo_range, surface_id, n_pulses, m):
    out = np.zeros(n_pulses, np.bool_)
    start = 0
    while start < pulse.shape[0]:
        stop = start + 1
        while stop < pulse.shape[0] and pulse[stop] == pulse[start]:
            stop += 1
        out[pulse[start]] = _is_simple(start, stop, m, echo_range, surface_id)
        start = stop
    return out


@kernel(inline="always")
def _is_simple(start, stop, m, echo_range, surface_id):
    """Whether one pulse's rows start .. stop - 1 are all ``m`` sub-rays, on one surface, their echo ranges
    within :data:`COLLAPSE_SPAN_M`."""
    if stop - start != m:
        return False
    lo, hi = np.inf, -np.inf
    for r in range(start, stop):
        if surface_id[r] != surface_id[start]:
            return False
        lo, hi = min(lo, echo_range[r]), max(hi, echo_range[r])
    return hi - lo < COLLAPSE_SPAN_M


def two_point_rule(energy: np.ndarray, delay: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two-point Gauss quadrature of the discrete distributions ``energy`` (n, m) >= 0 over ``delay`` (n, m), rows
    with energy: nodes (n, 2) and each node's share of the energy (n, 2), exact for polynomials of degree 3.

    In standard units z of a row (mean 0, variance 1, third moment g) the nodes are the roots of the orthogonal
    polynomial z^2 - g z - 1, z = (g -/+ sqrt(g^2 + 4)) / 2, with shares z2 / (z2 - z1) and -z1 / (z2 - z1)."""
    n = energy.shape[0]
    nodes, share = np.empty((n, 2)), np.empty((n, 2))
    for i in range(n):
        _rule(energy[i], delay[i], nodes[i], share[i])
    return nodes, share


@kernel(nogil=True)
def _rule(energy, delay, nodes, share):
    """:func:`two_point_rule` of one distribution into ``nodes`` (2,) and ``share`` (2,)."""
    total = 0.0
    mean = 0.0
    for k in range(energy.shape[0]):
        total += energy[k]
        mean += energy[k] * delay[k]
    mean /= total
    var, third = 0.0, 0.0
    for k in range(energy.shape[0]):
        d = delay[k] - mean
        var += energy[k] * d * d
        third += energy[k] * d * d * d
    sd = math.sqrt(var / total)
    g = third / total / sd**3 if sd > 0.0 else 0.0
    root = math.sqrt(g * g + 4.0)
    z1, z2 = 0.5 * (g - root), 0.5 * (g + root)
    nodes[0], nodes[1] = mean + sd * z1, mean + sd * z2
    share[0], share[1] = z2 / root, -z1 / root


@kernel(nogil=True)
def pulse_figures(start, stop, m, rows, angles, energy, tau, nodes, share):
    """The simple-pulse figures of one pulse's rows start .. stop - 1 of ``rows`` (:class:`HitColumns`; its
    ``incidence_rad`` the angles if ``angles``, else their cosines): (beam, rho_mean, cosine, mean_range) with beam -1
    when the pulse is not simple (:func:`simple_pulses`' test) and 0 when no light comes back; for a lit simple
    pulse its two echoes' delays ``nodes`` (as echo ranges [m]) and energy ``share`` (:func:`two_point_rule`).
    ``energy``, ``tau``: (m,) scratch."""
    if not _is_simple(start, stop, m, rows.echo_range_m, rows.surface_id):
        return -1.0, 0.0, 0.0, 0.0
    total, w_sum, rho_sum, r_sum = 0.0, 0.0, 0.0, 0.0
    for k in range(m):
        r = start + k
        cos_r = math.cos(rows.incidence_rad[r]) if angles else rows.incidence_rad[r]
        energy[k] = echo_energy(rows.weight[r], rows.reflectance[r], cos_r, rows.receiver_weight[r])
        tau[k] = rows.echo_range_m[r]
        total += energy[k]
        w_sum += rows.weight[r]
        rho_sum += rows.weight[r] * rows.reflectance[r]
        r_sum += rows.weight[r] * rows.range_m[r]
    if total <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    _rule(energy, tau, nodes, share)
    return w_sum, rho_sum / w_sum, min(1.0, total / rho_sum), r_sum / w_sum


@kernel(inline="always")
def cast_pulse_figures(prim, tfar, p, rays, layout, faces, view, energy, tau, nodes, share):
    """:func:`pulse_figures` of pulse ``p`` straight from its cast, where every one of its m sub-rays hit: face
    ``prim`` (m,) at distance ``tfar`` (m,) (as Embree answers; :mod:`scanner_sim.rays.kernels`' inputs). The same
    numbers as :func:`pulse_figures` of the rows :func:`scanner_sim.rays.kernels.hit_block` would write, without
    writing them: a simple pulse then needs only its axis row. The incidence, echo range and receiver weight are
    ``hit_block``'s arithmetic, step for step (a test holds the two to the bit)."""
    beam_local, beam_dir, u, v, rx_local, rx_dir = rays
    xy, weights, r_t, tan_h = layout
    face_normal, surface_id, face_reflectance = faces.normal, faces.surface_id, faces.reflectance
    m = prim.shape[0]
    surface = surface_id[prim[0]]
    rx, ry, rz = rx_local[p, 0], rx_local[p, 1], rx_local[p, 2]
    kx, ky, kz = rx_dir[p, 0], rx_dir[p, 1], rx_dir[p, 2]
    lo, hi = np.inf, -np.inf
    total, w_sum, rho_sum, r_sum = 0.0, 0.0, 0.0, 0.0
    for j in range(m):
        f = prim[j]
        if surface_id[f] != surface:
            return -1.0, 0.0, 0.0, 0.0
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
        t = np.float64(tfar[j])
        qx = beam_local[p, 0] + r_t * ax + t * dx
        qy = beam_local[p, 1] + r_t * ay + t * dy
        qz = beam_local[p, 2] + r_t * az + t * dz
        nx, ny, nz = face_normal[f, 0], face_normal[f, 1], face_normal[f, 2]
        dn = nx * dx + ny * dy + nz * dz
        if dn > 0.0:
            nx, ny, nz, dn = -nx, -ny, -nz, -dn
        cosine = -dn if -dn < 1.0 else 1.0
        tx, ty, tz = rx - qx, ry - qy, rz - qz
        dist = math.sqrt(tx * tx + ty * ty + tz * tz)
        echo = echo_range_m(t, np.float64(np.float32(dist)))
        along = -(tx * kx + ty * ky + tz * kz)
        if view.finite:
            seen = aperture_share(view.aperture_radius, view.tan_half_fov, along,
                                  math.sqrt(max(dist * dist - along * along, 0.0)))
        else:
            behind = along + view.apex_behind
            wx, wy, wz = qx - (rx - view.apex_behind * kx), qy - (ry - view.apex_behind * ky), qz - (rz - view.apex_behind * kz)
            seen = 1.0 if behind >= view.cos_half_fov * math.sqrt(wx * wx + wy * wy + wz * wz) else 0.0
        if not (seen > 0.0 and nx * tx + ny * ty + nz * tz > 0.0):
            seen = 0.0
        lo, hi = min(lo, echo), max(hi, echo)
        weight, reflectance = weights[j], face_reflectance[f]
        energy[j] = echo_energy(weight, reflectance, cosine, seen)
        tau[j] = echo
        total += energy[j]
        w_sum += weight
        rho_sum += weight * reflectance
        r_sum += weight * t
    if not hi - lo < COLLAPSE_SPAN_M:
        return -1.0, 0.0, 0.0, 0.0
    if total <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    _rule(energy, tau, nodes, share)
    return w_sum, rho_sum / w_sum, min(1.0, total / rho_sum), r_sum / w_sum


@kernel(nogil=True)
def _copy_row(rows, r, angles, out, o):
    """Row r of ``rows`` into row o of ``out``, incidence out in radians."""
    out.pulse_index[o], out.subray_index[o], out.range_m[o] = rows.pulse_index[r], rows.subray_index[r], rows.range_m[r]
    out.reflectance[o], out.label[o], out.object_id[o] = rows.reflectance[r], rows.label[r], rows.object_id[r]
    out.surface_id[o] = rows.surface_id[r]
    out.incidence_rad[o] = rows.incidence_rad[r] if angles else math.acos(rows.incidence_rad[r])
    for a in range(3):
        out.point[o, a] = rows.point[r, a]
        out.normal[o, a] = rows.normal[r, a]
    out.receiver_weight[o], out.weight[o], out.echo_range_m[o] = (rows.receiver_weight[r], rows.weight[r],
                                                                  rows.echo_range_m[r])


@kernel(nogil=True)
def emit_rows(start, stop, rows, angles, out, o, beam, rho_mean, cosine, mean_range, nodes, share):
    """Write one pulse's rows start .. stop - 1 of ``rows`` into ``out`` from row o as :func:`collapse_simple`
    keeps them (all as they are if ``beam`` < 0, else the axis row with no energy share and, with light, its two
    echoes; incidence out in radians); returns the next free row."""
    simple = beam >= 0.0
    for r in range(start, stop):
        if simple and rows.subray_index[r] != 0:
            continue
        _copy_row(rows, r, angles, out, o)
        o += 1
        if not simple:
            continue
        axis = o - 1
        out.weight[axis] = 0.0
        if beam == 0.0:
            continue
        incidence = math.acos(cosine)
        for c in range(2):  # the footprint's two echoes, built on its axis hit (copied as written: in radians)
            _copy_row(out, axis, True, out, o)
            out.subray_index[o] = c + 1
            out.weight[o] = beam * share[c]
            out.reflectance[o] = rho_mean
            out.incidence_rad[o] = incidence
            out.receiver_weight[o] = 1.0
            out.range_m[o] = mean_range
            # Out along the footprint's mean range (where the water column is cut), back along the return leg
            # (float32, as every hit's) that makes up the node's delay.
            out.echo_range_m[o] = echo_range_m(mean_range, np.float64(np.float32(2.0 * nodes[c] - mean_range)))
            o += 1
    return o


@kernel(nogil=True)
def _collapse_rows(rows, angles, m, out):
    """:func:`collapse_simple` of the pulse-major ``rows`` into ``out`` (room for every row); returns the rows
    written."""
    pulse = rows.pulse_index
    energy, tau, nodes, share = np.empty(m), np.empty(m), np.empty(2), np.empty(2)
    start, o = 0, 0
    while start < pulse.shape[0]:
        stop = start + 1
        while stop < pulse.shape[0] and pulse[stop] == pulse[start]:
            stop += 1
        beam, rho_mean, cosine, mean_range = pulse_figures(start, stop, m, rows, angles, energy, tau, nodes, share)
        o = emit_rows(start, stop, rows, angles, out, o, beam, rho_mean, cosine, mean_range, nodes, share)
        start = stop
    return o


def collapse_simple(hits: Hits) -> Hits:
    """``hits`` with each simple pulse's sub-rays (:func:`simple_pulses`) replaced by its axis hit as cast with
    no energy share (sub-ray 0, weight 0) and two echoes (sub-rays 1 and 2) of its :func:`two_point_rule` over
    echo range, weighted by each sub-ray's :func:`~scanner_sim.rays.echoes.echo_energy`. Each echo carries its
    share of the footprint's beam share, the footprint's beam-weighted reflectance, and the cosine that gives it
    its share of the energy; its range along the beam is the footprint's beam-weighted mean range (where a
    footprint within one bin cuts the water column, survey.handoff.column_cuts) and its echo range the node's.
    Other pulses keep their rows. ``hits`` as :func:`scanner_sim.rays.cast.cast_beams` gives them: pulse-major,
    sub-rays ascending; the result too. Compiled, in one pass over the rows."""
    out = empty_columns(len(hits))
    k = _collapse_rows(hits.columns(), True, hits.n_subrays, out)
    return Hits.from_columns(head(out, k), hits.n_pulses, hits.n_subrays, copy=True)
