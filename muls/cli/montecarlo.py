"""The ``muls`` subcommands of the multiple-scattering Monte Carlo (multiscatter, multiscatter-study, mobley1993,
validate-pass): per subcommand a builder that adds its options (:data:`BUILDERS`) and a thin function that runs the
Monte Carlo and prints the result (each returns the result dict, its table as text and a plot function or None). The
Monte Carlo itself lives in :mod:`muls.montecarlo`, its checks in :mod:`muls.validation` and its studies beside
MULS in :mod:`muls.studies`."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from .. import studies
from ..infra.atomic import write_atomically
from ..infra.command import fraction, nonempty, output_dir, positive_float, positive_int, seed
from ..presets import water_preset
from ..validation import mobley1993
from .arguments import add_output_options, attenuation_rule, count_option, table_cell, water_name, water_names


def _packets(option: str, value: int, factor: int = 1) -> int:
    """A count of Monte Carlo packets, a run tracing up to ``factor`` times it: at most what its 64-bit packet
    numbers allow (:func:`muls.montecarlo.run.max_packets`)."""
    from ..montecarlo.run import max_packets

    limit = max_packets() // factor
    if count_option(option, value) > limit:
        raise ValueError(f"{option} = {value}: at most {limit:,} (the Monte Carlo numbers its packets in 64 bits)")
    return value


def _geometry(name: str) -> str:
    if name not in ("mul2023", "coaxial"):
        raise ValueError(f"--geometry {name!r}: must be one of coaxial, mul2023")
    return name


#: The keys ``muls multiscatter --json`` prints (the study returns more, for the picture and the table).
MULTISCATTER_KEYS = ("time_ns", "mc_w", "mc_rel_err", "muls_w", "mc_column_w", "mc_column_rel_err", "mc_target_w",
                     "mc_target_rel_err", "target", "column_peak_ratio", "effective_attenuation_per_m", "packets",
                     "seconds")


def _cmd_multiscatter(args):
    water = water_name(args.water)
    range_m = studies.multiscatter.check_range_m("--range-m", water_preset(water), args.range_m,
                                                _geometry(args.geometry))
    full = studies.multiscatter_study(water, range_m,
                                         geometry=_geometry(args.geometry), packets=_packets("--packets", args.packets),
                                         seed=args.seed, reflectance=args.reflectance,
                                         attenuation_model=attenuation_rule(args.attenuation))
    d = full["details"]
    tg = full["target"]
    rules = d["attenuation_rules_per_m"]
    mc_err = (f"+-{d['mc_target_energy_err_j'] / tg['mc_energy_j']:.1%}" if tg["mc_energy_j"] > 0
              else "no light seen")
    lines = [f"multiple scattering: {d['water']}, {d['geometry']}, plate at {d['range_m']:g} m (reflectance "
             f"{d['reflectance']:g}), {d['phase']} phase function, {full['packets']:,} packets, seed {d['seed']} "
             f"({full['seconds']:.1f} s)",
             f"target echo energy: Monte Carlo {tg['mc_energy_j']:.4g} J ({mc_err}), MULS {tg['muls_energy_j']:.4g} J, "
             f"ratio {table_cell(tg['ratio'], 4)}",
             f"effective attenuation of the echo: {table_cell(full['effective_attenuation_per_m'], 4)} /m (MULS k_lidar "
             f"{rules['muls_k_lidar']:.4f}, c {rules['muls_c']:.4f}, kd {rules['muls_kd']:.4f}; the water uses "
             f"{rules['muls_model']})",
             f"column peak: Monte Carlo / MULS {table_cell(full['column_peak_ratio'], 3)} (at {d['mc_column_peak_time_ns']:.1f}"
             f" vs {d['muls_column_peak_time_ns']:.1f} ns; first scattering alone {table_cell(d['column_first_peak_ratio'], 4)};"
             f" beta_pi of the phase function / MULS's {table_cell(d['beta_pi_ratio'], 3)})",
             f"{'time ns':>8s} {'MC W':>11s} {'rel err':>8s} {'MULS W':>11s} {'MC/MULS':>8s}"]
    step = max(1, len(full["time_ns"]) // 24)
    for t, mc, err, mu in list(zip(full["time_ns"], full["mc_w"], full["mc_rel_err"], full["muls_w"]))[::step]:
        ratio = f"{mc / mu:8.3g}" if mu > 0 else "       -"
        lines.append(f"{t:8.1f} {mc:11.4g} {table_cell(err, 3):>8s} {mu:11.4g} {ratio}")
    from ..plots import plot_multiscatter

    result = {k: full[k] for k in MULTISCATTER_KEYS}
    return result, "\n".join(lines), lambda res, path: plot_multiscatter(full, path)


def _cmd_multiscatter_study(args):
    waters = [water_name(w) for w in args.waters]
    result = studies.multiscatter_waters_study(waters, packets=_packets("--packets", args.packets), seed=args.seed,
                                                  geometry=_geometry(args.geometry),
                                                  attenuation_model=attenuation_rule(args.attenuation))
    s = result["settings"]
    lines = [f"Monte Carlo / MULS, {s['geometry']}, flat 0.1 plate, {s['phase']} phase function, MULS's own rule "
             f"{s['attenuation_model']} (its maximum range, the correction table), "
             f"{s['packets']:,} packets per water, seed {s['seed']} ({s['seconds']:.0f} s)",
             "target echo energy, MC / MULS with each attenuation rule, the share of it due to the transceiver "
             "geometry alone (MC without scattering / Eq. 7), and the MC's effective attenuation:",
             f"{'water':14s} {'range m':>7s} {'k_lidar':>9s} {'c':>9s} {'kd':>9s} {'small_ang':>9s} {'closest':>11s} "
             f"{'geometry':>8s} {'k_eff /m':>8s} {'err':>6s}"]
    for w in s["waters"]:
        for row in result[w]["ranges"]:
            r = row["ratio"]
            lines.append(f"{w:14s} {row['range_m']:7.2f} {r['k_lidar']:9.3g} {r['c']:9.3g} {r['kd']:9.3g} "
                         f"{r['small_angle']:9.3g} {row['closest_rule']:>11s} {table_cell(row['geometry'], 3):>8s} "
                         f"{row['effective_attenuation_per_m']:8.3f} {row['mc_rel_err']:6.1%}")
    lines.append("water column peak, MC / MULS (MULS's beta_pi; with the phase function's beta_pi), first-order "
                 "share, and the detection range MULS needs vs the MC implies:")
    lines.append(f"{'water':14s} {'k_lidar':>15s} {'c':>17s} {'kd':>15s} {'small_angle':>15s} {'1st order':>9s} "
                 f"{'err':>6s} {'R_det MULS':>10s} {'R_det MC':>9s} {'interp err':>10s}")
    for w in s["waters"]:
        c, det = result[w]["column"], result[w]["detection"]
        rules = " ".join(f"{c['rules'][q]['peak_ratio']:7.3g} ({c['rules'][q]['peak_ratio_same_beta_pi']:6.3g})"
                         for q in studies.ATTENUATION_RULES)
        worst = max(abs(q["error"]) for q in result[w]["correction_check"])
        r_mc = "-" if det is None or det["mc_implied_m"] is None else f"{det['mc_implied_m']:.1f}"
        r_mu = "-" if det is None else f"{det['muls_m']:.1f}"
        lines.append(f"{w:14s} {rules} {c['mc_first_order_peak_w'] / c['mc_peak_w']:9.3g} {c['mc_peak_rel_err']:6.1%} "
                     f"{r_mu:>10s} {r_mc:>9s} {worst:10.1%}")
    from ..plots import plot_multiscatter_study

    def write(res, out_dir):  # the study's directory: its chart and its JSON, each written whole
        os.makedirs(out_dir, exist_ok=True)
        write_atomically(lambda tmp: Path(tmp).write_text(json.dumps(res, indent=1, allow_nan=False)),
                         os.path.join(out_dir, "multiscatter_study.json"))
        write_atomically(lambda tmp: plot_multiscatter_study(res, tmp), os.path.join(out_dir, "multiscatter_study.png"))

    return result, "\n".join(lines), write


def _cmd_mobley1993(args):
    photons = _packets("--photons", args.photons, max(mobley1993.PHOTON_FACTOR.values()))
    result = mobley1993.mobley1993_benchmark(photons=photons, seed=args.seed)
    records = result["problems"]
    lines = [f"Mobley et al. (1993) problems 1 and 2 (sun at 60 deg in a black sky, level surface, n 1.34, infinitely "
             f"deep): Monte Carlo beside Table 5, {result['photons']:,} photons per run at albedo 0.9 "
             f"({mobley1993.PHOTON_FACTOR[0.2]} times as many at 0.2), seed {result['seed']} "
             f"({result['seconds']:.1f} s)",
             "paper: the codes' mean and s/x as printed, N codes, and the range that holds every code's value "
             "(mean +- s (N-1)/sqrt(N), rounding included)",
             f"{'problem':>7s} {'albedo':>6s} {'quantity':>8s} {'tau':>4s} {'Monte Carlo':>11s} {'2 sigma':>8s} "
             f"{'paper mean':>10s} {'s/x':>6s} {'N':>2s} {'paper min':>10s} {'paper max':>10s} {'within':>6s}"]
    for r in records:
        lines.append(f"{r['problem']:7d} {r['albedo']:6.1f} {r['quantity']:>8s} {r['optical_depth']:4.0f} "
                     f"{r['value']:11.4g} {2 * r['mc_sigma'] / r['value']:8.2%} {r['paper_mean']:10.3g} "
                     f"{r['paper_rel_sd']:6.3f} {r['paper_models']:2d} {r['paper_min']:10.4g} {r['paper_max']:10.4g} "
                     f"{ {True: 'yes', False: 'NO', None: 'not judged'}[r['within']]:>6s}")
    judged = [r for r in records if r["within"] is not None]
    lines.append(f"{sum(r['within'] for r in judged)} of {len(judged)} judged values within the paper's range widened "
                 f"by the Monte Carlo's 2 standard errors; {len(records) - len(judged)} not judged (2 standard errors "
                 "wider than the codes' range)")
    from ..plots import plot_mobley1993

    return result, "\n".join(lines), plot_mobley1993


def _cmd_validate_pass(args):
    from ..validation.validate import MAX_MC_REL_ERR, check_packets, validate_pass, verdict

    waters = tuple(water_name(w) for w in args.waters)
    full = validate_pass(waters, packets=check_packets("--packets", _packets("--packets", args.packets)),
                         seed=args.seed)
    lines = [f"consistency of the scattering tables: the pass's waveform model (monte_carlo attenuation, finite "
             f"aperture, multiple scattering from the tables) over a fresh run of the Monte Carlo that made them "
             f"({full['packets']:,} packets, seed {full['seed']}, {full['seconds']:.0f} s): flat 0.1 plate at normal "
             f"incidence, the MUL; a case whose Monte Carlo error is {MAX_MC_REL_ERR:.0%} or more is not judged",
             f"{'water':14s} {'range m':>7s} {'echo energy':>11s} {'echo peak':>9s} {'column 0-50 ns':>14s} "
             f"{'MC err':>7s} {'within':>10s}"]
    for case in full["cases"]:
        cells = [f"{case[k]:.3f}" if case[k] is not None else "-" for k in ("echo_energy_ratio", "echo_peak_ratio",
                                                                           "column_ratio")]
        error = "-" if case["mc_rel_err"] is None else f"{case['mc_rel_err']:.2%}"
        lines.append(f"{case['water']:14s} {case['range_m']:7.1f} {cells[0]:>11s} {cells[1]:>9s} {cells[2]:>14s} "
                     f"{error:>7s} {verdict(case):>10s}")
    judged = [c for c in full["cases"] if c["within"] is not None]
    lines.append(f"{sum(c['within'] for c in judged)} of {len(judged)} judged cases within; "
                 f"{len(full['cases']) - len(judged)} not judged")
    return {"cases": full["cases"]}, "\n".join(lines), None


DEFAULT_OUT = {"multiscatter": "multiscatter.png", "multiscatter-study": "multiscatter_study",
               "mobley1993": "mobley1993.png"}
#: Commands whose --out is a folder of files, each written whole by the command itself.
FOLDER_OUTPUTS = ("multiscatter-study",)


def _add_multiscatter(p: argparse.ArgumentParser) -> None:
    p.add_argument("--water", required=True, type=nonempty(), help=f"water preset ({water_names()})")
    p.add_argument("--range-m", type=positive_float(), required=True, help="plate range [m]: beyond the geometry's "
                   "blind zone (mul2023: 1.68 m), up to where absorption leaves e^-40 of the light")
    p.add_argument("--geometry", default="mul2023", type=nonempty(),
                   help="mul2023 (receiver 130 mm beside the beam) or coaxial")
    p.add_argument("--packets", type=positive_int(), default=studies.DEFAULT_PACKETS, help="beam packets")
    p.add_argument("--reflectance", type=fraction(), default=0.1)
    p.add_argument("--seed", type=seed(), default=0)
    p.add_argument("--attenuation", default="small_angle", type=nonempty(),
                   help="MULS's attenuation rule (k_lidar, c, kd, small_angle)")
    add_output_options(p)
    p.set_defaults(run=_cmd_multiscatter)


def _add_multiscatter_study(p: argparse.ArgumentParser) -> None:
    p.add_argument("--waters", nargs="+", type=nonempty(), default=list(studies.STUDY_WATERS),
                   help=f"water presets ({water_names()})")
    p.add_argument("--geometry", default="mul2023", type=nonempty(), help="mul2023 or coaxial")
    p.add_argument("--packets", type=positive_int(), default=studies.STUDY_PACKETS, help="beam packets per water")
    p.add_argument("--seed", type=seed(), default=0)
    p.add_argument("--attenuation", default="small_angle", type=nonempty(),
                   help="MULS's own rule for its maximum range and the correction table (k_lidar, c, kd, small_angle)")
    add_output_options(p, out_type=output_dir)  # a folder: the study's chart and its JSON
    p.set_defaults(run=_cmd_multiscatter_study)


def _add_mobley1993(p: argparse.ArgumentParser) -> None:
    p.add_argument("--photons", type=positive_int(), default=mobley1993.DEFAULT_PHOTONS,
                   help="photons per run at albedo 0.9; the runs at albedo 0.2 trace 5 times as many")
    p.add_argument("--seed", type=seed(), default=0)
    add_output_options(p)
    p.set_defaults(run=_cmd_mobley1993)


def _add_validate_pass(p: argparse.ArgumentParser) -> None:
    from ..validation.validate import VALIDATION_PACKETS, VALIDATION_SEED, VALIDATION_WATERS

    p.add_argument("--waters", nargs="+", default=list(VALIDATION_WATERS), type=nonempty(), metavar="WATER",
                   help="water presets (default: %(default)s)")
    p.add_argument("--packets", type=positive_int(), default=VALIDATION_PACKETS, help="beam packets per water (at "
                   "least 3,500: fewer judge no case)")
    p.add_argument("--seed", type=seed(), default=VALIDATION_SEED)
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    p.set_defaults(run=_cmd_validate_pass, no_plot=True, out=None)


#: What adds each subcommand's options and sets its ``run`` (:data:`muls.cli.registry.SUBCOMMANDS` names them).
BUILDERS = {
    "multiscatter": _add_multiscatter,
    "multiscatter-study": _add_multiscatter_study,
    "mobley1993": _add_mobley1993,
    "validate-pass": _add_validate_pass,
}
