"""Studies: the Monte Carlo waveform of one plate beside MULS's (``muls multiscatter``), and where single
scattering fails per water and range (``muls multiscatter-study``).
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..infra.errors import ParameterError, check_positive
from ..montecarlo.run import TargetPlanes, run_monte_carlo
from ..optics.optical_model import OpticalModel
from ..optics.radiometry import lambertian_weight, target_factor
from ..presets import instrument_preset, water_preset
from ..validation.correction import MultipleScatteringCorrection, same_phase
from ..validation.power import effective_attenuation_per_m, geometry_factor, mc_power_w, muls_power_w, two_way_transmission
from ..water.phase import check_phase
from ..water.properties import MAX_ATTENUATION_EXPONENT, Water
from .maxrange import maxrange_study

#: Beam packets of ``muls multiscatter`` by default: the pond at 10 m then has every bin within 100 times
#: of the column's and of the echo's peak below 5 % relative error (docs/multiple-scattering.md).
DEFAULT_PACKETS = 2_000_000


def max_range_m(water: Water) -> float:
    """The farthest plate [m] whose echo a run can see: every packet that returns from range r travelled at least
    2 r and kept at most exp(-2 a r) of its weight, so beyond 2 a r = MAX_ATTENUATION_EXPONENT (e^-40) none does.
    (The run's histograms grow with the range: a plate 10^6 m away needed more memory than any machine has.)"""
    return MAX_ATTENUATION_EXPONENT / (2.0 * water.absorption_per_m) if water.absorption_per_m > 0.0 else math.inf


def check_range_m(key: str, water: Water, range_m: float, geometry: str | None = None) -> float:
    """``range_m``, or a :class:`ParameterError` naming ``key`` when it is not > 0, lies beyond :func:`max_range_m`,
    or, with ``geometry`` (an instrument preset's name), within its blind zone: there the beam has not entered the
    receiver's field of view, MULS's echo is zero (MULS Eq. 11: overlap 0) and the study would compare nothing."""
    check_positive(key, range_m)
    if geometry is not None:
        blind_m = instrument_preset(geometry).geometry.blind_zone_m
        if range_m <= blind_m:
            raise ParameterError(f"{key} = {range_m!r}: the plate lies in the {geometry} geometry's blind zone (closer "
                                 f"than {blind_m:.2f} m the beam is outside the receiver's field of view, so MULS sees no "
                                 f"echo and the study compares nothing); give a range beyond {blind_m:.2f} m, or the "
                                 "coaxial geometry (no blind zone)")
    if range_m > max_range_m(water):
        raise ParameterError(f"{key} = {range_m!r}: no light comes back from so far in {water.name}: absorption alone "
                             f"leaves e^-{2.0 * water.absorption_per_m * range_m:,.0f} of it (none beyond "
                             f"e^-{MAX_ATTENUATION_EXPONENT:g}); at most {max_range_m(water):,.1f} m in this water")
    return float(range_m)


def multiscatter_study(water: str | Water = "pond", range_m: float = 10.0, geometry: str = "mul2023",
                       packets: int = DEFAULT_PACKETS, seed: int = 0, phase: str = "petzold",
                       reflectance: float = 0.1, attenuation_model: str | None = None) -> dict:
    """The Monte Carlo waveform of one pulse on a flat plate beside MULS's, for ``muls multiscatter``.

    water: preset name or Water (MULS uses it as configured: its attenuation and backscatter rules, the
    attenuation replaced by ``attenuation_model`` when given); geometry: ``mul2023`` (receiver 130 mm beside
    the beam) or ``coaxial``. Returns the keys of the JSON output (``time_ns``, ``mc_w``, ``mc_rel_err``,
    ``muls_w``, the Monte Carlo's column and target apart (``mc_column_w``, ``mc_column_rel_err``,
    ``mc_target_w``, ``mc_target_rel_err``), ``target``, ``column_peak_ratio``,
    ``effective_attenuation_per_m``, ``packets``, ``seconds``) and ``details`` (parts, rules, budget).
    """
    w = water if isinstance(water, Water) else water_preset(water)
    if attenuation_model is not None:
        w = w.with_models(attenuation_model=attenuation_model)
    if geometry not in ("mul2023", "coaxial"):
        raise ParameterError(f"geometry = {geometry!r}: must be 'mul2023' or 'coaxial'")
    check_range_m("range_m", w, range_m, geometry)
    instrument = instrument_preset(geometry)
    t0 = time.perf_counter()
    result = run_monte_carlo(instrument, w, TargetPlanes((float(range_m),), reflectance), phase=phase,
                             packets=packets, seed=seed)
    mc = mc_power_w(result, 0, instrument)
    keep = result.time_s < result.scene_end_s[0]
    t = result.time_s[keep]
    muls = muls_power_w(instrument, w, range_m, reflectance, t)
    total, total_err = (v[keep] for v in mc["total"])
    e_scale = instrument.transmitter.pulse_energy_j * two_way_transmission(instrument)
    tm, tv = result.target(0)
    mc_energy = float(tm.sum()) * e_scale
    mc_energy_err = float(math.sqrt(tv.sum())) * e_scale
    muls_total = muls["column"] + muls["target"]
    col_mc, col_muls = mc["column"][0][keep], muls["column"]
    geometry_ratio = float(geometry_factor(instrument, [range_m], seed=seed)[0])
    k_eff = effective_attenuation_per_m(instrument, range_m, reflectance, w, mc_energy, geometry_ratio)
    seconds = time.perf_counter() - t0
    rules = {rule: w.with_models(attenuation_model=rule).two_way_attenuation_per_m for rule in ("k_lidar", "c", "kd")}
    ph = check_phase(phase)
    return {
        "time_ns": _round(t * 1e9, 4),
        "mc_w": _round(total),
        "mc_rel_err": _relative(total, total_err),
        "muls_w": _round(muls_total),
        "mc_column_w": _round(col_mc),
        "mc_column_rel_err": _relative(col_mc, mc["column"][1][keep]),
        "mc_target_w": _round(mc["target"][0][keep]),
        "mc_target_rel_err": _relative(mc["target"][0][keep], mc["target"][1][keep]),
        "target": {"mc_energy_j": mc_energy, "muls_energy_j": muls["target_energy_j"],
                   "ratio": mc_energy / muls["target_energy_j"] if muls["target_energy_j"] > 0 else None},
        "column_peak_ratio": float(col_mc.max() / col_muls.max()) if col_muls.max() > 0 else None,
        "effective_attenuation_per_m": k_eff,
        "packets": result.packets,
        "seconds": round(seconds, 2),
        "details": {
            "water": w.name, "range_m": float(range_m), "geometry": geometry, "reflectance": float(reflectance),
            "phase": ph.name, "seed": int(seed), "receiver_packets": result.receiver_packets,
            "mc_column_w": _round(col_mc), "mc_column_first_w": _round(mc["column_first"][0][keep]),
            "mc_target_w": _round(mc["target"][0][keep]), "mc_target_err_w": _round(mc["target"][1][keep]),
            "mc_column_err_w": _round(mc["column"][1][keep]),
            "muls_column_w": _round(col_muls), "muls_target_w": _round(muls["target"]),
            "mc_target_energy_err_j": mc_energy_err, "geometry_ratio": geometry_ratio,
            "mc_column_peak_time_ns": float(t[np.argmax(col_mc)] * 1e9),
            "muls_column_peak_time_ns": float(t[np.argmax(col_muls)] * 1e9),
            "column_first_peak_ratio": float(mc["column_first"][0][keep].max() / col_muls.max()) if col_muls.max() > 0 else None,
            "attenuation_rules_per_m": {"muls_" + r: v for r, v in rules.items()} | {"muls_model": w.attenuation_model},
            "beta_pi_ratio": ph.value_at_pi_per_sr * w.scattering_per_m / w.beta_pi_per_m_sr if w.beta_pi_per_m_sr > 0 else None,
            "energy_budget": result.energy,
        },
    }


def _relative(mean, err) -> list:
    """Standard error over the value per bin (None where the value is 0)."""
    return [None if v <= 0.0 else round(float(e / v), 5) for v, e in zip(mean, err)]


def _round(a, digits: int | None = None) -> list:
    a = np.asarray(a, float)
    if digits is None:
        return [float(f"{v:.6g}") for v in a.tolist()]
    return np.round(a, digits).tolist()


#: Waters of the study (the paper's two test waters and the three Petzold waters of its Table 3).
STUDY_WATERS = ("pond", "pool", "clean_ocean", "coastal_ocean", "turbid_harbor")
#: Target ranges of the correction tables [m], and ranges between them where the interpolation is checked.
STUDY_RANGES_M = (2.0, 2.25, 2.5, 2.75, 3.0, 3.5, 4.0, 5.0, 7.5, 10.0, 12.5, 15.0, 20.0, 25.0, 30.0)
CHECK_RANGES_M = (2.125, 2.625, 3.25, 6.0, 8.75, 17.5)
#: Ranges scanned around MULS's maximum detectable range R_det for the detection question.
DETECTION_FACTORS = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0)
ATTENUATION_RULES = ("k_lidar", "c", "kd", "small_angle")
#: Beam packets per water of the study by default (docs/multiple-scattering.md gives the errors).
STUDY_PACKETS = 400_000


def _detection_range(ranges, mc_peak, level):
    """Smallest range where the Monte Carlo echo peak falls to ``level`` (log-linear between ranges)."""
    lp = np.log(np.maximum(mc_peak, 1e-300))
    below = np.nonzero(lp <= math.log(level))[0]
    if below.size == 0 or below[0] == 0:
        return None, "beyond the ranges run" if below.size == 0 else "below the nearest range run"
    i = below[0]
    f = (math.log(level) - lp[i - 1]) / (lp[i] - lp[i - 1])
    return float(ranges[i - 1] + f * (ranges[i] - ranges[i - 1])), "interpolated"


def multiscatter_waters_study(waters=STUDY_WATERS, ranges_m=STUDY_RANGES_M, packets: int = STUDY_PACKETS, seed: int = 0,
                              phase: str = "petzold", geometry: str = "mul2023", detection_shots: int = 200,
                              check_ranges_m=CHECK_RANGES_M, attenuation_model: str = "small_angle") -> dict:
    """Monte Carlo over MULS per water: column peak, target echo, implied detection range, correction table.

    For each water one Monte Carlo run serves flat 0.1 plates at all ``ranges_m``, at ``check_ranges_m``
    (for the interpolation error of the correction) and around MULS's maximum detectable range R_det
    (``muls.studies.maxrange_study``, the MUL's total, ``detection_shots`` pulses per range). MULS is
    evaluated with each attenuation rule (k_lidar, c, kd, small_angle; beta_pi as the water is configured). The
    detection range the Monte Carlo implies is where its echo peak power falls to MULS's echo peak at R_det
    (the far channel's threshold is fixed by its dark noise, so a peak level is what detection needs).
    ``geometry`` per range is the echo without scattering over Eq. 7 (:func:`geometry_factor`), and the
    effective attenuation is taken against it, so that it holds the propagation alone.
    ``attenuation_model`` (one of :data:`ATTENUATION_RULES`; the Monte Carlo's own tables, every water's default,
    are not compared with the Monte Carlo) is the rule of MULS's maximum range, of the correction table and of the
    column's ``under_echo`` comparison.
    Returns {water: {...}, "settings": {...}}.
    """
    if geometry not in ("mul2023", "coaxial"):
        raise ParameterError(f"geometry = {geometry!r}: must be 'mul2023' or 'coaxial'")
    if attenuation_model not in ATTENUATION_RULES:
        raise ParameterError(f"attenuation_model = {attenuation_model!r}: must be one of {', '.join(ATTENUATION_RULES)}")
    instrument = instrument_preset(geometry)
    ph = check_phase(phase)
    t_all = time.perf_counter()
    out = {}
    geo_ranges = sorted({float(r) for r in list(ranges_m) + list(check_ranges_m)})
    geo = dict(zip(geo_ranges, geometry_factor(instrument, geo_ranges, seed=seed)))
    for name in ([waters] if isinstance(waters, str) else list(waters)):
        w = water_preset(name).with_models(attenuation_model=attenuation_model)
        t0 = time.perf_counter()
        r_det = (maxrange_study([name], shots=detection_shots, seed=seed, attenuation_model=w.attenuation_model)[name]
                 ["total_m"] if detection_shots else None)
        table = sorted(float(r) for r in ranges_m)
        extra = list(check_ranges_m) + ([r_det * f for f in DETECTION_FACTORS] if r_det else [])
        ranges = sorted({round(float(r), 3) for r in table + extra})
        result = run_monte_carlo(instrument, w, TargetPlanes(tuple(ranges), 0.1), phase=ph, packets=packets, seed=seed)
        e_scale = instrument.transmitter.pulse_energy_j * two_way_transmission(instrument)
        pulse_peak = instrument.pulse.peak_per_s
        rows = []
        for k, r in enumerate(ranges):
            tm, tv = result.target(k)
            mc_e = float(tm.sum()) * e_scale
            parts = mc_power_w(result, k, instrument)
            muls_e = {rule: instrument.transmitter.pulse_energy_j * float(target_factor(
                instrument, w.with_models(attenuation_model=rule), r, lambertian_weight(instrument, r, 0.1)))
                for rule in ATTENUATION_RULES}  # MULS Eq. 7 with each rule
            ratios = {rule: mc_e / v for rule, v in muls_e.items()}
            g = geo.get(r)
            rows.append({
                "range_m": r, "mc_energy_j": mc_e, "mc_rel_err": math.sqrt(tv.sum()) / tm.sum(), "geometry": g,
                "mc_peak_w": float(parts["target"][0].max()),
                "muls_peak_w": muls_e[w.attenuation_model] * pulse_peak,
                "ratio": ratios, "closest_rule": min(ratios, key=lambda q: abs(math.log(ratios[q]))),
                "effective_attenuation_per_m": effective_attenuation_per_m(instrument, r, 0.1, w, mc_e, g or 1.0),
            })
        # the column: the farthest scene holds every earlier time
        far = len(ranges) - 1
        mc = mc_power_w(result, far, instrument)
        t = result.time_s
        col, col_err = mc["column"]
        first = mc["column_first"][0]
        col_rules = {}
        for rule in ATTENUATION_RULES:
            ref = OpticalModel.build(instrument, w.with_models(attenuation_model=rule)).column_power_w(t, cut_m=ranges[far])
            same = OpticalModel.build(instrument, same_phase(w.with_models(attenuation_model=rule), ph)).column_power_w(
                t, cut_m=ranges[far])
            col_rules[rule] = {"muls_peak_w": float(ref.max()), "peak_ratio": float(col.max() / ref.max()),
                               "peak_ratio_same_beta_pi": float(col.max() / same.max())}
        i_pk = int(np.argmax(col))
        under_echo = []
        muls_model = OpticalModel.build(instrument, w)
        for row in rows:  # the column beneath the echo: the 4 ns before the echo starts
            sel = (t < 2.0 * row["range_m"] / w.speed_m_s) & (t >= 2.0 * row["range_m"] / w.speed_m_s - 4e-9)
            muls_col = float(muls_model.column_power_w(t[sel], cut_m=np.inf).mean())
            mc_col, mc_err = float(col[sel].mean()), float(col_err[sel].mean())  # errors of neighbours correlate
            under_echo.append({"range_m": row["range_m"], "mc_w": mc_col, "mc_rel_err": mc_err / mc_col if mc_col > 0 else None,
                               "ratio": mc_col / muls_col if muls_col > 0 else None})
        # detection: MULS's echo peak at R_det is the level; where does the Monte Carlo echo fall to it?
        detection = None
        if r_det:
            level = rows[ranges.index(round(r_det, 3))]["muls_peak_w"]
            r_mc, how = _detection_range(np.array(ranges), np.array([q["mc_peak_w"] for q in rows]), level)
            detection = {"muls_m": r_det, "mc_implied_m": r_mc, "how": how, "level_w": level,
                         "ratio": None if r_mc is None else r_mc / r_det}
        # correction table from the table ranges, checked at the others
        idx_table = [ranges.index(round(r, 3)) for r in table]
        corr = MultipleScatteringCorrection.from_result(result, instrument, w, ph, scenes=idx_table)
        checks = []
        for r in check_ranges_m:
            k = ranges.index(round(float(r), 3))
            direct = rows[k]["ratio"][w.attenuation_model]
            checks.append({"range_m": float(r), "interpolated": float(corr.target_factor(r)), "monte_carlo": direct,
                           "error": float(corr.target_factor(r) / direct - 1.0),
                           "mc_rel_err": rows[k]["mc_rel_err"]})
        out[w.name] = {
            "ranges": [{**q, "ratio": {k: round(v, 6) for k, v in q["ratio"].items()}} for q in rows if q["range_m"] in table],
            "column": {
                "mc_peak_w": float(col.max()), "mc_peak_rel_err": float(col_err[i_pk] / col[i_pk]),
                "mc_peak_time_ns": float(t[i_pk] * 1e9), "mc_first_order_peak_w": float(first.max()),
                "rules": col_rules, "under_echo": [u for u in under_echo if u["range_m"] in table],
            },
            "detection": detection,
            "correction_check": checks,
            "attenuation_per_m": {rule: w.with_models(attenuation_model=rule).two_way_attenuation_per_m
                                  for rule in ("k_lidar", "c", "kd")},
            "model_rule": w.attenuation_model,
            "beta_pi_ratio": ph.value_at_pi_per_sr * w.scattering_per_m / w.beta_pi_per_m_sr,
            "packets": result.packets, "receiver_packets": result.receiver_packets,
            "seconds": round(time.perf_counter() - t0, 1), "monte_carlo_seconds": round(result.seconds, 1),
        }
    out["settings"] = {
        "waters": [water_preset(n).name for n in ([waters] if isinstance(waters, str) else waters)],
        "ranges_m": list(ranges_m), "check_ranges_m": list(check_ranges_m), "geometry": geometry, "phase": ph.name,
        "packets": int(packets), "seed": int(seed), "reflectance": 0.1, "detection_shots": detection_shots,
        "attenuation_model": attenuation_model,
        "seconds": round(time.perf_counter() - t_all, 1),
    }
    return out
