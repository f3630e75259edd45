"""The ``features`` subcommand: cubes of the S-44 feature sizes placed across the swath, one pass, the share of
each size detected (:mod:`scanner_sim.studies.features`)."""

from __future__ import annotations

import json

from muls.infra.command import nonempty, output_dir, positive_float, positive_int, seed
from scanner_sim.fidelity import FIDELITY_LEVELS


def _add_features(p):
    from scanner_sim.metrics.coverage import CoverageSettings
    from scanner_sim.metrics.feature_cubes import DEFAULT_COUNT, DEFAULT_SIZES_M

    p.add_argument("scene", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--cubes-m", nargs="+", type=positive_float("cubes_m"), default=list(DEFAULT_SIZES_M), metavar="M",
                   help="cube edge sizes [m] (default: %(default)s, S-44's Exclusive, Special and 1a features)")
    p.add_argument("--count", type=positive_int("count"), default=DEFAULT_COUNT,
                   help="cubes of each size (default: %(default)s)")
    p.add_argument("--seed", type=seed(), default=0, help="seed of the cube positions (default: %(default)s)")
    p.add_argument("--water", type=nonempty(), help="water preset (default: the scene's)")
    p.add_argument("--scene-objects", action="store_true", help="place no cubes: count the scene's own objects")
    p.add_argument("--max-pulses", type=positive_int(), help="stop the pass after this many pulses (cubes are placed "
                   "along the stretch it flies)")
    p.add_argument("--fidelity", choices=list(FIDELITY_LEVELS), help="fidelity level (default: the scene's)")
    p.add_argument("--tolerance-m", type=positive_float("tolerance_m"), default=CoverageSettings.tolerance_m,
                   help="largest |range error| of a valid sounding [m] (default: %(default)s)")
    p.add_argument("--out", type=output_dir(), help="output directory (default: the scene's output.dir + /features)")
    p.add_argument("--no-render", action="store_true", help="features.json only, no features.png")
    p.add_argument("--json", action="store_true", help="print features.json's content instead of a table")
    p.set_defaults(func=_cmd_features)


def _cmd_features(args) -> int:
    from pathlib import Path

    from scanner_sim.config import load_scene
    from scanner_sim.io.run_dir import hold_output
    from scanner_sim.metrics.coverage import CoverageSettings
    from scanner_sim.studies.features import run_features

    config = load_scene(args.scene)
    out = Path(args.out or Path(config.output_dir) / "features")
    with hold_output(out):
        result = run_features(config, out, args.cubes_m, args.count, args.seed, args.water, args.scene_objects,
                              args.max_pulses, args.fidelity, CoverageSettings(tolerance_m=args.tolerance_m),
                              render=not args.no_render)
    if args.json:
        print(json.dumps({k: result[k] for k in ("scene", "water", "altitude_m", "seed", "cubes", "rule", "objects")},
                         indent=1))
        return 0
    print(f"{result['scene']} in {result['water']} at {result['altitude_m']} m; rule: {result['rule']['text']}")
    for size, c in result["cubes"].items():
        print(f"  {size} m cubes: {c['detected']}/{c['placed']} detected ({100 * c['fraction']:.0f} %), valid "
              f"soundings {c['valid_soundings']}")
    for o in result["objects"] if not result["cubes"] else []:
        print(f"  {o['name']}: {o['valid_points']} valid soundings, {'detected' if o['detected'] else 'missed'}")
    print(out / "features.json")
    return 0


#: name -> the function that adds the subcommand's options to its parser and sets ``func``.
BUILDERS = {"features": _add_features}
