"""Bands over a family of phase functions on the answers people read: run a study once per member of the family
(:data:`muls.water.phase_family.SENSITIVITY_FAMILY`), the default with the model's own tables and the others with
quicker table runs (:func:`muls.montecarlo.tables.table_packets`), and give each figure as (low, median, high)
beside the default."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TypeVar

import numpy as np

from ..montecarlo.tables import table_packets
from ..water.phase_family import DEFAULT_PHASE, SENSITIVITY_FAMILY, PhaseMember, phase_from_spec
from ..water.properties import Water

T = TypeVar("T")

#: Beam packets of a non-default member's table run, an eighth of the standard run's: in the pond 100,000 packets took
#: 45 s of one core (shared machine) with relative errors of 0.3-0.5 % on the echo energy at 2-20 m, 20,000 took
#: 0.6-1.0 %; 50,000 give a member in about 23 s of one core and errors under 1 %, well inside the bands (tens of %:
#: docs/studies.md).
BAND_PACKETS = 50_000


def over_family(run: Callable[[Water], T], water: Water, family: tuple[PhaseMember, ...] = SENSITIVITY_FAMILY,
                packets: int = BAND_PACKETS) -> list[T]:
    """``run(water with each member's phase function)`` per member, in the family's order; the default member with
    the standard tables, the others with tables of ``packets`` beam packets."""
    out = []
    for member in family:
        w = replace(water, phase_function=member.spec)
        if member.spec == DEFAULT_PHASE:
            out.append(run(w))
        else:
            with table_packets(packets):
                out.append(run(w))
    return out


def band(values, labels: list[str], digits: int = 4) -> dict:
    """{"default", "low", "median", "high", "low_member", "high_member"} of ``values`` (one per member, the default
    first; None where a member gives no value: not counted)."""
    v = np.array([np.nan if x is None else float(x) for x in values])
    finite = np.isfinite(v)
    if not finite.any():
        return {"default": None, "low": None, "median": None, "high": None, "low_member": None, "high_member": None}
    lo, hi = int(np.nanargmin(v)), int(np.nanargmax(v))
    return {"default": None if not finite[0] else round(float(v[0]), digits),
            "low": round(float(v[lo]), digits), "median": round(float(np.nanmedian(v)), digits),
            "high": round(float(v[hi]), digits), "low_member": labels[lo], "high_member": labels[hi]}


def family_summary(family: tuple[PhaseMember, ...] = SENSITIVITY_FAMILY, packets: int = BAND_PACKETS) -> dict:
    """What a band's summary says of its family: the phase function of the default, that a band was computed, and
    each member with its source and b_b/b."""
    return {"phase_function": f"{DEFAULT_PHASE} (default)", "band": True, "packets_members": int(packets),
            "phase_functions": [{"label": m.label, "spec": m.spec, "source": m.source,
                         "backscatter_ratio": round(phase_from_spec(m.spec).backscatter_fraction, 5)}
                        for m in family]}


def experiment_band(experiment="pond", shots: int | None = None, seed: int = 0, ranging: str = "prototype",
                    family: tuple[PhaseMember, ...] = SENSITIVITY_FAMILY, packets: int = BAND_PACKETS) -> dict:
    """The paper's tank test (:func:`muls.studies.experiment.experiment_study`) once per phase function of
    ``family``: per distance and channel the band of the detected fraction and of the bias [m], and every member's
    detected fractions (``members``), with :func:`family_summary`."""
    from ..experiments import EXPERIMENT_SHOTS, Experiment, experiment_preset
    from .experiment import experiment_study

    exp = experiment if isinstance(experiment, Experiment) else experiment_preset(experiment)
    shots = EXPERIMENT_SHOTS if shots is None else shots
    results = over_family(lambda w: experiment_study(replace(exp, water=w), shots, seed, ranging, waveforms=False),
                          exp.water, family, packets)
    labels = [m.label for m in family]
    distances = {
        d: {ch: {"detected_fraction": band([r["distances"][d][ch]["detected_fraction"] for r in results], labels),
                 "bias_m": band([r["distances"][d][ch]["bias_m"] for r in results], labels)}
            for ch in chans}
        for d, chans in results[0]["distances"].items()}
    members = {label: {d: {ch: st["detected_fraction"] for ch, st in chans.items()}
                       for d, chans in r["distances"].items()} for label, r in zip(labels, results)}
    return {"distances": distances, "members": members, **family_summary(family, packets)}


#: The figures of ``muls maxrange`` per water that carry a band.
MAXRANGE_FIGURES = ("single_channel_m", "near_field_m", "far_field_m", "total_m", "improvement")


def maxrange_band(waters, shots: int = 200, reflectance: float = 0.1, seed: int = 0,
                  attenuation_model: str | None = None, family: tuple[PhaseMember, ...] = SENSITIVITY_FAMILY,
                  packets: int = BAND_PACKETS) -> dict:
    """The maximum-range study (:func:`muls.studies.maxrange.maxrange_study`) once per phase function of ``family``,
    water by water: per water the band of each figure of :data:`MAXRANGE_FIGURES` [m] and every member's figures,
    with :func:`family_summary`. A member whose range is None (nothing detectable) is left out of that band."""
    from ..presets import water_preset
    from .maxrange import maxrange_study

    names = [waters] if isinstance(waters, (str, Water)) else list(waters)
    labels = [m.label for m in family]
    out = {}
    for name in names:
        water = name if isinstance(name, Water) else water_preset(name)
        results = over_family(lambda w: maxrange_study([w], shots=shots, reflectance=reflectance, seed=seed,
                                                       attenuation_model=attenuation_model)[w.name],
                              water, family, packets)
        out[water.name] = {"figures": {f: band([r[f] for r in results], labels, 3) for f in MAXRANGE_FIGURES},
                           "members": {label: {f: r[f] for f in MAXRANGE_FIGURES}
                                       for label, r in zip(labels, results)}}
    return {"waters": out, **family_summary(family, packets)}
