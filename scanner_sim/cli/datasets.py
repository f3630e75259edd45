"""Subcommand that writes a labelled dataset: ``dataset``."""

from __future__ import annotations

import json

from muls.infra.command import nonempty, output_dir
from scanner_sim.cli.studies import _add_dask_arguments, _workers


def _add_dataset(p):
    p.add_argument("spec", metavar="SPEC.yaml", type=nonempty(), help="dataset spec (e.g. scenes/datasets/example.yaml)")
    p.add_argument("--out", type=output_dir(), help="output directory (default: out/datasets/NAME); a folder holding "
                   "the same spec is resumed")
    p.add_argument("--json", action="store_true", help="print {scenes, points, classes, splits} as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress; print only the path of manifest.json")
    _add_dask_arguments(p)
    p.set_defaults(func=_cmd_dataset)


def _cmd_dataset(args) -> int:
    from pathlib import Path

    from scanner_sim.io.run_dir import hold_output
    from scanner_sim.runs.cluster import maybe_client
    from scanner_sim.runs.dataset import MANIFEST, load_dataset, run_dataset, summary_line

    dataset = load_dataset(args.spec)
    out = Path(args.out or Path("out") / "datasets" / dataset.name)
    quiet = args.quiet or args.json
    # the folder's lock before the cluster starts, so a second writer is refused at once
    with hold_output(out), maybe_client(scheduler=args.scheduler, workers=_workers(args), announce=not quiet,
                                        passes=dataset.spec.scenes) as client:
        result = run_dataset(dataset, out, client, redo=args.redo, progress=not quiet)
    if "failed" in result:
        first = result["failed"][0]
        print(f"{len(result['failed'])} of {len(dataset.scenes)} scenes failed, no manifest written (run again to "
              f"redo them); first: {first['scene']}: {first['error']}")
        return 1
    if args.json:
        print(json.dumps(summary_line(result)))
        return 0
    if not quiet:
        splits = ", ".join(f"{name} {len(dirs)}" for name, dirs in result["splits"].items())
        classes = ", ".join(f"{name} {count:,}" for name, count in result["classes"].items())
        count = result["scene_count"]
        print(f"{count} scene{'s' * (count != 1)}, {result['points']:,} points ({classes}); splits: {splits}")
    print(out / MANIFEST)
    return 0


#: name -> the function that adds the subcommand's options to its parser and sets ``func``.
BUILDERS = {"dataset": _add_dataset}
