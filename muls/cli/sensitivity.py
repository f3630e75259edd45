"""``muls sensitivity``: how far the unknown phase function of a water moves the echo and the column, range by range
(:func:`muls.studies.sensitivity.sensitivity_study`)."""

from __future__ import annotations

import argparse

from ..infra.command import fraction, nonempty, positive_float, positive_int, seed
from .arguments import add_output_options, water_name, water_names

DEFAULT_OUT = {"sensitivity": "sensitivity.png", "pond-unknowns": ""}
FOLDER_OUTPUTS = ()


def _water(args):
    """The water of the command: a preset, or c and a given together (b = c - a)."""
    from ..water.properties import GROUP_INDEX_FRESHWATER, GROUP_INDEX_SEAWATER, Water

    given = (args.c_per_m is not None, args.a_per_m is not None)
    if any(given) and not all(given):
        raise ValueError("--c-per-m and --a-per-m: give both (b = c - a) or neither")
    if all(given):
        if args.water is not None:
            raise ValueError(f"--water {args.water!r}: give either a preset or --c-per-m and --a-per-m, not both")
        index = GROUP_INDEX_FRESHWATER if args.fresh else GROUP_INDEX_SEAWATER
        return Water.from_attenuation(f"c {args.c_per_m:g} a {args.a_per_m:g}", args.c_per_m, args.a_per_m,
                                      group_index=index, source="given on the command line")
    return water_name(args.water or "pond")


def _cmd_sensitivity(args):
    from ..montecarlo.tables import TABLE_SEED
    from ..studies.sensitivity import sensitivity_study

    result = sensitivity_study(_water(args), packets=args.packets, reflectance=args.reflectance,
                               seed=TABLE_SEED if args.seed is None else args.seed)
    w, s = result["water"], result["settings"]
    lines = [f"sensitivity of {w['name']} (c {w['c_per_m']:g}, a {w['a_per_m']:g} per m) to its phase function: "
             f"{result['phase_function']}; plate {s['reflectance']:g} on the {s['instrument']}, Monte Carlo "
             f"attenuation ({s['elapsed_s']:.0f} s)"]
    for m in result["phase_functions"]:
        lines.append(f"  {m['label']:18s} b_b/b {m['backscatter_ratio']:.4f} g {m['mean_cosine']:.3f}  {m['source']}")
    lines.append(f"{'R m':>5s} {'echo energy J: default [min median max]':>44s} {'peak W: default [min max]':>32s} "
                 f"{'delay ns [min max]':>18s} {'MC err':>7s}  moved most by (energy)")
    for row in result["ranges"]:
        e, p, d = row["echo_energy_j"], row["echo_peak_w"], row["echo_delay_ns"]
        lines.append(f"{row['range_m']:5.1f} {e['default']:10.3e} [{e['min']:9.3e} {e['median']:9.3e} "
                     f"{e['max']:9.3e}] {p['default']:9.3e} [{p['min']:9.3e} {p['max']:9.3e}] "
                     f"[{d['min']:6.2f} {d['max']:6.2f}] {row['mc_rel_err_max']:7.2%}  {e['moved_most_by']}")
    from ..plots import plot_sensitivity

    return result, "\n".join(lines), plot_sensitivity


def _add_sensitivity(p: argparse.ArgumentParser) -> None:
    from ..studies.sensitivity import SENSITIVITY_PACKETS

    p.add_argument("--water", default=None, type=nonempty(), help=f"water preset ({water_names()}); default pond")
    p.add_argument("--c-per-m", type=positive_float(), default=None, help="beam attenuation c [1/m] (with --a-per-m)")
    p.add_argument("--a-per-m", type=positive_float(), default=None, help="absorption a [1/m] (with --c-per-m)")
    p.add_argument("--fresh", action="store_true", help="fresh water's group index (with --c-per-m/--a-per-m)")
    p.add_argument("--packets", type=positive_int(), default=SENSITIVITY_PACKETS,
                   help="beam packets of each member's table run (the default member uses the model's own tables)")
    p.add_argument("--reflectance", type=fraction(), default=0.1, help="the plate's Lambertian reflectance")
    p.add_argument("--seed", type=seed(), default=None, help="seed of the members' runs (default the tables' own)")
    add_output_options(p)
    p.set_defaults(run=_cmd_sensitivity)


def _cmd_pond_unknowns(args):
    from ..experiments import RANGING
    from ..studies.pond_unknowns import pond_unknowns_study

    if args.ranging not in RANGING:
        raise ValueError(f"--ranging {args.ranging!r}: must be one of {', '.join(RANGING)}")
    result = pond_unknowns_study(shots=args.shots, seed=args.seed, ranging=args.ranging)
    s = result["settings"]
    cells = [(d, ch) for d, chans in result["cases"][0]["detected"].items() for ch in chans]
    lines = [f"the pond's detected fractions as each unknown moves ({s['shots']} shots, seed {s['seed']}, "
             f"{s['ranging']} ranging, {s['elapsed_s']:.0f} s); the paper: {result['paper']}",
             f"{'unknown':26s} {'setting':62s} " + " ".join(f"{ch}@{d:>4s}" for d, ch in cells) + "  all"]
    for c in result["cases"]:
        lines.append(f"{c['unknown']:26s} {c['setting'][:62]:62s} "
                     + " ".join(f"{c['detected'][d][ch]:8.3f}" for d, ch in cells)
                     + f"  {'yes' if c['every_cell_half_the_shots'] else 'no'}")
    lines.append(f"phase function: {result['phase_function']}; band over {len(result['phase_functions'])} phase "
                 "functions")
    return result, "\n".join(lines), None


def _add_pond_unknowns(p: argparse.ArgumentParser) -> None:
    p.add_argument("--shots", type=positive_int(), default=1000, help="static shots at each distance")
    p.add_argument("--seed", type=seed(), default=0)
    p.add_argument("--ranging", default="prototype", type=nonempty(), help="prototype or template")
    add_output_options(p, plot=False)
    p.set_defaults(run=_cmd_pond_unknowns, no_plot=True, out=None)


BUILDERS = {"sensitivity": _add_sensitivity, "pond-unknowns": _add_pond_unknowns}
