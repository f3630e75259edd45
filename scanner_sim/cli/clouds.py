"""Subcommands that look at a pass's point cloud: ``view`` and ``swath``."""

from __future__ import annotations

import json

from muls.infra.command import (
    nonempty,
    output_file,
    positive_float,
    positive_int,
)

# -- view ---------------------------------------------------------------------------------------------------
#: ``--color`` name (also the point cloud's colouring, ``color_by``) -> the PointRecords field it shows ("depth": -z).
_VIEW_FIELDS = {"class": "classification", "depth": "xyz", "intensity": "intensity", "channel": "channel",
                "range_error": "range_error_m", "tvu": "tvu_m", "snr": "snr"}


def _add_view(p):
    p.add_argument("path", metavar="RUN_DIR", type=nonempty(),
                   help="a run folder of scanner-sim run (its points.las...) or a LAS file, e.g. out/cable_survey")
    p.add_argument("--html", metavar="OUT.html", nargs="?", const=True, type=output_file(),
                   help="write one self-contained HTML page (WebGL, no network needed; default RUN_DIR/view.html)")
    p.add_argument("--serve", action="store_true",
                   help="serve a local interactive viewer at http://127.0.0.1:PORT until Ctrl-C (viser, the serve extra)")
    p.add_argument("--port", type=positive_int(), default=8080, help="--serve's port (default 8080)")
    p.add_argument("--color", choices=list(_VIEW_FIELDS),
                   help="point colouring (default: depth in the HTML page over a seabed, else class)")
    p.add_argument("--screenshot", metavar="PNG", type=output_file(),
                   help="render off-screen to this PNG instead of opening a window "
                   "(without a display the default is POINTS.<color>.png beside the LAS)")
    p.add_argument("--no-mesh", action="store_true", help="do not draw the scene.ply beside the LAS (or one directory up)")
    p.add_argument("--point-size", type=positive_float(), default=3.0, help="pixels (default 3; 2 in the HTML page)")
    p.add_argument("--max-points", type=positive_int(),
                   help="show at most this many points, one in every ceil(n / max) in file order (default 2,000,000; "
                        "500,000 in the HTML page)")
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
    from scanner_sim.render import point_cloud, point_colours

    path = Path(args.path)
    if not path.exists():
        raise ValueError(f"RUN_DIR = {str(path)!r}: no such file or folder; expected a run folder or a LAS file")
    if args.html is not None and args.serve:
        raise ValueError("--html and --serve: give one (a page to keep, or a local viewer)")
    if args.html is not None:
        return _write_html(args, path)
    if args.serve:
        from scanner_sim.render import serve_view, web_view

        files = web_view.PassFiles.of(path)
        if args.no_mesh:
            files = web_view.PassFiles(files.clouds, None, files.trajectory, files.dropouts, files.summary)
        serve_view.serve(files, port=args.port, max_points=args.max_points or serve_view.DEFAULT_MAX_POINTS,
                         color=args.color, announce=lambda line: print(line, flush=True))
        return 0
    point_cloud.check_window_size("--window-size", args.window_size)
    if path.is_dir():
        from scanner_sim.render.web_view import PassFiles

        path = PassFiles.of(path).clouds[0]
    las = path
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
    color = args.color or "class"
    values = -points.xyz[:, 2] if color == "depth" else getattr(points, _VIEW_FIELDS[color])
    colouring = ({"classification": values} if color == "class" else
                 {"color_by": color, "scalars": values})
    options = dict(title=f"{las}: {len(values):,} points coloured by {color}", point_size=args.point_size,
                   max_points=args.max_points or 2_000_000, window_size=tuple(args.window_size), **colouring, **mesh)
    png = args.screenshot
    if args.open3d:
        if not os.environ.get("DISPLAY"):
            raise ValueError("--open3d: opens a window, and there is no display (DISPLAY is unset); "
                             "use --screenshot PNG instead")
        point_cloud.show_open3d(points.xyz, point_colours.point_rgb(values, color), title=str(las),
                                **{k: v for k, v in mesh.items()})
        return 0
    if png is None and os.environ.get("DISPLAY"):
        point_cloud.show_point_cloud(points.xyz, **options)
        return 0
    png = Path(png) if png is not None else las.with_suffix(f".{color}.png")
    point_cloud.render_point_cloud(png, points.xyz, **options)
    print(png)
    return 0


def _write_html(args, path) -> int:
    """``view --html``: the pass's page, by default view.html in the run folder (beside a LAS file given)."""
    from pathlib import Path

    from scanner_sim.render import web_view

    files = web_view.PassFiles.of(path)
    if args.no_mesh:
        files = web_view.PassFiles(files.clouds, None, files.trajectory, files.dropouts, files.summary)
    out = Path(args.html) if args.html is not True else (path if path.is_dir() else path.parent) / "view.html"
    page = web_view.write_view_html(out, files, max_points=args.max_points or web_view.DEFAULT_MAX_POINTS,
                                    color=args.color, point_size_px=args.point_size if args.point_size != 3.0 else 2.0)
    print(f"{out}: {page['shown']:,} of {page['points']:,} points"
          + (f" (one in every {page['stride']})" if page["stride"] > 1 else "") + f", {page['bytes'] / 1e6:.1f} MB")
    return 0


# -- swath --------------------------------------------------------------------------------------------------
def _add_swath(p):
    p.add_argument("path", type=nonempty(), help="a pass folder (points.las/laz or leg*_points.*) or one LAS/LAZ file")
    p.add_argument("--overlap-m", type=positive_float(), default=0.5,
                   help="largest nearest-neighbour distance [m] of a point in the overlap")
    p.add_argument("--json", action="store_true", help="print the pairs as JSON")
    p.set_defaults(func=_cmd_swath)


def _cmd_swath(args) -> int:
    from pathlib import Path

    from scanner_sim.io import read_las
    from scanner_sim.metrics.swath import swath_consistency
    from scanner_sim.records.point_records import PointRecords

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


#: name -> the function that adds the subcommand's options to its parser and sets ``func``.
BUILDERS = {"view": _add_view, "swath": _add_swath}
