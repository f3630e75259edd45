"""Subcommands about scenes and passes: ``scenes``, ``validate``, ``schema``, ``run``."""

from __future__ import annotations

import json
import sys

from muls.infra.command import (
    non_negative_float,
    non_negative_int,
    nonempty,
    output_dir,
    output_file,
    positive_float,
    positive_int,
    seed,
)
from scanner_sim.fidelity import FIDELITY_LEVELS


# -- scenes -------------------------------------------------------------------------------------------------
def _add_scenes(p):
    p.set_defaults(func=_cmd_scenes)


def _cmd_scenes(args) -> int:
    from scanner_sim.config.loading import parse_yaml_text, read_scene_text, shipped_scenes

    for name, path in shipped_scenes().items():  # each file's description alone: no raster or mesh opened to list it
        description = str(parse_yaml_text(read_scene_text(path), path).get("description") or "").strip()
        first = description.splitlines()[0] if description else ""
        print(f"{name:18s} {first}")
    return 0


# -- validate -----------------------------------------------------------------------------------------------
def _add_validate(p):
    p.add_argument("scene", type=nonempty(), help="shipped scene name (see `scanner-sim scenes`) or path to a YAML file")
    p.add_argument("--build", action="store_true", help="also build the meshes and the trajectory")
    p.set_defaults(func=_cmd_validate)


def _cmd_validate(args) -> int:
    from scanner_sim.config import load_scene
    from scanner_sim.config.raster_seabed import RasterSeabedConfig

    cfg = load_scene(args.scene)
    cfg.water_model()
    inst = cfg.instrument_model()
    if isinstance(cfg.seabed, RasterSeabedConfig):  # the same check, the same line, as `run`'s
        from scanner_sim.world.raster import check_raster_frame, plan_bounds  # rasterio: only for a raster's header

        check_raster_frame(cfg.seabed, plan_bounds(cfg), cfg.crs)
    extra = ""
    if args.build:
        from scanner_sim.survey.setup import checked_trajectory
        from scanner_sim.world.scene import build_scene

        scene = build_scene(cfg)
        traj = checked_trajectory(cfg, scene)
        extra = f", {scene.n_faces:,} triangles, pass {traj.duration_s:.1f} s"
    print(f"OK {cfg.name}: water {cfg.water.preset or 'custom'}, instrument {inst.name}, "
          f"{len(cfg.objects)} objects, platform {cfg.platform.mode}, scanner {cfg.scanner.mode}{extra}")
    return 0


def _no_seabed_note(summary: dict) -> str:
    """How many ``no_hit`` dropouts were aimed where the seabed has no data, naming a raster's nodata value."""
    n = summary.get("no_hit_over_no_seabed")
    if not n:
        return ""
    seabed = summary.get("seabed")
    if seabed is None:
        return f" ({n:,} of them aimed beyond the seabed's edge)"
    nodata = "" if seabed.get("nodata") is None else f" ({seabed['nodata']:g})"
    return f" ({n:,} of them aimed where the raster has nodata{nodata} or beyond its edge: no seabed to meet)"


# -- schema -------------------------------------------------------------------------------------------------
def _add_schema(p):
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


# -- run ----------------------------------------------------------------------------------------------------
def _add_run(p):
    p.add_argument("scene", nargs="?", default="cable_survey", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--out", type=output_dir(), help="output directory (default: the scene's output.dir); an earlier "
                   "run there is replaced whole once this one is complete")
    p.add_argument("--water", type=nonempty(), help="water preset instead of the scene's (clean_ocean, coastal_ocean, ...)")
    p.add_argument("--seed", type=seed(), help="seed of the pass (default: the scene's survey.seed)")
    p.add_argument("--fidelity", choices=list(FIDELITY_LEVELS), help="fidelity level (default: the scene's)")
    p.add_argument("--max-pulses", type=positive_int(), help="stop after this many pulses")
    p.add_argument("--chunk-pulses", type=positive_int(), help="pulses per chunk (memory vs overhead)")
    p.add_argument("--waveforms", type=non_negative_int(), default=0,
                   help="also write the full records of N sampled pulses")
    p.add_argument("--altitude-m", type=positive_float(), help="fly at this altitude over the seabed (platform.altitude_m)")
    p.add_argument("--gate-delay-ns", type=non_negative_float(),
                   help="open the far channel's gate this long after the pulse (instrument.gate_delay_ns)")
    p.add_argument("--gate-width-ns", type=positive_float(), help="gate width (default: the scene's or the preset's)")
    p.add_argument("--split-lines", action="store_true",
                   help="one point cloud and one trajectory per survey leg (output.split_legs)")
    p.add_argument("--copc", action="store_true",
                   help="also write points.copc.laz, a Cloud-Optimised Point Cloud for Potree and QGIS (output.copc)")
    p.add_argument("--rosbag", metavar="DIR", type=output_dir(),
                   help="also write the pass as a ROS 2 bag in folder DIR (output.rosbag.dir; frame and storage: "
                        "--set output.rosbag.frame=ned, output.rosbag.storage=sqlite3)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="set any scene key by its dotted name (YAML value), validated like the scene file; "
                        "repeatable, e.g. --set survey.subrays=37 --set output.laz=true")
    p.add_argument("--no-render", action="store_true", help="skip render.png")
    p.add_argument("--quiet", action="store_true", help="no progress bar; print only the summary path")
    p.set_defaults(func=_cmd_run)


def set_overrides(items: list[str]) -> dict:
    """The scene keys that ``--set KEY=VALUE`` options set, by dotted name (validated later with the scene)."""
    import yaml

    from scanner_sim.config.errors import shown
    from scanner_sim.config.loading import load_strict_yaml

    changes = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--set {item!r}: must be KEY=VALUE with a dotted scene key, e.g. platform.altitude_m=5")
        try:  # the scene loader's bounds (depth, aliases, tags) hold for a value given here too
            changes[key.strip()] = load_strict_yaml(text)
        except yaml.YAMLError as exc:
            problem = getattr(exc, "problem", None) or str(exc)
            raise ValueError(f"--set {shown(item)}: not a YAML value ({' '.join(str(problem).split())})") from None
    return changes


def scene_overrides(args, config) -> dict:
    """The scene keys that ``run``'s options set, by dotted name (validated later with the scene)."""
    changes = set_overrides(args.set)
    for key, value in (("water", args.water), ("survey.seed", args.seed), ("survey.fidelity", args.fidelity),
                       ("survey.max_pulses", args.max_pulses), ("survey.chunk_pulses", args.chunk_pulses)):
        if value is not None:
            changes[key] = value
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
    if args.copc:
        changes["output.copc"] = True
    if args.rosbag is not None:
        changes["output.rosbag.dir"] = args.rosbag
    return changes


def kernels_cached() -> bool:
    """Whether numba's caches hold compiled kernels of both packages for the installed sources (their digitiser and
    hit kernels); False on a fresh machine, and after the sources change (``muls/infra/runtime.py``)."""
    from pathlib import Path

    from muls.infra.runtime import kernel_cache_dir

    for package, pattern in (("muls", "digitiser._digitise*.nbi"), ("scanner_sim", "kernels.hit_block*.nbi")):
        module = sys.modules.get(package) or __import__(package)
        cache = kernel_cache_dir(package) or Path(module.__file__).parent / "__pycache__"
        if not any(cache.rglob(pattern)):
            return False
    return True


def _first_run_notice() -> bool:
    """Say so when the kernels are not cached yet: the pass compiles them first. True when it did."""
    if kernels_cached():
        return False
    print("first run: compiling the simulation kernels before the pass (measured 20 to 40 s of CPU on 2-core machines, "
          "minutes on a busy one; later runs load them from the cache in seconds)", file=sys.stderr, flush=True)
    return True


def _cmd_run(args) -> int:
    import contextlib
    from pathlib import Path

    from scanner_sim.config import load_scene
    from scanner_sim.io.run_dir import hold_output
    from scanner_sim.survey.pipeline import check_bag_dir, run_pass
    from scanner_sim.survey.setup import PassOptions

    config = load_scene(args.scene)
    config = config.with_overrides(scene_overrides(args, config))
    options = PassOptions(waveforms=args.waveforms, progress=not args.quiet, render=not args.no_render)
    out = Path(args.out or config.output_dir)
    bag = config.output.rosbag
    check_bag_dir(bag, out)  # before the bag's lock would create its parent folder
    with hold_output(out), (hold_output(bag.dir) if bag and bag.dir else contextlib.nullcontext()):
        # taken before the pass is built, so a second writer is refused at once
        compiling = _first_run_notice()
        summary = run_pass(config, out, options).summary
    if compiling:
        print(f"first run: the kernels compiled in {summary['compile_s']:.0f} s (summary.json's compile_s; its "
              "pulses_per_s leaves it out)", file=sys.stderr, flush=True)
    if not args.quiet:
        dropped = ", ".join(f"{k} {v:,}" for k, v in summary["dropouts"].items() if v) or "none"
        dropped += _no_seabed_note(summary)
        print(f"{summary['pulses']:,} pulses -> {summary['points']:,} points in {summary['wall_s']:.1f} s "
              f"({summary['pulses_per_s']:,.0f} pulses/s); dropouts: {dropped}")
        error = summary["range_error_m"]
        if error["median"] is None:
            print("range error: no point has a truth surface along its line of sight")
        else:
            print(f"range error |median| {100 * error['median']:.1f} cm, p95 {100 * error['p95']:.1f} cm; signed median "
                  f"{100 * error['median_signed']:+.1f} cm, {100 * error['share_short']:.0f} % of the points short")
        cov = summary.get("coverage")
        if cov and cov["covered_fraction"] is not None:
            gaps = ", ".join(f"{k} {v:.2f} m²" for k, v in cov["gaps_m2"].items() if v) or "none"
            print(f"coverage {100 * cov['covered_fraction']:.1f} % of {cov['reached_area_m2']:.0f} m² reached "
                  f"(cells of {cov['cell_m']:g} m); gaps: {gaps}")
    print(out / "summary.json")
    return 0


#: name -> the function that adds the subcommand's options to its parser and sets ``func``.
BUILDERS = {"scenes": _add_scenes, "validate": _add_validate, "schema": _add_schema, "run": _add_run}
