"""The registry of ``scanner-sim``'s subcommands: for each, its module under :mod:`scanner_sim.cli` (whose
``BUILDERS`` adds its options and sets ``func``) and its one-line help. The module is imported only when its
subcommand is parsed, so that ``scanner-sim --help`` imports no pipeline, kernel or ray tracer; adding a
subcommand is a line here and a builder there."""

from __future__ import annotations

#: name -> (module under scanner_sim.cli, one-line help), in the order ``scanner-sim --help`` lists them: the
#: main job first.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "run": ("passes", "simulate a survey pass: points.las, dropouts, summary, trajectory, render"),
    "scenes": ("passes", "list the shipped scenes, one line each"),
    "validate": ("passes", "check a scene file (shipped name or path); exit 2 when it is wrong"),
    "schema": ("passes", "print the JSON Schema of scene files (editors validate and complete with it)"),
    "view": ("clouds", "look at a pass's points over its scene.ply: an HTML page to turn in a browser "
                   "(--html), a window, or a PNG without a display"),
    "swath": ("clouds", "swath-to-swath consistency of overlapping survey lines (open3d extra)"),
    "coverage": ("studies", "mapping coverage per water type x altitude x instrument, with its report"),
    "features": ("features", "feature detection: cubes placed across the swath, the share detected per size"),
    "campaign": ("studies", "one pass per combination of the swept scene keys, on Dask "
                   "(docs/campaigns.md)"),
    "plan": ("studies", "the cheapest survey plan (altitude, speed, line spacing) meeting an IHO S-44 "
                   "order at the scene's site, per water type (docs/planning.md)"),
    "dataset": ("datasets", "N labelled scenes drawn from a spec, run on Dask: point clouds, manifest, "
                   "splits (docs/datasets.md)"),
    "tradeoff": ("studies", "speed against accuracy: each fidelity level and knob on the same pulses, "
                   "against the truth and the reference level (chart, table, JSON)"),
    "overlap": ("studies", "ray-cast overlap on a perpendicular plate vs MULS Eq. 11"),
    "bench": ("perf", "end-to-end pulses/s per fidelity beside raw embreex on the same rays, with "
                   "cores used and peak memory, and a two-million-triangle seabed"),
    "bench-rays": ("perf", "ray throughput: the pipeline's ray stage vs raw embreex, same rays"),
    "bench-site": ("perf", "a site-scale pass (1 km x 200 m at 0.25 m, 6.4 M triangles, tiled) beside "
                   "a small scene's: set-up, peak memory, pulses/s, memory after 10 and 60 minutes of survey"),
    "uncertainty": ("uncertainty", "simulate a pass in memory and check each point's THU and TVU (95 %%) "
                   "against its true error: shares within, per channel and incidence band"),
}
