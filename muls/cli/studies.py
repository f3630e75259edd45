"""The ``muls`` subcommands of the MULS studies (waveform, maxrange, precision, edge-bias, experiment, budget,
coaxial, bench): per subcommand a builder that adds its options (:data:`BUILDERS`) and a thin function that runs its
study and prints the result (each returns the result dict, its table as text and a plot function or None). The
studies themselves live in :mod:`muls.studies`, :mod:`muls.photon_budget` and :mod:`muls.experiments`."""

from __future__ import annotations

import argparse
import json
import math
import os

from .. import studies
from ..infra.atomic import write_atomically
from ..infra.command import (
    fraction,
    non_negative_float,
    nonempty,
    output_dir,
    positive_float,
    positive_int,
    seed,
)
from ..studies.common import check_pulse_memory
from .arguments import (
    add_attenuation_option,
    add_output_options,
    attenuation_rule,
    count_option,
    one_of,
    positive_number,
    table_cell,
    water_name,
    water_names,
)


def _shots(option: str, value: int, per_shot: int, what: str, unit: str = "shots", mode: str = "windowed") -> int:
    """A count of pulses, ``per_shot`` of them in one simulate call each (``what`` they are, e.g. "3 distances"):
    refused before allocating when that call needs more memory than the command may plan on."""
    check_pulse_memory(option, count_option(option, value), per_shot, f"{what}{value:,} {unit}", unit, mode)
    return value


def _gate_s(args) -> tuple[float | None, float | None]:
    delay = None if args.gate_delay_ns is None else args.gate_delay_ns * 1e-9
    width = None if args.gate_width_ns is None else positive_number("--gate-width-ns", args.gate_width_ns) * 1e-9
    if delay is not None and not (math.isfinite(delay) and delay >= 0.0):
        raise ValueError(f"--gate-delay-ns {args.gate_delay_ns!r}: must be a number >= 0")
    return delay, width


def _cmd_waveform(args):
    delay, width = _gate_s(args)
    result = studies.waveform_study(water_name(args.water), positive_number("--range-m", args.range_m), seed=args.seed,
                                    reflectance=args.reflectance, gate_delay_s=delay, gate_width_s=width,
                                    attenuation_model=attenuation_rule(args.attenuation))
    s = result["settings"]
    lines = [f"waveform: {s['water']}, panel at {s['range_m']:g} m (reflectance {s['reflectance']:g}), "
             f"CH3 gate {s['gate_delay_ns']:g}/{s['gate_width_ns']:g} ns, seed {s['seed']}, full record"]
    lines.append(f"{'channel':8s} {'max LSB':>8s} {'noise-free max':>15s}")
    for name, codes in result["channels"].items():
        lines.append(f"{name:8s} {max(codes):8d} {max(result['noise_free'][name]):15.1f}")
    if result["returns"]:
        for r in result["returns"]:
            lines.append(f"return: {r['channel']} at {r['range_m']:.3f} m (error {r['error_m']:+.3f} m, "
                         f"SNR {r['snr']:.1f}{', clipped' if r['saturated'] else ''})")
    else:
        lines.append(f"no return: dropout cause {result['dropout_cause']}")
    for p in result["peaks"]:
        lines.append(f"peak: {p['channel']} at {p['range_m']:.3f} m{' (clipped)' if p['saturated'] else ''}")
    from ..plots import plot_waveform

    return result, "\n".join(lines), plot_waveform


def _cmd_maxrange(args):
    waters = [water_name(w) for w in args.waters]
    from ..studies.maxrange import MAX_BATCH_RANGES

    shots = _shots("--shots", args.shots, MAX_BATCH_RANGES, f"up to {MAX_BATCH_RANGES} ranges at once x ")
    result = studies.maxrange_study(waters, shots=shots, seed=args.seed,
                                    reflectance=args.reflectance, attenuation_model=attenuation_rule(args.attenuation))
    s = result["settings"]
    lines = [f"maximum detectable range [m]: reflectance {s['reflectance']:g}, >= {s['detection_fraction']:.0%} "
             f"of {s['shots']} pulses within {s['tolerance_bins']} range bins, {s['attenuation_model']} attenuation, "
             f"seed {s['seed']} ({s['elapsed_s']:.1f} s)",
             f"{'water':15s} {'single':>7s} {'near':>7s} {'far':>7s} {'total':>7s} {'improvement':>12s}  "
             f"{'gains single/PMT1/PMT2':>22s}"]
    for w in s["waters"]:
        r = result[w]
        g = r["gains"]
        lines.append(f"{w:15s} {table_cell(r['single_channel_m'], 1):>7s} {table_cell(r['near_field_m'], 1):>7s} "
                     f"{table_cell(r['far_field_m'], 1):>7s} {table_cell(r['total_m'], 1):>7s} "
                     f"{table_cell(r['improvement'], 2):>12s}  "
                     f"{g['single']:>6.1f}/{g['pmt1']:>6.0f}/{g['pmt2']:>6.0f}")
    lines.append("limited by (the best channel one step beyond each edge: its SNR, and the cause):")
    for w in s["waters"]:
        cells = []
        for group, lim in result[w]["limits"].items():
            cells.append(f"{group} -" if lim is None else
                         f"{group} {lim['channel']} {lim['cause']} (SNR {table_cell(lim['snr'], 1)})")
        lines.append(f"{w:15s} " + "; ".join(cells))
    result["settings"] = {**s, "phase_function": "petzold (default)", "band": bool(args.band)}
    if args.band:
        from ..studies.bands import MAXRANGE_FIGURES, maxrange_band

        result["band"] = maxrange_band(waters, shots=shots, reflectance=args.reflectance, seed=args.seed,
                                       attenuation_model=attenuation_rule(args.attenuation))
        lines.append(f"band [low median high] over {len(result['band']['phase_functions'])} phase functions:")
        for w, b in result["band"]["waters"].items():
            lines.append(f"{w:15s} " + "; ".join(
                f"{f.removesuffix('_m')} [{table_cell(b['figures'][f]['low'], 1)} {table_cell(b['figures'][f]['median'], 1)} "
                f"{table_cell(b['figures'][f]['high'], 1)}]" for f in MAXRANGE_FIGURES))
    lines.append("phase function: petzold (default); " + ("band computed" if args.band else "no band (--band)"))
    from ..plots import plot_maxrange

    return result, "\n".join(lines), plot_maxrange


def _cmd_precision(args):
    delay, width = _gate_s(args)
    ranges = [positive_number("--ranges-m", r) for r in args.ranges_m]
    shots = _shots("--shots", args.shots, len(ranges), f"{len(ranges)} ranges x ")
    result = studies.precision_study(water_name(args.water), ranges, shots=shots,
                                     seed=args.seed, reflectance=args.reflectance, gate_delay_s=delay,
                                     gate_width_s=width, attenuation_model=attenuation_rule(args.attenuation))
    s = result["settings"]
    lines = [f"range precision: {s['water']}, {s['shots']} shots per range, CH3 gate {s['gate_delay_ns']:g}/"
             f"{s['gate_width_ns']:g} ns, detection within {s['tolerance_m']:.3f} m, seed {s['seed']}",
             f"{'range m':>8s} {'channel':8s} {'std m':>8s} {'mean dev m':>11s} {'detected':>9s} {'clipped':>8s}"]
    for key in (k for k in result if k != "settings"):
        for ch, st in result[key].items():
            lines.append(f"{key:>8s} {ch:8s} {table_cell(st['precision_m'], 4):>8s} {table_cell(st['mean_deviation_m'], 4):>11s} "
                         f"{table_cell(st['detected_fraction'], 3):>9s} {table_cell(st['saturated_fraction'], 3):>8s}")
    from ..plots import plot_precision

    return result, "\n".join(lines), plot_precision


def _cmd_edge_bias(args):
    waters = [water_name(w) for w in args.waters] if args.waters else None
    ranges = [positive_number("--ranges-m", r) for r in args.ranges_m]
    shots = _shots("--shots", args.shots, len(ranges), f"{len(ranges)} ranges x ")
    result = studies.edge_bias_study(waters, ranges, shots=shots, seed=args.seed, reflectance=args.reflectance,
                                     attenuation_model=attenuation_rule(args.attenuation))
    s = result["settings"]
    lines = [f"range bias at the blind-zone edge: plate {s['reflectance']:g} at normal incidence, {s['shots']} shots "
             f"per range, {s['attenuation_model']} attenuation, CH3 gate {s['gate_delay_ns']:g}/{s['gate_width_ns']:g} "
             f"ns, seed {s['seed']}",
             "mean error / std [cm] per channel (detected share); noise-free chosen return with the column cut at the "
             "plate, with it not cut (echo alone), and their difference (the missing column's bias)",
             f"{'water':14s} {'range':>5s} {'overlap':>7s} " + " ".join(f"{c:>18s}" for c in ("ch1", "ch2", "ch3",
             "chosen")) + f" {'noise-free':>10s} {'echo alone':>10s} {'column':>7s}"]

    def cm(v):
        return "-" if v is None else f"{100.0 * v:.1f}"

    for water in s["waters"]:
        for key, row in result[water].items():
            cells = [f"{cm(row[c]['mean_deviation_m'])} / {cm(row[c]['precision_m'])} ({row[c]['detected_fraction']:.2f})"
                     for c in ("ch1", "ch2", "ch3", "chosen")]
            lines.append(f"{water:14s} {key:>5s} {row['overlap']:7.4f} " + " ".join(f"{c:>18s}" for c in cells)
                         + f" {cm(row['noise_free_m']):>10s} {cm(row['echo_alone_m']):>10s}"
                         f" {cm(row['column_deficit_m']):>7s}")
    return result, "\n".join(lines), None


def _experiment_name(name: str) -> str:
    from ..experiments import EXPERIMENTS

    return one_of("experiment", name, EXPERIMENTS)


def _ranging(name: str) -> str:
    from ..experiments import RANGING

    return one_of("--ranging", name, RANGING)


#: The keys ``muls experiment --json`` prints (the study also returns the waveforms, for the picture).
EXPERIMENT_KEYS = ("distances", "settings")


def _cmd_experiment(args):
    from ..experiments import experiment_preset

    exp = experiment_preset(_experiment_name(args.experiment), attenuation_rule(args.attenuation))
    shots = _shots("--shots", args.shots, len(exp.distances_m), f"{len(exp.distances_m)} distances x ")
    full = studies.experiment_study(exp, shots=shots, seed=args.seed,
                                    ranging=_ranging(args.ranging), waveforms=not args.no_plot)
    s = full["settings"]
    lines = [f"experiment {s['experiment']}: panel {s['reflectance']:g} at {', '.join(f'{d:g}' for d in s['distances_m'])} m"
             f", {s['shots']} shots each, M1 {s['gain_pmt1']:.0f}, M2 {s['gain_pmt2']:.0f}, CH3 gate "
             f"{s['gate_delay_ns']:g}/{s['gate_width_ns']:g} ns, {s['ranging']} ranging, {s['attenuation_model']} "
             f"attenuation, seed {s['seed']} ({s['elapsed_s']:.1f} s)",
             f"gains: {s['gain_rule']}",
             f"{'dist m':>6s} {'ch':4s} {'detected':>8s} {'std m':>8s} {'mad m':>8s} {'bias m':>8s} {'clipped':>8s}"
             + ("" if args.no_band else "  detected band [low median high] over the phase functions")]
    from ..studies.bands import experiment_band

    band = None if args.no_band else experiment_band(exp, shots=shots, seed=args.seed, ranging=args.ranging)
    for key, chans in full["distances"].items():
        for ch, st in chans.items():
            cells = "" if band is None else "  [{low:.3f} {median:.3f} {high:.3f}]".format(
                **band["distances"][key][ch]["detected_fraction"])
            lines.append(f"{key:>6s} {ch:4s} {table_cell(st['detected_fraction'], 3):>8s} {table_cell(st['precision_m'], 4):>8s} "
                         f"{table_cell(st['mean_abs_deviation_m'], 4):>8s} {table_cell(st['bias_m'], 4):>8s} "
                         f"{table_cell(st['clipped_fraction'], 3):>8s}{cells}")
    lines.append("phase function: petzold (default)" + ("; no band computed (--no-band)" if band is None else
                 f"; band over {len(band['members'])} phase functions: {', '.join(band['members'])}"))
    from ..plots import plot_experiment

    result = {k: full[k] for k in EXPERIMENT_KEYS}
    result["settings"] = {**result["settings"], "phase_function": "petzold (default)", "band": band is not None}
    if band is not None:
        result["band"] = band

    def write(res, out_dir):  # the experiment's directory: its JSON and its picture
        os.makedirs(out_dir, exist_ok=True)
        write_atomically(lambda tmp: _dump_json(res, tmp), os.path.join(out_dir, "experiment.json"))
        write_atomically(lambda tmp: plot_experiment(full, tmp), os.path.join(out_dir, "experiment.png"))
        return out_dir

    return result, "\n".join(lines), write


def _dump_json(result, path):
    with open(path, "w") as f:
        json.dump(result, f, indent=1, allow_nan=False)
    return path


def _cmd_budget(args):
    from ..studies.budget import budget_table

    result = studies.budget_study(attenuation_rule(args.attenuation))
    head = (f"photon budget, {result['settings']['attenuation_model']} attenuation, panel "
            f"{result['settings']['reflectance']:g}: photoelectrons / echo peak LSB / SNR per channel")
    return result, "\n".join([head] + budget_table(result)), None


def _cmd_coaxial(args):
    rule = attenuation_rule(args.attenuation)
    result = studies.coaxial_study(water_name(args.water), attenuation_model=rule)
    s = result["settings"]
    text = (f"coaxial vs non-coaxial water-column backscatter in {s['water']}:\n"
            f"  peak coaxial {result['coaxial_peak_w']:.4g} W at {result['coaxial_peak_time_ns']:.1f} ns, "
            f"peak non-coaxial {result['non_coaxial_peak_w']:.4g} W at {result['non_coaxial_peak_time_ns']:.1f} ns\n"
            f"  peak_ratio = {result['peak_ratio']:.2f}")
    from ..plots import plot_coaxial

    def plot(res, path):
        others = {w: studies.coaxial_study(w, attenuation_model=rule) for w in studies.MAXRANGE_WATERS if w != s["water"]}
        return plot_coaxial({s["water"]: res, **others}, path)

    return result, text, plot


def _cmd_bench(args):
    result = studies.bench_study(pulses=_shots("--pulses", args.pulses, 1, "", "windowed pulses"),
                                 full_pulses=_shots("--full-pulses", args.full_pulses, 1, "", "full records", "full"),
                                 repeats=count_option("--repeats", args.repeats))
    m = result["machine"]
    lines = [f"simulate (waveform + digitise + ranging), {result['settings']['water']}, mul2023, "
             f"{m['cpu_count']} CPUs, {m['numba_threads']} numba threads, load {m['loadavg_1_5_15']}"]
    for key, name, target in (("windowed", "windowed", 100_000), ("full_record", "full record", 10_000)):
        r = result[key]
        lines.append(f"{name:12s} {r['pulses_per_s']:>10,.0f} pulses/s (target {target:,}; {r['pulses']:,} pulses, "
                     f"digitise {r['digitise_s']:.3f} s, ranging {r['range_batch_s']:.3f} s)")
    return result, "\n".join(lines), None


DEFAULT_OUT = {"waveform": "waveform.png", "maxrange": "maxrange.png", "precision": "precision.png",
               "coaxial": "coaxial.png", "experiment": "experiment_{experiment}"}
#: Commands whose --out is a folder of files, each written whole by the command itself.
FOLDER_OUTPUTS = ("experiment",)


def _add_waveform(p: argparse.ArgumentParser) -> None:
    p.add_argument("--water", default="pond", type=nonempty(), help=f"water preset ({water_names()})")
    p.add_argument("--range-m", type=positive_float(), default=11.5, help="panel range [m]")
    p.add_argument("--reflectance", type=fraction(), default=0.1)
    p.add_argument("--seed", type=seed(), default=0)
    p.add_argument("--gate-delay-ns", type=non_negative_float(), default=None,
                   help="CH3 gate delay [ns] (default: that water's experiment)")
    p.add_argument("--gate-width-ns", type=positive_float(), default=None, help="CH3 gate width [ns]")
    add_attenuation_option(p)
    add_output_options(p)
    p.set_defaults(run=_cmd_waveform)


def _add_maxrange(p: argparse.ArgumentParser) -> None:
    p.add_argument("--shots", type=positive_int(), default=200, help="seeded pulses per range")
    p.add_argument("--seed", type=seed(), default=0)
    p.add_argument("--reflectance", type=fraction(), default=0.1)
    p.add_argument("--waters", nargs="+", type=nonempty(), default=list(studies.MAXRANGE_WATERS),
                   help=f"water presets ({water_names()})")
    add_attenuation_option(p)
    p.add_argument("--band", action="store_true",
                   help="each figure's band over the family of phase functions (the study once per member)")
    add_output_options(p)
    p.set_defaults(run=_cmd_maxrange)


def _add_precision(p: argparse.ArgumentParser) -> None:
    p.add_argument("--water", default="pond", type=nonempty(), help=f"water preset ({water_names()})")
    p.add_argument("--ranges-m", type=positive_float(), nargs="+", default=[8.5, 10.0, 11.5], help="panel ranges [m]")
    p.add_argument("--shots", type=positive_int(), default=1000)
    p.add_argument("--seed", type=seed(), default=0)
    p.add_argument("--reflectance", type=fraction(), default=0.1)
    p.add_argument("--gate-delay-ns", type=non_negative_float(), default=None)
    p.add_argument("--gate-width-ns", type=positive_float(), default=None)
    add_attenuation_option(p)
    add_output_options(p)
    p.set_defaults(run=_cmd_precision)


def _add_edge_bias(p: argparse.ArgumentParser) -> None:
    p.add_argument("--waters", nargs="+", type=nonempty(), default=None, help=f"water presets (default all: {water_names()})")
    p.add_argument("--ranges-m", type=positive_float(), nargs="+", default=list(studies.EDGE_RANGES_M),
                   help="plate ranges [m] (default 1.60 to 2.20 m in 5 cm steps)")
    p.add_argument("--shots", type=positive_int(), default=200, help="noisy pulses per range and water")
    p.add_argument("--seed", type=seed(), default=0)
    p.add_argument("--reflectance", type=fraction(), default=0.1)
    add_attenuation_option(p)
    add_output_options(p, plot=False)
    p.set_defaults(run=_cmd_edge_bias, no_plot=True, out=None)


def _add_experiment(p: argparse.ArgumentParser) -> None:
    p.add_argument("experiment", type=nonempty(), help="pond or pool")
    p.add_argument("--shots", type=positive_int(), default=1000, help="static shots at each distance")
    p.add_argument("--seed", type=seed(), default=0)
    p.add_argument("--ranging", default="prototype", type=nonempty(),
                   help="prototype (plain peak detection on the 1 GS/s record) or template (pulse-shape fit)")
    add_attenuation_option(p)
    p.add_argument("--no-band", action="store_true",
                   help="skip the band over the family of phase functions (one more run per member)")
    add_output_options(p, out_type=output_dir)  # a folder: experiment.json and experiment.png
    p.set_defaults(run=_cmd_experiment)


def _add_budget(p: argparse.ArgumentParser) -> None:
    add_attenuation_option(p)
    add_output_options(p, plot=False)
    p.set_defaults(run=_cmd_budget)


def _add_coaxial(p: argparse.ArgumentParser) -> None:
    p.add_argument("--water", default="turbid_harbor", type=nonempty(), help=f"water preset ({water_names()})")
    add_attenuation_option(p)
    add_output_options(p)
    p.set_defaults(run=_cmd_coaxial)


def _add_bench(p: argparse.ArgumentParser) -> None:
    p.add_argument("--pulses", type=positive_int(), default=100_000, help="windowed-mode pulses")
    p.add_argument("--full-pulses", type=positive_int(), default=10_000, help="full-record pulses")
    p.add_argument("--repeats", type=positive_int(), default=3)
    add_output_options(p, plot=False)
    p.set_defaults(run=_cmd_bench)


#: What adds each subcommand's options and sets its ``run`` (:data:`muls.cli.registry.SUBCOMMANDS` names them).
BUILDERS = {
    "waveform": _add_waveform,
    "maxrange": _add_maxrange,
    "precision": _add_precision,
    "edge-bias": _add_edge_bias,
    "experiment": _add_experiment,
    "budget": _add_budget,
    "coaxial": _add_coaxial,
    "bench": _add_bench,
}
