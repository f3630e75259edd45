"""How far a water's unknown phase function moves the lidar's answer: the band over a stated family (``muls
sensitivity``).

A water measured by c and a (or a preset) leaves its phase function unknown. For each member of a family of
phase functions (:data:`muls.water.phase_family.SENSITIVITY_FAMILY`, each with its source) the Monte Carlo builds
the water's tables once (cached per phase function), and the model gives, for a flat Lambertian plate at each range,
the echo's energy, its peak power, the delay of its peak after the straight path's, and the water column's power at
the echo's time. The band per range is (min, median, max) over the members, beside the model's default (Petzold's
average, the shipped tables); the input that moves it most is the sub-family with the widest spread.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from ..infra.errors import ParameterError, check_fraction
from ..montecarlo.scattering_tables import ScatteringTables
from ..montecarlo.tables import TABLE_PACKETS, TABLE_SEED, find_or_build_tables
from ..optics.optical_model import OpticalModel, PulseBatch
from ..presets import mul2023, study_water
from ..water.phase_family import DEFAULT_PHASE, SENSITIVITY_FAMILY, PhaseMember, phase_from_spec
from ..water.properties import Water
from .bands import BAND_PACKETS
from .common import _ranges, _water

#: Plate ranges of the study [m]: 2 to 20 m every metre.
SENSITIVITY_RANGES_M = tuple(float(r) for r in range(2, 21))
#: Beam packets of a member's table run (the default member uses the model's own, :data:`TABLE_PACKETS`): the bands'
#: (:data:`muls.studies.bands.BAND_PACKETS`), so that a member's tables serve every band.
SENSITIVITY_PACKETS = BAND_PACKETS
#: Quantities per range: key, unit, and whether its spread is a ratio (positive quantities) or a difference.
QUANTITIES = {"echo_energy_j": ("J", True), "echo_peak_w": ("W", True), "echo_delay_ns": ("ns", False),
              "column_w": ("W", True)}
#: The two members that share Petzold's b_b/b (0.0183) but not its shape.
SHAPE_PAIR = ("Petzold (default)", "FF b_b/b 0.0183")
SHAPE_INPUT = "shape at b_b/b 0.0183 (Petzold vs Fournier-Forand)"
#: Time grid of the echo's peak search [s]: from the straight path's delay, this step, this long.
PEAK_STEP_S = 0.02e-9
PEAK_WINDOW_S = 40e-9


def member_tables(water: Water, member: PhaseMember, packets: int, seed: int = TABLE_SEED,
                  geometry=None) -> ScatteringTables:
    """The Monte Carlo's tables of ``water`` with ``member``'s phase function: the model's own (standard run) for the
    default, else a run of ``packets`` (built once, then cached per phase function and packet count)."""
    geometry = mul2023().geometry if geometry is None else geometry
    w = replace(water, phase_function=member.spec)
    if member.spec == DEFAULT_PHASE:
        return find_or_build_tables(geometry, w, TABLE_PACKETS)
    return find_or_build_tables(geometry, w, packets)


def echo_quantities(model: OpticalModel, ranges_m: np.ndarray, reflectance: float) -> dict[str, np.ndarray]:
    """Per range (n,): the echo's energy [J] and peak power [W] at the receiver of a flat Lambertian plate at normal
    incidence, the delay [ns] of its peak after the straight path's 2 R / c_w, and the column's power [W] then."""
    instrument = model.instrument
    batch = PulseBatch.flat_target(instrument, ranges_m, reflectance, pulse_id=np.arange(ranges_m.shape[0]))
    echoes = model.echoes(batch)
    pulse_of = np.repeat(np.arange(ranges_m.shape[0]), np.diff(echoes.offsets))
    target = echoes.source >= 0  # not the window's return
    energy = np.bincount(pulse_of[target], weights=echoes.energy_j[target], minlength=ranges_m.shape[0])
    straight_s = 2.0 * ranges_m / model.water.speed_m_s
    grid = np.arange(0.0, PEAK_WINDOW_S, PEAK_STEP_S)
    times = straight_s[:, None] + grid[None, :]  # (n, m)
    p, d, e = pulse_of[target], echoes.delay_s[target], echoes.energy_j[target]
    power = np.zeros(times.shape)
    np.add.at(power, p, e[:, None] * instrument.pulse(times[p] - d[:, None]))
    pulse_peak_s = instrument.pulse.peak_delay_s
    peak_at = grid[np.argmax(power, axis=1)] - pulse_peak_s  # the pulse's own rise is not a delay
    return {"echo_energy_j": energy, "echo_peak_w": power.max(axis=1), "echo_delay_ns": peak_at * 1e9,
            "column_w": model.column_power_w(straight_s)}


def _spread(values: np.ndarray, ratio: bool) -> np.ndarray:
    """Per range, the spread of ``values`` (members, n): max / min for a ratio quantity, max - min otherwise."""
    lo, hi = values.min(axis=0), values.max(axis=0)
    if ratio:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(lo > 0.0, hi / lo, np.inf)
    return hi - lo


def input_groups(family: tuple[PhaseMember, ...]) -> dict[str, list[int]]:
    """The inputs a band varies, each with the members (indices) that vary it alone: b_b/b along Fournier-Forand,
    g along Henyey-Greenstein, and the shape at Petzold's b_b/b."""
    groups: dict[str, list[int]] = {}
    for i, m in enumerate(family):
        if m.varies != "default":
            groups.setdefault(m.varies, []).append(i)
    labels = [m.label for m in family]
    if all(s in labels for s in SHAPE_PAIR):
        groups[SHAPE_INPUT] = [labels.index(s) for s in SHAPE_PAIR]
    return {k: v for k, v in groups.items() if len(v) >= 2}


def sensitivity_study(water: str | Water = "pond", ranges_m=SENSITIVITY_RANGES_M, packets: int = SENSITIVITY_PACKETS,
                      reflectance: float = 0.1, family: tuple[PhaseMember, ...] = SENSITIVITY_FAMILY,
                      seed: int = TABLE_SEED) -> dict:
    """The band of the echo and the column over ``family`` per range, for ``muls sensitivity`` (module doc).

    water: preset name or Water (its a, b and group index; the Monte Carlo attenuation rule); ranges_m: plate ranges
    [m]; packets: beam packets of each non-default member's table run; reflectance: the plate's. Returns
    ``phase_functions`` (each member: label, spec, what it varies, source, b_b/b, mean cosine, its tables' run),
    ``ranges`` (per range: per quantity the default, min, median, max, the members at min and max, the Monte Carlo's
    largest relative error of the members' echo energy, and the input that moves it most), ``members`` (every
    member's values), ``phase_function`` and ``band`` (what a summary names) and ``settings``.
    """
    w = study_water(_water(water), "monte_carlo")
    r = _ranges("ranges_m", ranges_m)
    check_fraction("reflectance", reflectance)
    if isinstance(packets, bool) or int(packets) != packets or packets < 1000:
        raise ParameterError(f"packets = {packets!r}: must be an integer >= 1000")
    if len(family) < 2 or family[0].spec != DEFAULT_PHASE:
        raise ParameterError("family: must start with the default phase function and hold at least 2 members")
    if w.scattering_per_m == 0.0:
        raise ParameterError(f"water '{w.name}': b = 0, no phase function to vary")
    t0 = time.perf_counter()
    instrument = mul2023()
    values = {q: np.zeros((len(family), r.shape[0])) for q in QUANTITIES}
    rel_err = np.zeros((len(family), r.shape[0]))
    members = []
    for i, member in enumerate(family):
        tb = time.perf_counter()
        tables = member_tables(w, member, int(packets), seed, instrument.geometry)
        wm = replace(w, phase_function=member.spec)
        model = OpticalModel.build(instrument, wm, tables=tables)
        for q, v in echo_quantities(model, r, float(reflectance)).items():
            values[q][i] = v
        rel_err[i] = np.interp(np.log(r), np.log(tables.ranges_m), tables.transmission_rel_err)
        phase = phase_from_spec(member.spec)
        members.append({"label": member.label, "spec": member.spec, "varies": member.varies, "source": member.source,
                        "backscatter_ratio": round(phase.backscatter_fraction, 5),
                        "mean_cosine": round(phase.mean_cosine, 4), "tables": tables.source,
                        "seconds": round(time.perf_counter() - tb, 1)})
    groups = input_groups(family)
    labels = [m.label for m in family]
    rows = []
    for j, rj in enumerate(r):
        row = {"range_m": float(rj)}
        for q, (_, ratio) in QUANTITIES.items():
            v = values[q][:, j]
            moves = {g: float(_spread(v[idx][:, None], ratio)[0]) for g, idx in groups.items()}
            row[q] = {"default": _sig(v[0]), "min": _sig(v.min()), "median": _sig(float(np.median(v))),
                      "max": _sig(v.max()), "min_member": labels[int(v.argmin())],
                      "max_member": labels[int(v.argmax())], "spread": _sig(float(_spread(v[:, None], ratio)[0])),
                      "spread_is": "max / min" if ratio else "max - min",
                      "moved_most_by": max(moves, key=moves.get) if moves else None}
        row["mc_rel_err_max"] = _sig(float(rel_err[:, j].max()))
        rows.append(row)
    return {
        "water": {"name": w.name, "c_per_m": w.attenuation_per_m, "a_per_m": w.absorption_per_m,
                  "b_per_m": w.scattering_per_m, "group_index": w.group_index},
        "phase_function": f"{DEFAULT_PHASE} (default), band over {len(family)} phase functions",
        "band": True,
        "phase_functions": members,
        "ranges": rows,
        "members": {m.label: {q: [_sig(x) for x in values[q][i]] for q in QUANTITIES} for i, m in enumerate(family)},
        "settings": {"instrument": instrument.name, "reflectance": float(reflectance), "incidence_deg": 0.0,
                     "attenuation_model": "monte_carlo", "multiple_scattering": "table",
                     "packets_default": TABLE_PACKETS, "packets_members": int(packets), "seed": int(seed),
                     "units": {q: u for q, (u, _) in QUANTITIES.items()},
                     "echo_delay": "delay of the echo's peak after the straight path's peak (2 R / c_w plus the "
                                   "pulse's rise)",
                     "column": "the water column's power at the straight path's delay 2 R / c_w, no target",
                     "elapsed_s": round(time.perf_counter() - t0, 1)},
    }


def _sig(v: float, digits: int = 5):
    """``v`` to ``digits`` significant digits (None if not finite)."""
    v = float(v)
    if not math.isfinite(v):
        return None
    return float(f"{v:.{digits}g}")
