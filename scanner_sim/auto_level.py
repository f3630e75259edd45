"""The ``auto`` fidelity level's ray stage: cast as ``balanced`` casts, but give a simple footprint two echoes.

The physics' cost goes with the echoes, one per sub-ray hit; the rays are cheap beside it. A pulse is *simple*
when all of its sub-rays hit one object within :data:`SIMPLE_SPREAD_M` of echo range (a twentieth of the 10 ns
pulse's 1.1 m, under half of one 1 ns sample). Its echo, the pulse shape summed over the sub-ray echoes, is then
the pulse spread by a distribution of delay far narrower than the pulse, and the two-point Gauss quadrature of
that distribution (its energy, mean, variance and skewness) gives the same echo to the fourth order in the
spread over the pulse width: two echoes where ``balanced`` has 19. Each keeps the footprint's energy share and
beam share; the axis hit stays as cast, with no energy, for the pulse's truth and coverage footprint. Every
other pulse (an edge, two objects, a footprint stretched over range at grazing incidence) keeps its sub-rays.
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np

from .beams import BeamPattern
from .raycast import Hits, cast_beams

#: [m] Largest spread of a simple pulse's echo ranges: the column-cut bin (fidelity.SUBRAY_CUT_BIN_M), under half
#: the 0.11 m of range one 1 ns sample spans and a twentieth of the 10 ns pulse's 1.1 m.
SIMPLE_SPREAD_M = 0.05


def _echo_range(hits: Hits) -> np.ndarray:
    return 0.5 * (hits.range_m + hits.rx_distance_m)  # survey.hit_echo_range_m


def simple_pulses(hits: Hits) -> np.ndarray:
    """(n_pulses,) bool: every sub-ray of the pulse hit, all on one object, their echo ranges within
    :data:`SIMPLE_SPREAD_M` (``hits`` in scan order, pulse-major)."""
    n = hits.n_pulses
    simple = np.bincount(hits.pulse_index, minlength=n) == hits.n_subrays
    if not simple.any():
        return simple
    starts = np.flatnonzero(np.r_[True, hits.pulse_index[1:] != hits.pulse_index[:-1]])
    owner = hits.pulse_index[starts]

    def spread(values):
        out = np.full(n, np.inf)
        out[owner] = np.maximum.reduceat(values, starts) - np.minimum.reduceat(values, starts)
        return out

    return simple & (spread(hits.object_id.astype(np.float64)) == 0.0) & (spread(_echo_range(hits)) < SIMPLE_SPREAD_M)


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
def _collapse(first, m, weight, reflectance, incidence, seen, range_m, rx_m, nodes, share, beam, rho_mean, cosine,
              mean_range):
    """Per simple pulse (its rows ``first[i]`` to ``first[i] + m``): its two echoes' delays ``nodes`` and energy
    ``share`` (:func:`_rule` over echo range), beam share, beam-weighted reflectance, effective cosine and
    beam-weighted mean range; ``beam`` 0 where no light comes back."""
    energy = np.empty(m)
    tau = np.empty(m)
    for i in range(first.shape[0]):
        total, w_sum, rho_sum, r_sum = 0.0, 0.0, 0.0, 0.0
        for k in range(m):
            r = first[i] + k
            energy[k] = weight[r] * reflectance[r] * math.cos(incidence[r]) * seen[r]
            tau[k] = 0.5 * (range_m[r] + rx_m[r])
            total += energy[k]
            w_sum += weight[r]
            rho_sum += weight[r] * reflectance[r]
            r_sum += weight[r] * range_m[r]
        if total <= 0.0:
            beam[i] = 0.0
            continue
        _rule(energy, tau, nodes[i], share[i])
        beam[i] = w_sum
        rho_mean[i] = rho_sum / w_sum
        cosine[i] = min(1.0, total / rho_sum)
        mean_range[i] = r_sum / w_sum


def collapse_simple(hits: Hits) -> Hits:
    """``hits`` with each simple pulse's sub-rays (:func:`simple_pulses`) replaced by its axis hit as cast with
    no energy share (sub-ray 0, weight 0) and two echoes (sub-rays 1 and 2) of its :func:`two_point_rule` over
    echo range, weighted by energy (weight x reflectance x cosine of incidence x receiver weight, the echo
    weight of survey.pulse_batch). Each echo carries its share of the footprint's beam share, the footprint's
    beam-weighted reflectance, and the cosine that gives it its share of the energy; its outgoing leg is the
    footprint's beam-weighted mean range (where a footprint within one 5 cm bin cuts the water column,
    fidelity.column_cuts), its return leg what makes up its delay. Other pulses keep their rows. ``hits`` as
    :func:`scanner_sim.raycast.cast_beams` gives them: pulse-major, sub-rays ascending; the result too."""
    m = hits.n_subrays
    simple = simple_pulses(hits)
    rows = simple[hits.pulse_index]
    first = np.flatnonzero(rows)[::m]  # each simple pulse's axis row; its m rows follow
    k = first.size
    nodes, share = np.empty((k, 2)), np.empty((k, 2))
    beam, rho_mean, cosine, mean_range = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    _collapse(first, m, hits.weight, hits.reflectance, hits.incidence_rad, hits.receiver_weight, hits.range_m,
              hits.rx_distance_m, nodes, share, beam, rho_mean, cosine, mean_range)
    lit = beam > 0.0
    # Rows kept: every row of the other pulses; of a simple pulse its axis row, three times over if it has light.
    repeat = np.where(rows, 0, 1)
    repeat[first] = np.where(lit, 3, 1)
    take = np.repeat(np.arange(len(hits)), repeat)
    out = {f.name: getattr(hits, f.name)[take] for f in dataclasses.fields(Hits)
           if f.name not in ("n_pulses", "n_subrays")}
    axis_at = (np.cumsum(repeat) - repeat)[first]  # each axis row's place in the result
    out["weight"][axis_at] = 0.0
    at = (axis_at[lit][:, None] + np.array([1, 2])).ravel()
    out["subray_index"][at] = np.tile(np.array([1, 2], out["subray_index"].dtype), int(lit.sum()))
    out["weight"][at] = (beam[lit, None] * share[lit]).ravel()
    out["reflectance"][at] = np.repeat(rho_mean[lit], 2)
    out["incidence_rad"][at] = np.repeat(np.arccos(cosine[lit]), 2)
    out["receiver_weight"][at] = 1.0
    out["range_m"][at] = np.repeat(mean_range[lit], 2)
    out["rx_distance_m"][at] = (2.0 * nodes[lit] - mean_range[lit, None]).ravel()
    return Hits(**out, n_pulses=hits.n_pulses, n_subrays=m)


def cast_auto(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern: BeamPattern, geometry,
              shadow_rays: bool = True) -> Hits:
    """:func:`scanner_sim.raycast.cast_beams` for the ``auto`` level: ``balanced``'s cast, each simple pulse's
    echoes collapsed to two (:func:`collapse_simple`). Same arguments and result; rows in scan order."""
    return collapse_simple(cast_beams(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern,
                                      geometry, shadow_rays))
