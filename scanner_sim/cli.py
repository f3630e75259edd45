"""``scanner-sim`` command line.

Subcommands live in :data:`SUBCOMMANDS`, a registry of builder functions: adding one (``run``, ``bench``,
``coverage``, ``view``...) is a small, separate edit: write ``def _add_name(sub)`` that adds its parser and
sets ``func``, and decorate it with ``@subcommand("name")``. A ``ValueError`` (bad scene file, bad
parameter) becomes one line on stderr and exit code 2, without a traceback; every option is range-checked by
argparse through the typed helpers of :mod:`muls.command`, and any other ending is one line too (a full disk 1,
Ctrl-C 130, SIGTERM 143; ``docs/errors.md``).

It is longer than the other modules on purpose: it holds only the twelve subcommands' parsers and the thin
functions that call the package for them, one registry entry each; the work itself lives in the modules they
call.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable

from muls.command import (
    OneLineParser,
    checked_types,
    non_negative_float,
    non_negative_int,
    nonempty,
    output_dir,
    output_file,
    package_version,
    parse_guarded,
    positive_float,
    positive_int,
    run_guarded,
    seed,
)
from scanner_sim.fidelity import FIDELITY_LEVELS
from scanner_sim.rays.beams import SUBRAY_COUNTS

SUBCOMMANDS: dict[str, Callable] = {}


def subcommand(name: str):
    """Register a builder ``f(subparsers) -> None`` that adds subcommand ``name``."""

    def deco(builder):
        SUBCOMMANDS[name] = builder
        return builder

    return deco


# -- scenes ---------------------------------------------------------------------------------------------
@subcommand("scenes")
def _add_scenes(sub):
    p = sub.add_parser("scenes", help="list the shipped scenes, one line each")
    p.set_defaults(func=_cmd_scenes)


def _cmd_scenes(args) -> int:
    from scanner_sim.config import load_scene, shipped_scenes

    for name in shipped_scenes():
        cfg = load_scene(name)
        first = cfg.description.strip().splitlines()[0] if cfg.description.strip() else ""
        print(f"{name:18s} {first}")
    return 0


# -- validate -------------------------------------------------------------------------------------------
@subcommand("validate")
def _add_validate(sub):
    p = sub.add_parser("validate", help="check a scene file (shipped name or path); exit 2 when it is wrong")
    p.add_argument("scene", type=nonempty(), help="shipped scene name (see `scanner-sim scenes`) or path to a YAML file")
    p.add_argument("--build", action="store_true", help="also build the meshes and the trajectory")
    p.set_defaults(func=_cmd_validate)


def _cmd_validate(args) -> int:
    from scanner_sim.config import load_scene

    cfg = load_scene(args.scene)
    cfg.water_model()
    inst = cfg.instrument_model()
    extra = ""
    if args.build:
        from scanner_sim.motion.track_checks import build_trajectory
        from scanner_sim.world.scene import build_scene

        scene = build_scene(cfg)
        traj = build_trajectory(cfg, scene)
        extra = f", {scene.n_faces:,} triangles, pass {traj.duration_s:.1f} s"
    print(f"OK {cfg.name}: water {cfg.water.preset or 'custom'}, instrument {inst.name}, "
          f"{len(cfg.objects)} objects, platform {cfg.platform.mode}, scanner {cfg.scanner.mode}{extra}")
    return 0


# -- overlap --------------------------------------------------------------------------------------------
@subcommand("overlap")
def _add_overlap(sub):
    p = sub.add_parser("overlap", help="ray-cast overlap on a perpendicular plate vs MULS Eq. 11")
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

    from muls.errors import ParameterError
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
        from scanner_sim.render.viz import plot_overlap

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


# -- bench-rays -----------------------------------------------------------------------------------------
@subcommand("bench-rays")
def _add_bench_rays(sub):
    p = sub.add_parser("bench-rays", help="ray throughput: the pipeline's ray stage vs raw embreex, same rays")
    p.add_argument("scene", nargs="?", default="cable_survey", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--pulses", type=positive_int(), default=20000, help="scan-ordered pulses in the chunk")
    p.add_argument("--subrays", type=positive_int(), choices=SUBRAY_COUNTS, default=19, metavar="N",
                   help=f"beam sub-rays, one of {', '.join(map(str, SUBRAY_COUNTS))}")
    p.add_argument("--repeat", type=positive_int(), default=3, help="best of this many timings")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_rays)


def _cmd_bench_rays(args) -> int:
    from scanner_sim.perf.raybench import bench_rays

    result = bench_rays(args.scene, args.pulses, args.subrays, args.repeat)
    if args.json:
        print(json.dumps(result))
    else:
        for k, v in result.items():
            print(f"{k:28s} {v}")
    return 0


# -- schema ---------------------------------------------------------------------------------------------
@subcommand("schema")
def _add_schema(sub):
    p = sub.add_parser("schema", help="print the JSON Schema of scene files (editors validate and complete with it)")
    p.add_argument("--out", metavar="FILE", type=output_file(),
                   help="write the schema to FILE (atomically) instead of printing it")
    p.set_defaults(func=_cmd_schema)


def _cmd_schema(args) -> int:
    from scanner_sim.config import scene_json_schema

    text = json.dumps(scene_json_schema(), indent=2) + "\n"
    if args.out is None:
        sys.stdout.write(text)
        return 0
    from scanner_sim.io import write_text

    write_text(args.out, text)
    print(args.out)
    return 0


# -- run ------------------------------------------------------------------------------------------------
@subcommand("run")
def _add_run(sub):
    p = sub.add_parser("run", help="simulate a survey pass: points.las, dropouts, summary, trajectory, render")
    p.add_argument("scene", nargs="?", default="cable_survey", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--out", type=output_dir(), help="output directory (default: the scene's output.dir); an earlier "
                   "run there is replaced whole once this one is complete")
    p.add_argument("--water", type=nonempty(), help="water preset instead of the scene's (clean_ocean, coastal_ocean, ...)")
    p.add_argument("--seed", type=seed(), help="seed of the pass (default: the scene's survey.seed)")
    p.add_argument("--fidelity", choices=list(FIDELITY_LEVELS), help="fidelity level (default: the scene's)")
    p.add_argument("--max-pulses", type=positive_int(), help="stop after this many pulses")
    p.add_argument("--chunk-pulses", type=positive_int(), help="pulse slots per chunk (memory vs overhead)")
    p.add_argument("--waveforms", type=non_negative_int(), default=0,
                   help="also write the full records of N sampled pulses")
    p.add_argument("--altitude-m", type=positive_float(), help="fly at this altitude over the seabed (platform.altitude_m)")
    p.add_argument("--gate-delay-ns", type=non_negative_float(),
                   help="open the far channel's gate this long after the pulse (instrument.gate_delay_ns)")
    p.add_argument("--gate-width-ns", type=positive_float(), help="gate width (default: the scene's or the preset's)")
    p.add_argument("--split-lines", action="store_true",
                   help="one point cloud and one trajectory per survey leg (output.split_legs)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="set any scene key by its dotted name (YAML value), validated like the scene file; "
                        "repeatable, e.g. --set survey.subrays=37 --set output.laz=true")
    p.add_argument("--no-render", action="store_true", help="skip render.png")
    p.add_argument("--quiet", action="store_true", help="no progress bar; print only the summary path")
    p.set_defaults(func=_cmd_run)


def scene_overrides(args, config) -> dict:
    """The scene keys that ``run``'s options set, by dotted name (validated later with the scene)."""
    import yaml

    from scanner_sim.config.errors import shown
    from scanner_sim.config.loading import _StrictLoader

    changes = {}
    for item in args.set:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--set {item!r}: must be KEY=VALUE with a dotted scene key, e.g. platform.altitude_m=5")
        try:  # the scene loader's bounds (depth, aliases, tags) hold for a value given here too
            changes[key.strip()] = yaml.load(text, Loader=_StrictLoader)
        except yaml.YAMLError as exc:
            problem = getattr(exc, "problem", None) or str(exc)
            raise ValueError(f"--set {shown(item)}: not a YAML value ({' '.join(str(problem).split())})") from None
    if args.altitude_m is not None:
        changes["platform.altitude_m"] = args.altitude_m
    if args.gate_delay_ns is not None or args.gate_width_ns is not None:
        gated = [ch for ch in config.instrument_model().channels if ch.gated]
        if not gated:
            raise ValueError(f"--gate-delay-ns: instrument '{config.instrument.preset}' has no gated channel")
        changes["instrument.gate_delay_ns"] = (args.gate_delay_ns if args.gate_delay_ns is not None
                                               else gated[0].gate_delay_s * 1e9)
        changes["instrument.gate_width_ns"] = (args.gate_width_ns if args.gate_width_ns is not None
                                               else gated[0].gate_width_s * 1e9)
    if args.split_lines:
        changes["output.split_legs"] = True
    return changes


def _first_run_notice() -> None:
    """Say so when numba has no cached kernels yet: the first run compiles them for about a minute."""
    from pathlib import Path

    import muls
    from muls.kernel_cache import kernel_cache_dir

    cache = kernel_cache_dir() or Path(muls.__file__).parent / "__pycache__"
    if not any(cache.rglob("detection._digitise*.nbi")):
        print("first run: compiling the simulation kernels (about a minute; later runs load them from the cache)",
              file=sys.stderr, flush=True)


def _cmd_run(args) -> int:
    from pathlib import Path

    from scanner_sim.config import load_scene
    from scanner_sim.survey.pipeline import PassOptions, run_pass

    config = load_scene(args.scene)
    config = config.with_overrides(scene_overrides(args, config))
    options = PassOptions(water=args.water, seed=args.seed, fidelity=args.fidelity, max_pulses=args.max_pulses,
                          chunk_pulses=args.chunk_pulses, waveforms=args.waveforms, progress=not args.quiet,
                          render=not args.no_render)
    out = Path(args.out or config.output_dir)
    _first_run_notice()
    summary = run_pass(config, out, options).summary
    if not args.quiet:
        dropped = ", ".join(f"{k} {v:,}" for k, v in summary["dropouts"].items() if v) or "none"
        print(f"{summary['pulses']:,} pulses -> {summary['points']:,} points in {summary['wall_s']:.1f} s "
              f"({summary['pulses_per_s']:,.0f} pulses/s); dropouts: {dropped}")
        error = summary["range_error_m"]
        if error["median"] is None:
            print("range error: no point has a truth surface along its line of sight")
        else:
            print(f"range error |median| {100 * error['median']:.1f} cm, p95 {100 * error['p95']:.1f} cm")
        cov = summary.get("coverage")
        if cov and cov["covered_fraction"] is not None:
            gaps = ", ".join(f"{k} {v:.2f} m²" for k, v in cov["gaps_m2"].items() if v) or "none"
            print(f"coverage {100 * cov['covered_fraction']:.1f} % of {cov['reached_area_m2']:.0f} m² reached "
                  f"(cells of {cov['cell_m']:g} m); gaps: {gaps}")
    print(out / "summary.json")
    return 0


# -- bench ----------------------------------------------------------------------------------------------
@subcommand("bench")
def _add_bench(sub):
    p = sub.add_parser("bench", help="end-to-end pulses/s per fidelity beside raw embreex on the same rays, with "
                       "cores used and peak memory, and a two-million-triangle seabed")
    p.add_argument("scene", nargs="?", default="cable_survey", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--pulses", type=positive_int(), default=60000, help="pulses per fidelity level")
    p.add_argument("--repeat", type=positive_int(), default=5,
                   help="timed passes per level (the best is kept, the median reported beside it)")
    p.add_argument("--no-large-seabed", action="store_true", help="skip the two-million-triangle seabed case")
    p.add_argument("--profile", choices=list(FIDELITY_LEVELS), metavar="LEVEL",
                   help="instead: CPU seconds per stage of one pass at LEVEL on one numba thread (scanner_sim.perf.profiling)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench)


def _cmd_bench(args) -> int:
    from scanner_sim.perf.bench import bench_pass

    if args.profile:
        return _print_profile(args)
    result = bench_pass(args.scene, args.pulses, args.repeat, large_seabed=not args.no_large_seabed)
    if args.json:
        print(json.dumps(result))
        return 0
    rows = [(name, result[name]) for name in FIDELITY_LEVELS]
    if "large_seabed" in result:
        big = result["large_seabed"]
        rows.append((f"balanced, {big['triangles'] / 1e6:.1f} M triangles", big["balanced"]))
    for name, r in rows:
        print(f"{name:28s} {r['pulses_per_s']:>9,.0f} pulses/s (median {r['median_pulses_per_s']:>9,.0f})"
              f"  raw embreex {r['raw_embreex_pulses_per_s']:>9,.0f}  ratio {r['ratio_to_raw_rays']:.2f}"
              f"  cores {r['cores_used']:.2f}  peak {r['peak_rss_mb']:,.0f} MB")
    if "large_seabed" in result:
        big = result["large_seabed"]
        print(f"large seabed: scene build {big['scene_build_s']:.1f} s, BVH {big['bvh_build_s']:.1f} s")
    return 0


def _print_profile(args) -> int:
    from scanner_sim.perf.profiling import stage_profile

    result = stage_profile(args.scene, args.profile, args.pulses)
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"{result['fidelity']} on {result['scene']}, {result['pulses']:,} pulses, one numba thread, stage after stage:")
    for stage, r in result["stages"].items():
        print(f"  {stage:32s} {r['cpu_s']:7.3f} s  {r['us_per_pulse']:6.2f} us/pulse  {100 * r['share']:5.1f} %")
    print(f"  {'total':32s} {result['cpu_s_one_thread']:7.3f} s")
    print(f"the ordinary pass: {result['pass_pulses_per_s']:,.0f} pulses/s on {result['pass_cores_used']:.2f} cores")
    return 0


# -- tradeoff -------------------------------------------------------------------------------------------
@subcommand("tradeoff")
def _add_tradeoff(sub):
    from scanner_sim.studies.tradeoff import DEFAULT_PULSES, DEFAULT_REPEAT, DEFAULT_WAVEFORM_PULSES, KNOBS

    p = sub.add_parser("tradeoff", help="speed against accuracy: each fidelity level and knob on the same pulses, "
                       "against the truth and the reference level (chart, table, JSON)")
    p.add_argument("scene", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--levels", nargs="+", choices=list(FIDELITY_LEVELS), default=list(FIDELITY_LEVELS),
                   metavar="LEVEL", help=f"levels to run, of {', '.join(FIDELITY_LEVELS)} (default: all)")
    p.add_argument("--knobs", nargs="*", choices=list(KNOBS), default=list(KNOBS), metavar="KNOB",
                   help=f"single changes to balanced, of {', '.join(KNOBS)} (default: all; none: --knobs)")
    p.add_argument("--pulses", type=positive_int(), default=DEFAULT_PULSES, help="pulses per run (default: %(default)s)")
    p.add_argument("--waveform-pulses", type=positive_int(), default=DEFAULT_WAVEFORM_PULSES,
                   help="pulses whose records are compared (default: %(default)s)")
    p.add_argument("--repeat", type=positive_int(), default=DEFAULT_REPEAT,
                   help="timed passes of each run, round-robin, the fastest kept (default: %(default)s)")
    p.add_argument("--out", type=output_dir(), help="output directory (default: the scene's output.dir + /tradeoff)")
    p.add_argument("--json", action="store_true", help="print tradeoff.json instead of the table")
    p.add_argument("--no-render", action="store_true", help="no chart")
    p.add_argument("--no-convergence", action="store_true",
                   help="skip the reference run at 217 sub-rays that shows the reference has converged")
    p.set_defaults(func=_cmd_tradeoff)


def _cmd_tradeoff(args) -> int:
    from pathlib import Path

    from scanner_sim.config import load_scene
    from scanner_sim.studies.tradeoff import markdown_table, tradeoff, write_tradeoff

    config = load_scene(args.scene)
    out = Path(args.out or Path(config.output_dir) / "tradeoff")
    progress = None if args.json else (lambda name: print(f"running {name}", file=sys.stderr, flush=True))
    result = tradeoff(config, tuple(args.levels), tuple(args.knobs), args.pulses, args.waveform_pulses, progress,
                      convergence=not args.no_convergence, repeat=args.repeat)
    path = write_tradeoff(result, out, render=not args.no_render)
    print(json.dumps(result) if args.json else markdown_table(result) + str(path))
    return 0


# -- view -----------------------------------------------------------------------------------------------
#: ``--color`` name (also the ``viz`` colouring) -> the PointRecords field it shows.
_VIEW_FIELDS = {"class": "classification", "intensity": "intensity", "channel": "channel",
                "range_error": "range_error_m", "snr": "snr"}


@subcommand("view")
def _add_view(sub):
    p = sub.add_parser("view", help="look at a points.las over its scene.ply: a window, or a PNG without a display")
    p.add_argument("las", metavar="POINTS.las", type=nonempty(), help="a LAS file, e.g. out/cable_survey/points.las")
    p.add_argument("--color", default="class", choices=list(_VIEW_FIELDS), help="point colouring (default: class)")
    p.add_argument("--screenshot", metavar="PNG", type=output_file(),
                   help="render off-screen to this PNG instead of opening a window "
                   "(without a display the default is POINTS.<color>.png beside the LAS)")
    p.add_argument("--no-mesh", action="store_true", help="do not draw the scene.ply beside the LAS (or one directory up)")
    p.add_argument("--point-size", type=positive_float(), default=3.0, help="pixels")
    p.add_argument("--max-points", type=positive_int(), default=2_000_000, help="thin larger clouds by a fixed stride")
    p.add_argument("--window-size", type=positive_int(), nargs=2, default=[1600, 1000], metavar=("WIDTH", "HEIGHT"),
                   help="pixels")
    p.add_argument("--open3d", action="store_true",
                   help="an interactive open3d window instead of pyvista (needs a display and the open3d extra)")
    p.set_defaults(func=_cmd_view)


def _cmd_view(args) -> int:
    import os
    from pathlib import Path

    import laspy

    from scanner_sim.io import read_las, read_scene_ply
    from scanner_sim.render import viz

    las = Path(args.las)
    if not las.is_file():
        raise ValueError(f"POINTS.las = {str(las)!r}: no such file; expected a LAS file such as points.las")
    try:
        points = read_las(las)
    except (laspy.LaspyException, EOFError, OSError, ValueError) as exc:
        raise ValueError(f"POINTS.las = {str(las)!r}: not a readable LAS file ({exc})") from None
    mesh = {}
    # A pass writes scene.ply beside its LAS; a coverage study writes it once, one directory up.
    ply = next((d / "scene.ply" for d in (las.parent, las.parent.parent) if (d / "scene.ply").is_file()), None)
    if not args.no_mesh and ply is not None:
        scene = read_scene_ply(ply)
        mesh = {"truth_vertices": scene["vertices"], "truth_faces": scene["faces"]}
    values = getattr(points, _VIEW_FIELDS[args.color])
    colouring = ({"classification": values} if args.color == "class" else
                 {"color_by": args.color, "scalars": values})
    options = dict(title=f"{las}: {len(values):,} points coloured by {args.color}", point_size=args.point_size,
                   max_points=args.max_points, window_size=tuple(args.window_size), **colouring, **mesh)
    png = args.screenshot
    if args.open3d:
        if not os.environ.get("DISPLAY"):
            raise ValueError("--open3d: opens a window, and there is no display (DISPLAY is unset); "
                             "use --screenshot PNG instead")
        viz.show_open3d(points.xyz, viz.point_rgb(values, args.color), title=str(las),
                        **{k: v for k, v in mesh.items()})
        return 0
    if png is None and os.environ.get("DISPLAY"):
        viz.show_point_cloud(points.xyz, **options)
        return 0
    png = Path(png) if png is not None else las.with_suffix(f".{args.color}.png")
    viz.render_point_cloud(png, points.xyz, **options)
    print(png)
    return 0


# -- swath ----------------------------------------------------------------------------------------------
@subcommand("swath")
def _add_swath(sub):
    p = sub.add_parser("swath", help="swath-to-swath consistency of overlapping survey lines (open3d extra)")
    p.add_argument("path", type=nonempty(), help="a pass folder (points.las/laz or leg*_points.*) or one LAS/LAZ file")
    p.add_argument("--overlap-m", type=positive_float(), default=0.5,
                   help="largest nearest-neighbour distance [m] of a point in the overlap")
    p.add_argument("--json", action="store_true", help="print the pairs as JSON")
    p.set_defaults(func=_cmd_swath)


def _cmd_swath(args) -> int:
    from pathlib import Path

    from scanner_sim.io import read_las
    from scanner_sim.metrics.swath import swath_consistency
    from scanner_sim.survey.point_records import PointRecords

    path = Path(args.path)
    if path.is_file():
        files = [path]
    elif path.is_dir():  # one cloud of the pass: its LAS or its LAZ, whole or per leg
        files = (sorted(path.glob("points.la[sz]"))[:1]
                 or sorted(path.glob("leg*_points.las")) or sorted(path.glob("leg*_points.laz")))
    else:
        files = []
    if not files:
        raise ValueError(f"path = {str(path)!r}: no points.las/laz, leg*_points.las/laz nor LAS file there")
    pairs = swath_consistency(PointRecords.concatenate([read_las(f) for f in files]), args.overlap_m)
    if args.json:
        print(json.dumps({"pairs": pairs, "overlap_m": args.overlap_m}))
        return 0
    if not pairs:
        print("no two survey lines with points: nothing to compare")
    for r in pairs:
        print(f"lines {r['leg_a']}-{r['leg_b']}: {r['overlap_points']:,} points in the overlap, C2C median "
              f"{100 * r['c2c_median_m']:.1f} cm (p95 {100 * r['c2c_p95_m']:.1f} cm), vertical difference "
              f"{100 * r['dz_mean_m']:+.1f} cm mean, {100 * r['dz_rms_m']:.1f} cm RMS")
    return 0


# -- coverage -------------------------------------------------------------------------------------------
@subcommand("coverage")
def _add_coverage(sub):
    from scanner_sim.metrics.coverage import CoverageSettings
    from scanner_sim.studies.coverage_study import DEFAULT_INSTRUMENTS, DEFAULT_WATERS, GATE_MODES, INSTRUMENTS

    p = sub.add_parser("coverage", help="mapping coverage per water type x altitude x instrument, with its report")
    p.add_argument("scene", nargs="?", default="cable_survey", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--waters", nargs="+", default=list(DEFAULT_WATERS), metavar="WATER", type=nonempty(),
                   help="water presets (default: %(default)s)")
    p.add_argument("--altitudes-m", nargs="+", type=positive_float("altitudes_m"), metavar="M",
                   help="altitudes [m] (default: the scene's)")
    p.add_argument("--instruments", nargs="+", default=list(DEFAULT_INSTRUMENTS), choices=INSTRUMENTS,
                   metavar="INSTRUMENT", help=f"instrument presets, of {', '.join(INSTRUMENTS)} (default: %(default)s)")
    p.add_argument("--gate", default="follow", choices=GATE_MODES,
                   help="far gate at other altitudes: follow the nadir echo (default) or keep the scene's delay")
    p.add_argument("--cell-m", type=positive_float("cell_m"), default=CoverageSettings.cell_m,
                   help="plan cell and cable stretch [m] (default: %(default)s)")
    p.add_argument("--min-points", type=positive_int("min_points"), default=CoverageSettings.min_points,
                   help="valid points a cell needs (default: %(default)s)")
    p.add_argument("--tolerance-m", type=positive_float("tolerance_m"), default=CoverageSettings.tolerance_m,
                   help="largest |range error| of a valid point [m] (default: %(default)s, IHO S-44 Exclusive Order)")
    p.add_argument("--out", type=output_dir(), help="output directory (default: the scene's output.dir + /coverage)")
    p.add_argument("--fidelity", choices=list(FIDELITY_LEVELS), help="fidelity level (default: the scene's)")
    p.add_argument("--seed", type=seed(), help="seed of every pass (default: the scene's survey.seed)")
    p.add_argument("--max-pulses", type=positive_int(), help="stop each pass after this many pulses")
    p.add_argument("--no-render", action="store_true", help="tables and coverage.json only: no pictures, no report")
    p.add_argument("--quiet", action="store_true", help="no progress; print only the path of coverage.json")
    _add_dask_arguments(p)
    p.set_defaults(func=_cmd_coverage)


def _cmd_coverage(args) -> int:
    from pathlib import Path

    from scanner_sim.config import load_scene
    from scanner_sim.metrics.coverage import CoverageSettings
    from scanner_sim.render.report import main_table, markdown_table
    from scanner_sim.studies.coverage_study import StudyPlan, run_study

    config = load_scene(args.scene)
    plan = StudyPlan(tuple(args.waters), tuple(args.altitudes_m) if args.altitudes_m else (None,),
                     tuple(args.instruments), args.gate)
    settings = CoverageSettings(args.cell_m, args.min_points, args.tolerance_m)
    out = Path(args.out or Path(config.output_dir) / "coverage")
    study = run_study(config, plan, out, settings=settings, fidelity=args.fidelity, seed=args.seed,
                      max_pulses=args.max_pulses, render=not args.no_render, progress=not args.quiet,
                      workers=_workers(args), scheduler=args.scheduler, redo=args.redo)
    if not args.quiet:
        print(markdown_table(*main_table(study)))
        print(f"{len(study['records'])} passes in {study['wall_s']:.0f} s")
    print(out / "coverage.json")
    return 0


# -- campaign -------------------------------------------------------------------------------------------
def _add_dask_arguments(p) -> None:
    """--scheduler, --workers and --redo, shared by the commands that run passes on Dask."""
    p.add_argument("--scheduler", metavar="tcp://HOST:8786", type=nonempty(),
                   help="address of a running Dask scheduler (default: a local cluster on this machine)")
    p.add_argument("--workers", type=non_negative_int(), metavar="N", help="workers of the local cluster, one thread each "
                   "(default: one per core; 0: every pass in this process, without Dask)")
    p.add_argument("--redo", action="store_true", help="run every pass again, even those already complete in --out")


def _workers(args) -> int:
    """--workers, by default one per core."""
    from scanner_sim.runs.tasks import default_workers

    return default_workers() if args.workers is None else args.workers


@subcommand("campaign")
def _add_campaign(sub):
    p = sub.add_parser("campaign", help="one pass per combination of the swept scene keys, on Dask "
                       "(docs/campaigns.md)")
    p.add_argument("campaign", metavar="CAMPAIGN.yaml", type=nonempty(),
                   help="campaign file (e.g. scenes/campaigns/example_campaign.yaml)")
    p.add_argument("--out", type=output_dir(), help="output directory (default: out/campaigns/NAME)")
    p.add_argument("--quiet", action="store_true", help="no progress; print only the path of campaign.json")
    _add_dask_arguments(p)
    p.set_defaults(func=_cmd_campaign)


def _cmd_campaign(args) -> int:
    from pathlib import Path

    from scanner_sim.runs.campaign import load_campaign, run_campaign
    from scanner_sim.runs.tasks import maybe_client

    campaign = load_campaign(args.campaign)
    out = Path(args.out or Path("out") / "campaigns" / campaign.name)
    with maybe_client(scheduler=args.scheduler, workers=_workers(args), announce=not args.quiet) as client:
        result = run_campaign(campaign, out, client, redo=args.redo, progress=not args.quiet)
    if not args.quiet:
        print(f"{len(result['passes'])} passes in {result['wall_s']:.0f} s: {result['ran']} ran, "
              f"{result['skipped']} already complete, {result['failed']} failed")
        for failed in (p for p in result["passes"] if p["status"] == "failed"):
            print(f"failed: {failed['dir']}: {failed['error']} (run the campaign again to redo it)")
    print(out / "campaign.json")
    return 1 if result["failed"] else 0


# -- main -----------------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="scanner-sim", description="Underwater lidar survey simulator (MULS)")
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    sub.required = True
    for builder in SUBCOMMANDS.values():
        builder(sub)
    checked_types(parser)  # an option a builder left with a plain type still rejects empty text and nan
    return parser


def main(argv=None) -> int:
    """Entry point of ``scanner-sim``; returns the exit code: 0, 1 (a failure such as a full disk), 2 (bad
    input), 130 (Ctrl-C) or 143 (SIGTERM), with one line on stderr for anything but 0 (``docs/errors.md``)."""
    from scanner_sim.rays.cast import tune_memory

    tune_memory()  # reuse chunk-sized arrays instead of page-faulting them anew (measured, see raycast)
    args, code = parse_guarded(build_parser(), argv)
    if args is None:  # --help, --version (0) or a bad argument (2, one line printed)
        return code
    import laspy
    import yaml

    # a corrupt LAS or YAML file is bad input like a wrong scene key: exit 2
    return run_guarded(f"scanner-sim {args.command}", lambda: args.func(args),
                       bad_input=(laspy.LaspyException, yaml.YAMLError))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
