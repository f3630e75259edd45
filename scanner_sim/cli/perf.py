"""Subcommands that measure speed: ``bench``, ``bench-rays`` and ``bench-site``."""

from __future__ import annotations

import json

from muls.infra.command import (
    nonempty,
    positive_int,
)
from scanner_sim.fidelity import FIDELITY_LEVELS
from scanner_sim.rays.beams import SUBRAY_COUNTS


# -- bench --------------------------------------------------------------------------------------------------
def _add_bench(p):
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


# -- bench-rays ---------------------------------------------------------------------------------------------
def _add_bench_rays(p):
    p.add_argument("scene", nargs="?", default="cable_survey", type=nonempty(), help="shipped scene name or YAML path")
    p.add_argument("--pulses", type=positive_int(), default=20000, help="scan-ordered pulses in the chunk")
    p.add_argument("--subrays", type=positive_int(), choices=SUBRAY_COUNTS, default=19, metavar="N",
                   help=f"beam sub-rays, one of {', '.join(map(str, SUBRAY_COUNTS))}")
    p.add_argument("--repeat", type=positive_int(), default=3, help="best of this many timings")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_rays)


def _cmd_bench_rays(args) -> int:
    from muls.infra.memory import check_memory
    from scanner_sim.perf.raybench import bench_rays
    from scanner_sim.survey.sizing import CHUNK_BYTES_PER_SUBRAY

    per = args.subrays * CHUNK_BYTES_PER_SUBRAY  # one chunk of --pulses pulses, as a pass holds it (195 B measured)
    check_memory("--pulses", args.pulses, args.pulses * per, f"a chunk of {args.pulses:,} pulses x {args.subrays} sub-rays",
                 lambda budget: f"at most {int(budget // per):,} pulses on this machine")
    result = bench_rays(args.scene, args.pulses, args.subrays, args.repeat)
    if args.json:
        print(json.dumps(result))
    else:
        for k, v in result.items():
            print(f"{k:28s} {v}")
    return 0


# -- bench-site ---------------------------------------------------------------------------------------------
def _add_bench_site(p):
    p.add_argument("--fidelity", choices=list(FIDELITY_LEVELS), default="balanced", help="fidelity level of both passes")
    p.add_argument("--minutes", type=positive_int(), default=60, help="minutes of survey of the site's pass")
    p.add_argument("--seabed", choices=["raster", "procedural"], default="raster",
                   help="both scenes' seabed: a generated GeoTIFF (EPSG:32631, 1 m pixels) refined to 0.25 m (default), "
                        "or the procedural one")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_site)


def _cmd_bench_site(args) -> int:
    from scanner_sim.perf.sitebench import bench_site

    result = bench_site(args.fidelity, args.minutes, args.seabed)
    if args.json:
        print(json.dumps(result))
        return 0
    site, small = result["site"], result["small"]
    print(f"site  {site['triangles']:,} triangles: set-up {site['setup_s']:.1f} s, peak {site['peak_rss_mb']:,.0f} MB, "
          f"{site['pulses_per_s']:,.0f} pulses/s ({site['windows_built']} windows built)")
    print(f"small {small['triangles']:,} triangles: {small['pulses_per_s']:,.0f} pulses/s; site/small "
          f"{result['site_over_small_pulses_per_s']:.2f}")
    print("resident memory by minutes of survey: " + ", ".join(f"{m} min {mb:,.0f} MB"
                                                               for m, mb in result["rss_mb_by_minutes"].items()))
    print(result["subsampling"])
    return 0


#: name -> the function that adds the subcommand's options to its parser and sets ``func``.
BUILDERS = {"bench": _add_bench, "bench-rays": _add_bench_rays, "bench-site": _add_bench_site}
