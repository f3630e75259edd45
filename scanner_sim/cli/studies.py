"""Subcommands that run studies of many passes: ``overlap``, ``tradeoff``, ``coverage``, ``campaign``."""

from __future__ import annotations

import json
import sys

from muls.infra.command import (
    non_negative_int,
    nonempty,
    output_dir,
    output_file,
    positive_float,
    positive_int,
    seed,
)
from scanner_sim.fidelity import FIDELITY_LEVELS
from scanner_sim.rays.beams import SUBRAY_COUNTS


# -- overlap ------------------------------------------------------------------------------------------------
def _add_overlap(p):
    p.add_argument("--distances-m", type=positive_float(), nargs="+", default=[1, 1.5, 2, 2.5, 3, 4, 5, 6, 7, 8],
                   help="plate distances [m]")
    p.add_argument("--subrays", type=positive_int(), choices=SUBRAY_COUNTS, default=61, metavar="N",
                   help=f"beam sub-rays, one of {', '.join(map(str, SUBRAY_COUNTS))}")
    p.add_argument("--profile", default="top_hat", choices=["top_hat", "gaussian"])
    p.add_argument("--instrument", default="mul2023", type=nonempty(), help="muls instrument preset (geometry only)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--out", type=output_file(), help="write a PNG plot here")
    p.set_defaults(func=_cmd_overlap)


def _cmd_overlap(args) -> int:
    import numpy as np

    from muls.infra.errors import ParameterError
    from muls.presets import instrument_preset, water_preset
    from scanner_sim.studies.raycast_overlap import raycast_overlap

    dist = np.asarray(args.distances_m, float)
    if np.any(~np.isfinite(dist)) or np.any(dist <= 0):
        raise ParameterError(f"--distances-m = {args.distances_m}: must all be finite and > 0")
    geometry = instrument_preset(args.instrument, water_preset("coastal_ocean")).geometry
    ray = raycast_overlap(dist, geometry, args.subrays, args.profile)
    ana = geometry.overlap(dist)
    result = {
        "distance_m": dist.tolist(),
        "raycast": [round(float(v), 6) for v in ray],
        "analytic": [round(float(v), 6) for v in ana],
        "max_abs_error": round(float(np.abs(ray - ana).max()), 6),
        "subrays": args.subrays,
        "profile": args.profile,
        "instrument": args.instrument,
        "blind_zone_m": round(geometry.blind_zone_m, 4),
        "full_overlap_m": round(geometry.full_overlap_m, 4),
    }
    if args.out:
        from scanner_sim.render.overlap_plot import plot_overlap

        dense = np.linspace(0.0, float(dist.max()) * 1.05, 400)
        plot_overlap(args.out, dist, ray, ana, title=f"Beam / receiver-FOV overlap, {args.instrument} geometry",
                     raycast_label=f"ray-cast, {args.subrays} sub-rays", dense_distance_m=dense,
                     dense_analytic=geometry.overlap(dense))
        result["plot"] = str(args.out)
    if args.json:
        print(json.dumps(result))
    else:
        print(f"{'distance_m':>10s} {'raycast':>8s} {'Eq. 11':>8s} {'error':>8s}")
        for z, r, a in zip(dist, ray, ana):
            print(f"{z:10.3f} {r:8.4f} {a:8.4f} {r - a:+8.4f}")
        print(f"max |error| {result['max_abs_error']:.4f} with {args.subrays} sub-rays")
    return 0


# -- tradeoff -----------------------------------------------------------------------------------------------
def _add_tradeoff(p):
    from scanner_sim.studies.defaults import DEFAULT_PULSES, DEFAULT_REPEAT, DEFAULT_WAVEFORM_PULSES, KNOBS

    p.add_argument("scene", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--levels", nargs="+", choices=list(FIDELITY_LEVELS), default=list(FIDELITY_LEVELS),
                   metavar="LEVEL", help=f"levels to run, of {', '.join(FIDELITY_LEVELS)} (default: all)")
    p.add_argument("--knobs", nargs="*", choices=list(KNOBS), default=list(KNOBS), metavar="KNOB",
                   help=f"single changes to balanced, of {', '.join(KNOBS)} (default: all; none: --knobs)")
    p.add_argument("--pulses", type=positive_int(), default=DEFAULT_PULSES,
                   help="pulses per run, in stretches spread over the pass when it fires more (default: %(default)s)")
    p.add_argument("--waveform-pulses", type=positive_int(), default=DEFAULT_WAVEFORM_PULSES,
                   help="pulses whose records are compared (default: %(default)s)")
    p.add_argument("--repeat", type=positive_int(), default=DEFAULT_REPEAT,
                   help="timed passes of each run, round-robin, the fastest kept (default: %(default)s)")
    p.add_argument("--out", type=output_dir(), help="output directory (default: the scene's output.dir + /tradeoff)")
    p.add_argument("--json", action="store_true", help="print tradeoff.json instead of the table")
    p.add_argument("--failure-rows", action="store_true",
                   help="print the levels' rows of the failure-scene table of docs/fidelity.md instead of the table")
    p.add_argument("--no-render", action="store_true", help="no chart")
    p.add_argument("--no-convergence", action="store_true",
                   help="skip the reference run at 217 sub-rays that shows the reference has converged")
    p.set_defaults(func=_cmd_tradeoff)


def _cmd_tradeoff(args) -> int:
    from pathlib import Path

    from scanner_sim.config import load_scene
    from scanner_sim.io.run_dir import hold_output
    from scanner_sim.studies.tradeoff import (
        check_tradeoff_memory,
        failure_table_rows,
        markdown_table,
        tradeoff,
        write_tradeoff,
    )

    config = load_scene(args.scene)
    check_tradeoff_memory(config, args.levels, args.knobs, args.pulses, args.waveform_pulses, not args.no_convergence,
                          keys=("--pulses", "--waveform-pulses"))
    out = Path(args.out or Path(config.output_dir) / "tradeoff")
    progress = None if args.json else (lambda name: print(f"running {name}", file=sys.stderr, flush=True))
    with hold_output(out):  # taken before the runs, so a second writer is refused at once
        result = tradeoff(config, tuple(args.levels), tuple(args.knobs), args.pulses, args.waveform_pulses, progress,
                          convergence=not args.no_convergence, repeat=args.repeat)
        path = write_tradeoff(result, out, render=not args.no_render)
    if args.json:
        print(json.dumps(result))
    elif args.failure_rows:
        print(failure_table_rows(result), end="")
    else:
        print(markdown_table(result) + str(path))
    return 0


# -- coverage -----------------------------------------------------------------------------------------------
def _add_coverage(p):
    from scanner_sim.metrics.coverage import CoverageSettings
    from scanner_sim.studies.defaults import DEFAULT_INSTRUMENTS, DEFAULT_WATERS, GATE_MODES, INSTRUMENTS

    p.add_argument("scene", nargs="?", default="cable_survey", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--waters", nargs="+", default=list(DEFAULT_WATERS), metavar="WATER", type=nonempty(),
                   help="water presets, or 'scene' for the scene's own water (default: %(default)s)")
    p.add_argument("--altitudes-m", nargs="+", type=positive_float("altitudes_m"), metavar="M",
                   help="altitudes [m] (default: the scene's)")
    p.add_argument("--instruments", nargs="+", default=list(DEFAULT_INSTRUMENTS), choices=INSTRUMENTS,
                   metavar="INSTRUMENT", help=f"instrument presets, of {', '.join(INSTRUMENTS)} (default: %(default)s)")
    p.add_argument("--gate", default="follow", choices=GATE_MODES,
                   help="a gate the scene sets, at other altitudes: follow the nadir echo (default) or keep the scene's "
                        "delay; a scene without one gets the operator's rule at every altitude")
    p.add_argument("--cell-m", type=positive_float("cell_m"), default=CoverageSettings.cell_m,
                   help="plan cell and cable stretch [m] (default: %(default)s)")
    p.add_argument("--min-points", type=positive_int("min_points"), default=CoverageSettings.min_points,
                   help="valid points a cell needs (default: %(default)s)")
    p.add_argument("--tolerance-m", type=positive_float("tolerance_m"), default=CoverageSettings.tolerance_m,
                   help="largest |range error| of a valid point [m] (default: %(default)s, IHO S-44 Exclusive Order)")
    p.add_argument("--order-min-soundings", type=positive_int("order_min_soundings"),
                   default=CoverageSettings.order_min_soundings,
                   help="soundings a cell of an S-44 order that must detect features (Exclusive, Special, 1a) needs, "
                        "on that order's own grid (default: %(default)s, S-44 Annex D)")
    p.add_argument("--cubes-m", nargs="+", type=positive_float("cubes_m"), metavar="M",
                   help="place cubes of these edge sizes [m] across the swath and report the share detected per size")
    p.add_argument("--cube-count", type=positive_int("cube_count"), default=8, help="cubes of each size (default: 8)")
    p.add_argument("--cube-seed", type=seed(), default=0, help="seed of the cube positions (default: 0)")
    p.add_argument("--out", type=output_dir(), help="output directory (default: the scene's output.dir + /coverage)")
    p.add_argument("--fidelity", choices=list(FIDELITY_LEVELS), help="fidelity level (default: the scene's)")
    p.add_argument("--seed", type=seed(), help="seed of every pass (default: the scene's survey.seed)")
    p.add_argument("--max-pulses", type=positive_int(), help="stop each pass after this many pulses")
    p.add_argument("--no-render", action="store_true", help="tables and coverage.json only: no pictures, no report")
    p.add_argument("--view-pass", metavar="NAME", type=nonempty(),
                   help="the pass whose interactive 3-D view report.html embeds, by its folder name, e.g. "
                        "clean_ocean-mul2023-6m (default: the first)")
    p.add_argument("--water-uncertainty", action="store_true",
                   help="also fly each combination with the phase functions of the weakest and strongest echo: covered "
                        "and Order 1a shares as (low, default, high) bands (docs/coverage.md)")
    p.add_argument("--quiet", action="store_true", help="no progress; print only the path of coverage.json")
    p.add_argument("--json", action="store_true", help="print coverage.json's content (records with their S-44 "
                   "orders, s44_orders) instead of the table and the path")
    _add_dask_arguments(p)
    p.set_defaults(func=_cmd_coverage)


def _cmd_coverage(args) -> int:
    from pathlib import Path

    from scanner_sim.config import load_scene
    from scanner_sim.io.run_dir import hold_output
    from scanner_sim.metrics.coverage import CoverageSettings
    from scanner_sim.render.report import main_table, markdown_table
    from scanner_sim.studies.coverage_study import CubePlan, StudyPlan, run_study

    config = load_scene(args.scene)
    _check_cell_memory(args, config)
    plan = StudyPlan(tuple(args.waters), tuple(args.altitudes_m) if args.altitudes_m else (None,),
                     tuple(args.instruments), args.gate, args.water_uncertainty)
    settings = CoverageSettings(args.cell_m, args.min_points, args.tolerance_m, args.order_min_soundings)
    out = Path(args.out or Path(config.output_dir) / "coverage")
    with hold_output(out):  # taken before the passes are built, so a second writer is refused at once
        study = run_study(config, plan, out, view_pass=args.view_pass, settings=settings, fidelity=args.fidelity, seed=args.seed,
                          max_pulses=args.max_pulses, render=not args.no_render, progress=not (args.quiet or args.json),
                          workers=_workers(args), scheduler=args.scheduler, redo=args.redo,
                          cubes=CubePlan(tuple(args.cubes_m), args.cube_count, args.cube_seed) if args.cubes_m else None)
    if args.json:
        print((out / "coverage.json").read_text(), end="")
        return 0
    if not args.quiet:
        print(markdown_table(*main_table(study)))
        print(f"{len(study['records'])} passes in {study['wall_s']:.0f} s")
    print(out / "coverage.json")
    return 0


def _check_cell_memory(args, config) -> None:
    """Refuse a --cell-m whose coverage cells over the scene's seabed, in every pass running at once, would need more
    memory than the study may plan on (budget.COVERAGE_BYTES_PER_CELL a cell, its map rendered included)."""
    import math

    from muls.infra.memory import check_memory
    from scanner_sim.survey.sizing import COVERAGE_BYTES_PER_CELL
    from scanner_sim.world.raster import seabed_plan_size_m

    size = seabed_plan_size_m(config)
    if size is None:  # the study refuses the scene itself (or measures a mesh seabed, sized once built)
        return
    cells = math.prod(math.ceil(s / args.cell_m) for s in size)
    from scanner_sim.runs.cluster import capped_workers

    workers = _workers(args)
    at_once = 1 if args.scheduler or workers == 0 else capped_workers(workers)

    def smallest(budget: float) -> str:
        cell = math.sqrt(math.prod(size) * COVERAGE_BYTES_PER_CELL * at_once / budget)
        step = 10.0 ** (math.floor(math.log10(cell)) - 1)  # rounded up to two digits
        return f"cells of at least {math.ceil(cell / step) * step:.2g} m on this machine"

    check_memory("--cell-m", args.cell_m, cells * COVERAGE_BYTES_PER_CELL * at_once,
                 f"coverage over {cells:,} cells of the {size[0]:g} x {size[1]:g} m seabed, {at_once} "
                 f"pass{'es' if at_once > 1 else ''} at once,", smallest)


# -- campaign -----------------------------------------------------------------------------------------------
def _add_dask_arguments(p) -> None:
    """--scheduler, --workers and --redo, shared by the commands that run passes on Dask."""
    p.add_argument("--scheduler", metavar="tcp://HOST:8786", type=nonempty(),
                   help="address of a running Dask scheduler (default: a local cluster on this machine)")
    p.add_argument("--workers", type=non_negative_int(), metavar="N", help="workers of the local cluster, one thread each "
                   "(default: one per core; at most one per core and one per pass; 0: every pass in this process, "
                   "without Dask)")
    p.add_argument("--redo", action="store_true", help="run every pass again, even those already complete in --out")


def _workers(args) -> int:
    """--workers, by default one per core."""
    from scanner_sim.runs.cluster import default_workers

    return default_workers() if args.workers is None else args.workers


def _add_campaign(p):
    p.add_argument("campaign", metavar="CAMPAIGN.yaml", type=nonempty(),
                   help="campaign file (e.g. scenes/campaigns/example_campaign.yaml)")
    p.add_argument("--out", type=output_dir(), help="output directory (default: out/campaigns/NAME)")
    p.add_argument("--quiet", action="store_true", help="no progress; print only the path of campaign.json")
    _add_dask_arguments(p)
    p.set_defaults(func=_cmd_campaign)


def _cmd_campaign(args) -> int:
    from pathlib import Path

    from scanner_sim.io.run_dir import hold_output
    from scanner_sim.runs.campaign import load_campaign, run_campaign
    from scanner_sim.runs.cluster import maybe_client

    campaign = load_campaign(args.campaign)
    out = Path(args.out or Path("out") / "campaigns" / campaign.name)
    # the folder's lock before the cluster starts, so a second writer is refused at once
    with hold_output(out), maybe_client(scheduler=args.scheduler, workers=_workers(args),
                                        announce=not args.quiet, passes=len(campaign.jobs)) as client:
        result = run_campaign(campaign, out, client, redo=args.redo, progress=not args.quiet)
    if not args.quiet:
        print(f"{len(result['passes'])} passes in {result['wall_s']:.0f} s: {result['ran']} ran, "
              f"{result['skipped']} already complete, {result['failed']} failed")
        for failed in (p for p in result["passes"] if p["status"] == "failed"):
            print(f"failed: {failed['dir']}: {failed['error']} (run the campaign again to redo it)")
    print(out / "campaign.json")
    return 1 if result["failed"] else 0


# -- plan ---------------------------------------------------------------------------------------------------
def _add_plan(p):
    from scanner_sim.metrics.s44 import ORDER_NAMES
    from scanner_sim.studies.defaults import DEFAULT_REQUIRED_SHARE, DEFAULT_WATERS

    p.add_argument("scene", type=nonempty(), help="shipped scene name or YAML path (a raster or procedural seabed)")
    p.add_argument("--order", required=True, type=nonempty(), metavar="ORDER",
                   help=f"IHO S-44 order, one of {', '.join(ORDER_NAMES)}")
    p.add_argument("--waters", nargs="+", default=list(DEFAULT_WATERS), metavar="WATER", type=nonempty(),
                   help="water presets (default: %(default)s)")
    p.add_argument("--altitudes-m", nargs="+", type=positive_float("altitudes_m"), metavar="M",
                   help="altitudes tried [m] (default: the scene's x 0.5, 1, 1.5)")
    p.add_argument("--speeds-m-s", nargs="+", type=positive_float("speeds_m_s"), metavar="M_S",
                   help="speeds tried [m/s] (default: the scene's x 0.5, 1)")
    p.add_argument("--required-share", type=positive_float("required_share"), default=DEFAULT_REQUIRED_SHARE,
                   help="share of the planned area the order must hold on (default: %(default)s)")
    p.add_argument("--sample-lines", type=positive_int("sample_lines"), default=3,
                   help="sample lines over the site, at its depth quantiles (default: %(default)s)")
    p.add_argument("--sample-length-m", type=positive_float("sample_length_m"), default=20.0,
                   help="length of each sample line [m] (default: %(default)s)")
    p.add_argument("--max-confirm-pulses", type=positive_int("max_confirm_pulses"), default=2_000_000,
                   help="largest confirmation pass; a larger plan is confirmed over a centred sample "
                        "(default: %(default)s)")
    p.add_argument("--out", type=output_dir(), help="output directory (default: the scene's output.dir + /plan)")
    p.add_argument("--no-render", action="store_true", help="no chart, no plan.html")
    p.add_argument("--quiet", action="store_true", help="no progress; print only the path of plan.json")
    p.add_argument("--json", action="store_true", help="print plan.json's content instead of the summary")
    _add_dask_arguments(p)
    p.set_defaults(func=_cmd_plan)


def _cmd_plan(args) -> int:
    from pathlib import Path

    from scanner_sim.config import load_scene
    from scanner_sim.render.plan_report import water_summary
    from scanner_sim.studies.planning import plan_survey

    config = load_scene(args.scene)
    out = Path(args.out or Path(config.output_dir) / "plan")
    plan_survey(config, args.order, tuple(args.waters), args.altitudes_m, args.speeds_m_s,
                required_share=float(args.required_share), sample_lines=args.sample_lines,
                sample_length_m=args.sample_length_m, max_confirm_pulses=args.max_confirm_pulses, out_dir=out,
                workers=_workers(args), scheduler=args.scheduler, redo=args.redo, render=not args.no_render,
                progress=not (args.quiet or args.json))
    text = (out / "plan.json").read_text()
    if args.json:
        print(text, end="")
        return 0
    if not args.quiet:
        data = json.loads(text)
        for water in data["waters"]:
            print(water_summary(data, water))
        print(f"{data['sample_passes']} sample passes, {data['confirmation_passes']} confirmation passes")
    print(out / "plan.json")
    return 0


#: name -> the function that adds the subcommand's options to its parser and sets ``func``.
BUILDERS = {"tradeoff": _add_tradeoff, "coverage": _add_coverage, "plan": _add_plan, "overlap": _add_overlap,
            "campaign": _add_campaign}
