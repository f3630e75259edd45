"""Subcommand ``uncertainty``: a pass's THU and TVU checked against its truth."""

from __future__ import annotations

import json

from muls.infra.command import nonempty, output_file, positive_int, seed
from scanner_sim.fidelity import FIDELITY_LEVELS


def _add_uncertainty(p):
    p.add_argument("scene", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--water", type=nonempty(), help="water preset instead of the scene's")
    p.add_argument("--seed", type=seed(), help="seed of the pass (default: the scene's survey.seed)")
    p.add_argument("--seeds", type=positive_int(), default=1, metavar="N",
                   help="run N passes, their survey and navigation-noise seeds derived from the seed, and pool their "
                        "points (default 1: the pass itself; at most 10,000); the JSON lists each pass's seeds and shares")
    p.add_argument("--fidelity", choices=list(FIDELITY_LEVELS), help="fidelity level (default: the scene's)")
    p.add_argument("--max-pulses", type=positive_int(), help="stop after this many pulses (default: the whole pass)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="set any scene key by its dotted name (YAML value), as `run --set`; repeatable")
    p.add_argument("--chart", type=output_file(), metavar="PNG", help="write the calibration chart to PNG")
    p.add_argument("--json", action="store_true", help="print the summary's uncertainty section as JSON")
    p.set_defaults(func=_cmd_uncertainty)


def _cmd_uncertainty(args) -> int:
    from scanner_sim.cli.passes import set_overrides
    from scanner_sim.config import load_scene
    from scanner_sim.studies.tpu_ensemble import check_ensemble_size
    from scanner_sim.survey.pipeline import simulate_pass
    from scanner_sim.survey.setup import PassOptions

    check_ensemble_size(args.seeds, "--seeds")
    config = load_scene(args.scene)
    config = config.with_overrides(set_overrides(args.set))  # --set, read as `run` reads it
    options = PassOptions(water=args.water, seed=args.seed, fidelity=args.fidelity, max_pulses=args.max_pulses,
                          progress=False, render=False)
    if args.seeds > 1:
        from scanner_sim.studies.tpu_ensemble import ensemble_calibration

        summary = ensemble_calibration(config, options, args.seeds)
        figures = {k: v for k, v in summary.items() if k not in ("scene", "water", "seed", "pulses", "points")}
    else:
        summary = simulate_pass(config, options).summary
        figures = summary["uncertainty"]
    cal = figures["calibration"]
    passes = f"{args.seeds} passes of seeds derived from {summary['seed']}" if args.seeds > 1 else f"seed {summary['seed']}"
    if args.chart is not None:
        from scanner_sim.render.calibration_chart import plot_calibration

        plot_calibration(args.chart, cal, title=f"{summary['scene']} in {summary['water']}: {summary['pulses']:,} "
                                                f"pulses, {passes}")
    if args.json:
        print(json.dumps({"scene": summary["scene"], "water": summary["water"], "seed": summary["seed"],
                          "pulses": summary["pulses"], "points": summary["points"], **figures}, indent=2))
        return 0
    print(f"{summary['scene']} in {summary['water']}: {summary['pulses']:,} pulses, {summary['points']:,} points, "
          f"{cal['points']:,} judged against the truth (not judged: "
          + ", ".join(f"{k} {v:,}" for k, v in cal["skipped"].items()) + ")")
    print(f"THU median {_m(figures['thu_m']['median'])}, p95 {_m(figures['thu_m']['p95'])}; "
          f"TVU median {_m(figures['tvu_m']['median'])}, p95 {_m(figures['tvu_m']['p95'])} (95 % confidence)")
    print(f"{'group':16s} {'points':>8s} {'|dz| <= TVU':>12s} {'dh <= THU':>10s}")
    rows = [("all", cal), *cal["per_channel"].items(),
            *((f"incidence {k}", v) for k, v in cal["per_incidence_deg"].items())]
    for name, row in rows:
        print(f"{name:16s} {row['points']:8,d} {_share(row['vertical_within_tvu']):>12s} "
              f"{_share(row['horizontal_within_thu']):>10s}")
    if args.seeds > 1:
        spread = figures["ensemble"]["vertical_within_tvu_spread"]
        print(f"{passes}: |dz| <= TVU per pass from {_share(spread['min'])} to {_share(spread['max'])}, "
              f"standard deviation {_share(spread['std'])}")
    if args.chart is not None:
        print(args.chart)
    return 0


def _m(value) -> str:
    return "-" if value is None else f"{value:.3f} m"


def _share(value) -> str:
    return "-" if value is None else f"{value:.3f}"


#: name -> the function that adds the subcommand's options to its parser and sets ``func``.
BUILDERS = {"uncertainty": _add_uncertainty}
