"""Simple footprints as two echoes: where all of a pulse's sub-rays hit one object within :data:`SIMPLE_SPREAD_M`
of echo range (a twentieth of the 10 ns pulse's 1.1 m, under half of one 1 ns sample), its echo, the pulse shape
summed over the sub-ray echoes, is the pulse spread by a distribution of delay far narrower than the pulse. The
two-point Gauss quadrature of that distribution (its energy, mean, variance and skewness) gives the same echo to
the fourth order in the spread over the pulse width: two echoes where ``balanced`` has 19. Each keeps the
footprint's energy share and beam share; the axis hit stays as cast, with no energy, for the pulse's truth and
coverage footprint. Every other pulse (an edge, two objects, a footprint stretched over range at grazing
incidence) keeps its sub-rays. Used by the ``auto`` level (:mod:`scanner_sim.rays.auto`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from scanner_sim.rays.cast import Hits

#: [m] Largest spread of a simple pulse's echo ranges: the column-cut bin (fidelity.SUBRAY_CUT_BIN_M), under half
#: the 0.11 m of range one 1 ns sample spans and a twentieth of the 10 ns pulse's 1.1 m.
SIMPLE_SPREAD_M = 0.05


def simple_pulses(hits: Hits) -> np.ndarray:
    """(n_pulses,) bool: every sub-ray of the pulse hit, all on one object, their echo ranges within
    :data:`SIMPLE_SPREAD_M` (``hits`` in scan order, pulse-major): the test :func:`collapse_simple` applies."""
    return _simple_flags(hits.pulse_index, hits.range_m, hits.rx_distance_m, hits.object_id, hits.n_pulses,
                         hits.n_subrays)


@numba.njit(cache=True, nogil=True)
def _simple_flags(pulse, range_m, rx_m, object_id, n_pulses, m):
    out = np.zeros(n_pulses, np.bool_)
    start = 0
    while start < pulse.shape[0]:
        stop = start + 1
        while stop < pulse.shape[0] and pulse[stop] == pulse[start]:
            stop += 1
        out[pulse[start]] = _is_simple(start, stop, m, range_m, rx_m, object_id)
        start = stop
    return out


@numba.njit(cache=True, inline="always")
def _is_simple(start, stop, m, range_m, rx_m, object_id):
    """Whether one pulse's rows start .. stop - 1 are all ``m`` sub-rays, on one object, their echo ranges
    within :data:`SIMPLE_SPREAD_M`."""
    if stop - start != m:
        return False
    lo, hi = np.inf, -np.inf
    for r in range(start, stop):
        if object_id[r] != object_id[start]:
            return False
        e = 0.5 * (range_m[r] + rx_m[r])  # the echo's range (survey.hit_echo_range_m)
        lo, hi = min(lo, e), max(hi, e)
    return hi - lo < SIMPLE_SPREAD_M


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


@numba.njit(cache=True, nogil=True)
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


@numba.njit(cache=True, nogil=True)
def pulse_figures(start, stop, m, fields, angles, energy, tau, nodes, share):
    """The simple-pulse figures of one pulse's rows start .. stop - 1 of ``fields`` (:data:`HIT_FIELDS` order;
    incidence angles [rad] if ``angles``, else their cosines): (beam, rho_mean, cosine, mean_range) with beam -1
    when the pulse is not simple (:func:`simple_pulses`' test) and 0 when no light comes back; for a lit simple
    pulse its two echoes' delays ``nodes`` and energy ``share`` (:func:`two_point_rule`). ``energy``, ``tau``:
    (m,) scratch."""
    _, _, range_m, _, _, incidence, reflectance, _, object_id, seen, weight, rx_m = fields
    if not _is_simple(start, stop, m, range_m, rx_m, object_id):
        return -1.0, 0.0, 0.0, 0.0
    total, w_sum, rho_sum, r_sum = 0.0, 0.0, 0.0, 0.0
    for k in range(m):
        r = start + k
        cos_r = math.cos(incidence[r]) if angles else incidence[r]
        energy[k] = weight[r] * reflectance[r] * cos_r * seen[r]
        tau[k] = 0.5 * (range_m[r] + rx_m[r])
        total += energy[k]
        w_sum += weight[r]
        rho_sum += weight[r] * reflectance[r]
        r_sum += weight[r] * range_m[r]
    if total <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    _rule(energy, tau, nodes, share)
    return w_sum, rho_sum / w_sum, min(1.0, total / rho_sum), r_sum / w_sum


@numba.njit(cache=True, nogil=True)
def emit_rows(start, stop, fields, angles, out, o, beam, rho_mean, cosine, mean_range, nodes, share):
    """Write one pulse's rows start .. stop - 1 of ``fields`` into ``out`` from row o as :func:`collapse_simple`
    keeps them (all as they are if ``beam`` < 0, else the axis row with no energy share and, with light, its two
    echoes; incidence out in radians); returns the next free row."""
    (pi, sub, rng, pt, nrm, inc, refl, lab, obj, seen, wt, rx) = fields
    (po, so, ro, pto, no, io, fo, lo, oo, sno, wo, rxo) = out
    simple = beam >= 0.0
    for r in range(start, stop):
        if simple and sub[r] != 0:
            continue
        copies = 1 if not simple or beam == 0.0 else 3
        for c in range(copies):
            po[o], so[o], ro[o], fo[o], lo[o], oo[o] = pi[r], sub[r], rng[r], refl[r], lab[r], obj[r]
            io[o] = inc[r] if angles else math.acos(inc[r])
            for a in range(3):
                pto[o, a] = pt[r, a]
                no[o, a] = nrm[r, a]
            sno[o], wo[o], rxo[o] = seen[r], wt[r], rx[r]
            if simple:
                if c == 0:
                    wo[o] = 0.0
                else:
                    so[o] = c
                    wo[o] = beam * share[c - 1]
                    fo[o] = rho_mean
                    io[o] = math.acos(cosine)
                    sno[o] = 1.0
                    ro[o] = mean_range
                    rxo[o] = 2.0 * nodes[c - 1] - mean_range
            o += 1
    return o


@numba.njit(cache=True, nogil=True)
def _collapse_rows(fields, angles, m, out):
    """:func:`collapse_simple` of the pulse-major rows ``fields`` into ``out`` (room for every row); returns the
    rows written."""
    pulse = fields[0]
    energy, tau, nodes, share = np.empty(m), np.empty(m), np.empty(2), np.empty(2)
    start, o = 0, 0
    while start < pulse.shape[0]:
        stop = start + 1
        while stop < pulse.shape[0] and pulse[stop] == pulse[start]:
            stop += 1
        beam, rho_mean, cosine, mean_range = pulse_figures(start, stop, m, fields, angles, energy, tau, nodes, share)
        o = emit_rows(start, stop, fields, angles, out, o, beam, rho_mean, cosine, mean_range, nodes, share)
        start = stop
    return o


HIT_FIELDS = ("pulse_index", "subray_index", "range_m", "point", "normal", "incidence_rad", "reflectance", "label",
              "object_id", "receiver_weight", "weight", "rx_distance_m")


def collapse_simple(hits: Hits) -> Hits:
    """``hits`` with each simple pulse's sub-rays (:func:`simple_pulses`) replaced by its axis hit as cast with
    no energy share (sub-ray 0, weight 0) and two echoes (sub-rays 1 and 2) of its :func:`two_point_rule` over
    echo range, weighted by energy (weight x reflectance x cosine of incidence x receiver weight, the echo
    weight of survey.pulse_batch). Each echo carries its share of the footprint's beam share, the footprint's
    beam-weighted reflectance, and the cosine that gives it its share of the energy; its outgoing leg is the
    footprint's beam-weighted mean range (where a footprint within one 5 cm bin cuts the water column,
    fidelity.column_cuts), its return leg what makes up its delay. Other pulses keep their rows. ``hits`` as
    :func:`scanner_sim.rays.cast.cast_beams` gives them: pulse-major, sub-rays ascending; the result too. Compiled,
    in one pass over the rows."""
    fields = tuple(getattr(hits, f) for f in HIT_FIELDS)
    out = tuple(np.empty(a.shape, a.dtype) for a in fields)
    k = _collapse_rows(fields, True, hits.n_subrays, out)
    return Hits(**{f: a[:k].copy() for f, a in zip(HIT_FIELDS, out)}, n_pulses=hits.n_pulses,
                n_subrays=hits.n_subrays)
