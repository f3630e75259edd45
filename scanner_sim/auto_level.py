"""The ``auto`` fidelity level's ray stage: model no more of each pulse than its footprint needs.

Every pulse is first cast with a probe of :data:`PROBE_SUBRAYS` sub-rays, shadow rays included. A pulse is
*simple* when the probe finds one surface the receiver sees alike across the beam: every probe sub-ray hits, all
on the same object, all seen or all unseen by the receiver, their ranges within :data:`SIMPLE_SPREAD_M`. Its echo
is then one echo (the beam axis's hit carrying the whole beam's energy): over a footprint that lies on one
surface within a twentieth of the pulse length, more sub-rays change neither the echo's timing nor its
energy. Every other pulse (an edge, two objects, a partial view of the receiver, a footprint stretched over
range at grazing incidence) is cast again with the level's own pattern, as ``balanced`` casts it.
"""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np

from .beams import BeamPattern, beam_pattern
from .raycast import Hits, cast_beams

#: Sub-rays of the probe: the centre and one ring (``fast``'s pattern).
PROBE_SUBRAYS = 7
#: [m] Largest spread of the probe's hit ranges for a simple pulse: the column-cut bin (fidelity.SUBRAY_CUT_BIN_M),
#: under half the 0.11 m of range one 1 ns sample spans and a twentieth of the 10 ns pulse's 1.1 m.
SIMPLE_SPREAD_M = 0.05


@cache
def _probe(profile: str) -> BeamPattern:
    return beam_pattern(PROBE_SUBRAYS, profile)


def _select(hits: Hits, rows: np.ndarray) -> dict:
    return {f.name: getattr(hits, f.name)[rows] for f in dataclasses.fields(Hits) if f.name not in ("n_pulses",
                                                                                                  "n_subrays")}


def simple_pulses(probe: Hits) -> np.ndarray:
    """(n_pulses,) bool: the probe's sub-rays all hit one object, seen alike by the receiver, within
    :data:`SIMPLE_SPREAD_M` of range (``probe`` in scan order, pulse-major)."""
    n = probe.n_pulses
    count = np.bincount(probe.pulse_index, minlength=n)
    simple = count == probe.n_subrays
    if not simple.any():
        return simple
    starts = np.flatnonzero(np.r_[True, probe.pulse_index[1:] != probe.pulse_index[:-1]]) if len(probe) else []
    owner = probe.pulse_index[starts]

    def spread(values):
        out = np.full(n, np.inf)
        out[owner] = np.maximum.reduceat(values, starts) - np.minimum.reduceat(values, starts)
        return out

    return (simple & (spread(probe.object_id.astype(np.float64)) == 0.0) & (spread(probe.receiver_weight) == 0.0)
            & (spread(probe.range_m) < SIMPLE_SPREAD_M))


def cast_auto(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern: BeamPattern, geometry,
              shadow_rays: bool = True) -> Hits:
    """:func:`scanner_sim.raycast.cast_beams` for the ``auto`` level: one echo for a simple pulse
    (:func:`simple_pulses` of the probe), ``pattern`` for the others. Same arguments and result; rows in scan
    order, and every pulse that hits keeps its axis sub-ray (index 0)."""
    probe = cast_beams(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, _probe(pattern.profile),
                       geometry, shadow_rays)
    simple = simple_pulses(probe)
    axis = (probe.subray_index == 0) & simple[probe.pulse_index]
    kept = _select(probe, np.flatnonzero(axis))
    kept["weight"] = np.bincount(probe.pulse_index, weights=probe.weight, minlength=probe.n_pulses)[kept["pulse_index"]]
    other = np.flatnonzero(~simple)
    recast = cast_beams(caster, scene, beam_origin[other], beam_dir[other], shaft_dir[other], rx_origin[other],
                        rx_dir[other], pattern, geometry, shadow_rays)
    again = _select(recast, slice(None))
    again["pulse_index"] = other[again["pulse_index"]]
    merged = {name: np.concatenate([kept[name], again[name]]) for name in kept}
    order = np.lexsort((merged["subray_index"], merged["pulse_index"]))
    return Hits(**{name: values[order] for name, values in merged.items()}, n_pulses=probe.n_pulses,
                n_subrays=pattern.count)
