"""Speed against accuracy (``scanner-sim tradeoff``): every fidelity level, and each single knob of ``balanced``,
run on the same pulses of the same seed, timed, and measured against the truth mesh and against the reference
level (:mod:`scanner_sim.studies.accuracy`).

Each run is the pass's own chunk loop (:func:`scanner_sim.survey.pipeline.pass_chunks`, with the nominal footprint and
coverage tally where the scene has a seabed) over ``pulses`` of the pass's pulses, in stretches spread evenly over it
(:func:`sampled_pass`); ``pulses_per_s`` times that loop
alone, after a short untimed warm-up, the fastest of ``repeat`` passes taken round-robin over the runs. The
waveform R^2 is measured on the sample's first ``waveform_pulses`` pulses, simulated again with their records kept (the
full reference records take 6 kB a pulse).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from scanner_sim import io
from scanner_sim.config import SceneConfig
from scanner_sim.fidelity import FIDELITY_LEVELS, FidelityLevel
from scanner_sim.io.run_dir import hold_output
from scanner_sim.records.point_records import PointRecords
from scanner_sim.studies import accuracy
from scanner_sim.studies.defaults import DEFAULT_PULSES, DEFAULT_REPEAT, DEFAULT_WAVEFORM_PULSES, KNOBS
from scanner_sim.survey import sinks
from scanner_sim.survey.georeference import NO_OBJECT
from scanner_sim.survey.pipeline import load_sink_kernels, pass_chunks, stream_pass
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.world.scene import build_scene

#: The level every other is measured against.
REFERENCE = "reference"
#: Sub-rays of the reference run again at a finer resolution to show the reference has converged (the densest
#: ring layout, beams.SUBRAY_COUNTS: 8 rings against the reference's 5).
CONVERGENCE_SUBRAYS = 217
WARM_UP_PULSES = 200
#: Bytes a run keeps per pulse until the metrics are taken (every run is kept): its points (77 bytes each, about
#: one a pulse), their hidden flags, its slot numbers and the copies made matching them. Measured: 237 bytes (peak
#: RSS of pool_panel's tradeoff between 400,000 and 2,000,000 pulses, 2 runs), rounded up for more returns a pulse.
KEPT_BYTES_PER_PULSE = 400
#: Bytes of a pulse's whole records, kept by each run for the waveforms' R^2: 8.2 kB at the reference level
#: (cable_survey), rounded up with the working memory of the simulate call that makes them.
RECORD_BYTES_PER_PULSE = 12_000


@dataclass(frozen=True)
class LevelRun:
    """One level's run: its speed [pulses/s] (the fastest of its timed passes and their median), points, the coverage
    it reached (covered share of the reached seabed cells, or without a seabed the share of pulses with a point an
    echo explains), which points lie on a surface the receiver cannot see, the waveform records of the first pulses,
    and for an adaptive level what it decided (:func:`level_decisions`)."""

    level: FidelityLevel
    pulses_per_s: float
    median_pulses_per_s: float
    n_pulses: int
    points: PointRecords
    coverage: float | None
    hidden: np.ndarray
    records: object
    decisions: dict | None = None


def knob_level(name: str) -> FidelityLevel:
    """``balanced`` with the one change of knob ``name`` (:data:`KNOBS`)."""
    key, value = KNOBS[name]
    return replace(FIDELITY_LEVELS["balanced"], name=name, **{key: value})


#: [m] Occluders this close to a point's truth surface do not hide it: the point is placed on the surface along its
#: estimated line of sight, which navigation noise (5 cm sigma in the shipped scenes) moves over the relief.
HIDDEN_MARGIN_M = 0.1

#: [m] A point's truth this close to the first surface along its line was taken from that surface
#: (survey.georeference): two float32 casts of one line differ by micrometres.
ON_FIRST_SURFACE_M = 1e-3


def hidden_from_receiver(setup: PassSetup, points: PointRecords) -> np.ndarray:
    """(n,) bool: the surface a point ranged has something more than :data:`HIDDEN_MARGIN_M` from it and in front
    of the receiver aperture at the pulse's true pose.

    The surface point is where the truth puts it, ``true_range_m`` along the point's estimated line of sight. Only
    points whose truth is the first surface along that line (within :data:`ON_FIRST_SURFACE_M`) are judged: a return
    off that surface (behind an edge, on the other level of a step) has its truth on the plane of the facet it
    ranged, extended past the surface the line meets, where visibility means nothing. Noise points are never
    hidden."""
    known = np.isfinite(points.true_range_m) & (points.object_id >= 0)
    out = np.zeros(len(points), bool)
    if not known.any():
        return out
    times = points.gps_time_s[known]
    truth = setup.trajectory.poses(times)
    origin, direction = setup.scanner.beam_rays(setup.trajectory.estimate_of(truth))
    _, _, _, rx_origin, _ = setup.scanner.world_rays(truth)
    local = origin - setup.scene.local_origin
    ray, _, dist = setup.target.caster.first_hits(local.astype(np.float32), direction.astype(np.float32))
    first_range = np.full(times.size, np.nan)
    first_range[ray] = dist
    judged = np.abs(first_range - points.true_range_m[known]) <= ON_FIRST_SURFACE_M
    surface = origin + points.true_range_m[known, None].astype(np.float64) * direction
    to_rx = rx_origin - surface
    length = np.linalg.norm(to_rx, axis=1)
    to_rx /= length[:, None]
    start = surface + HIDDEN_MARGIN_M * to_rx - setup.scene.local_origin
    blocked = setup.target.caster.occluded(start.astype(np.float32), to_rx.astype(np.float32),
                                    (length - HIDDEN_MARGIN_M).astype(np.float32))
    out[known] = blocked & judged
    return out


def _timed_pass(setup: PassSetup):
    """The pass's chunks as a pass runs them (:func:`scanner_sim.survey.pipeline.pass_chunks`, one per core at once)
    into memory, with the coverage tally where the pass measures it: (points, covered share or None, wall seconds
    of the loop)."""
    points = sinks.MemorySink()
    _, coverage, wall_s = stream_pass(setup, pass_chunks(setup, PassOptions(progress=False)), [points],
                                      PassOptions(progress=False))
    return points.points(), None if coverage is None else coverage.figures()["covered_fraction"], wall_s


def run_level(base: PassSetup, level: FidelityLevel, waveform_pulses: int) -> LevelRun:
    """The pulses of pass ``base`` (its ``max_pulses``) at ``level``, timed once, with their metrics' inputs."""
    setup = base.at_level(level)
    slots = list(setup.slot_chunks())
    setup.simulate_chunk(slots[0][:WARM_UP_PULSES])  # compiled kernels and caches warm
    load_sink_kernels(setup)
    points, covered, wall_s = _timed_pass(setup)
    n = int(sum(s.size for s in slots))
    if covered is None:
        covered = np.unique(points.pulse_index[points.object_id >= 0]).size / max(n, 1)
    first = np.concatenate(slots)[:waveform_pulses]
    records = setup.simulate_chunk(first, whole_records=True).waveforms  # every sample, for the waveforms' R^2
    return LevelRun(level, n / wall_s, n / wall_s, n, points, covered, hidden_from_receiver(setup, points), records,
                    level_decisions(setup, slots, records))


def level_decisions(setup: PassSetup, slots: list, records) -> dict | None:
    """What an adaptive level (``auto``) decided on the pulses of ``slots`` (arrays of slots), after its timed
    passes, as shares of the pulses: sub-ray hits found on the height field, no shadow ray cast (``proven``); axis
    met the height field first (``axis_on_seabed``: the others are cast as ``balanced`` casts them); proven to
    meet nothing, no sub-ray but the axis cast (``proven_missed``); echoes
    collapsed to two (``simple``); no sub-ray met anything (``no_hit``). Then the channels digitised per record
    window of ``records`` (``channels_per_window`` of ``channels``) and ``falls_back``: why no pulse is proven
    where that is so. None for a level that decides nothing, or whose ray stage cannot say (a site's windows)."""
    decide = getattr(setup.rays, "decisions", None)
    if not setup.level.adaptive or decide is None:
        return None
    counts = {"pulses": 0, "proven": 0, "proven_missed": 0, "axis_on_seabed": 0, "simple": 0, "no_hit": 0}
    reason = None
    for chunk in slots:
        poses = setup.trajectory.poses(chunk / setup.scanner.pulse_rate_hz)
        found = decide(*setup.scanner.world_rays(poses))
        reason = found["no_grid"]
        for key in counts:
            counts[key] += found[key]
    n = max(counts["pulses"], 1)
    kept = records.synthesised
    return {"proven": counts["proven"] / n, "proven_missed": counts["proven_missed"] / n,
            "axis_on_seabed": counts["axis_on_seabed"] / n,
            "simple": counts["simple"] / n, "no_hit": counts["no_hit"] / n,
            "channels_per_window": None if kept is None or kept.size == 0 else float(kept.sum(axis=1).mean()),
            "channels": int(records.codes.shape[1]), "falls_back": reason}


def best_speed(base: PassSetup, runs: dict, repeat: int) -> dict:
    """``runs`` with each one's ``pulses_per_s`` the best of ``repeat`` timed passes and ``median_pulses_per_s``
    their median (how far a disturbed pass falls): the first (in ``runs``) and ``repeat - 1`` more, taken
    round-robin over the runs so that a machine's drift meets them all alike. The passes give the same points (a
    seed fixes them); only their time is kept."""
    rates = {name: [run.pulses_per_s] for name, run in runs.items()}
    for _ in range(repeat - 1):
        for name, run in runs.items():
            setup = base.at_level(run.level)
            _, _, wall_s = _timed_pass(setup)
            rates[name].append(run.n_pulses / wall_s)
    return {name: replace(run, pulses_per_s=max(rates[name]), median_pulses_per_s=float(np.median(rates[name])))
            for name, run in runs.items()}


def _rounded(metrics: dict) -> dict:
    return {k: (None if v is None else round(float(v), 6)) for k, v in metrics.items()}


def range_bias(points: PointRecords) -> float | None:
    """[m] Median of measured minus true range of the returns an echo explains (signed: positive is long), None
    without any: the bias :func:`scanner_sim.studies.accuracy.vs_truth`'s absolute errors leave out."""
    error = points.range_error_m[points.object_id != NO_OBJECT].astype(np.float64)
    error = error[np.isfinite(error)]
    return float(np.median(error)) if error.size else None


def level_metrics(run: LevelRun, reference: LevelRun) -> dict:
    """The JSON entry of one run: its settings, speed, and metrics against the truth and the reference."""
    fit = accuracy.WaveformFit.of(run.records, reference.records)
    vs_ref = accuracy.vs_reference(run.points, reference.points, run.n_pulses)
    vs_ref["coverage_diff"] = accuracy.coverage_difference(run.coverage, reference.coverage)
    vs_ref["waveform_r2"] = fit.r2
    lv = run.level
    entry = {"pulses_per_s": round(run.pulses_per_s, 1), "median_pulses_per_s": round(run.median_pulses_per_s, 1),
             "subrays": lv.subrays, "shadow_rays": lv.shadow_rays,
             "record_mode": lv.record_mode, "column_cut": lv.column_cut, "multiple_scattering": lv.multiple_scattering,
             "coverage": run.coverage,
             "vs_truth": _rounded({**accuracy.vs_truth(run.points, run.n_pulses, run.hidden),
                                   "median_range_bias_m": range_bias(run.points)}),
             "vs_reference": _rounded(vs_ref)}
    if run.decisions is not None:
        entry["decisions"] = {k: round(v, 4) if isinstance(v, float) else v for k, v in run.decisions.items()}
    return entry


def run_plan(levels, knobs, convergence: bool) -> list[tuple[str, FidelityLevel]]:
    """The runs of a tradeoff, in order: the reference, the other ``levels``, each knob, and with ``convergence``
    the reference at :data:`CONVERGENCE_SUBRAYS` sub-rays."""
    plan = [(name, FIDELITY_LEVELS[name]) for name in dict.fromkeys([REFERENCE, *levels])]
    plan += [(name, knob_level(name)) for name in knobs]
    if convergence:
        finer = f"reference, {CONVERGENCE_SUBRAYS} sub-rays"
        plan.append((finer, replace(FIDELITY_LEVELS[REFERENCE], name=finer, subrays=CONVERGENCE_SUBRAYS)))
    return plan


def check_tradeoff_memory(config: SceneConfig, levels, knobs, pulses: int, waveform_pulses: int, convergence: bool,
                          keys=("pulses", "waveform_pulses"), available_bytes: int | None = None) -> None:
    """Refuse, before any run, ``pulses`` or ``waveform_pulses`` (named by ``keys``, the larger share's) when the
    runs would keep more than a command may plan on (:func:`muls.infra.memory.check_memory`): each run keeps
    :data:`KEPT_BYTES_PER_PULSE` a pulse the pass fires and :data:`RECORD_BYTES_PER_PULSE` a waveform pulse."""
    from muls.infra.memory import check_memory
    from scanner_sim.survey.sizing import estimate_pass

    runs = len(run_plan(levels, knobs, convergence))
    fired = estimate_pass(config.with_overrides({"survey.max_pulses": pulses})).pulses
    records = min(waveform_pulses, fired)
    points_b, records_b = runs * fired * KEPT_BYTES_PER_PULSE, runs * records * RECORD_BYTES_PER_PULSE
    key, value, per, rest, unit = ((keys[0], pulses, runs * KEPT_BYTES_PER_PULSE, records_b, "pulses")
                                   if points_b >= records_b else
                                   (keys[1], waveform_pulses, runs * RECORD_BYTES_PER_PULSE, points_b, "waveform pulses"))
    check_memory(key, value, points_b + records_b, f"{runs} runs keeping the points of {fired:,} pulses and the records "
                 f"of {records:,}", lambda budget: f"at most {max(0, int((budget - rest) // per)):,} {unit} on this "
                 "machine", available_bytes)


def sampled_pass(config: SceneConfig, pulses: int) -> PassSetup:
    """The pass of ``config`` cut to ``pulses`` of its pulses, in stretches of consecutive pulses spread evenly over it,
    one a chunk's worth (``survey.chunk_pulses``), each about the middle of its share of the pass
    (:meth:`~scanner_sim.survey.setup.PassSetup.spread_sample`): the timed passes run the chunks a pass runs, over
    ground like the whole survey's rather than its start's; the whole pass when it fires no more."""
    whole = PassSetup.build(config, PassOptions(), build_scene(config))
    return whole.spread_sample(pulses, max(1, round(pulses / config.survey.chunk_pulses)))


def tradeoff(config: SceneConfig, levels=tuple(FIDELITY_LEVELS), knobs=tuple(KNOBS), pulses: int = DEFAULT_PULSES,
             waveform_pulses: int = DEFAULT_WAVEFORM_PULSES, progress=None, convergence: bool = True,
             repeat: int = DEFAULT_REPEAT) -> dict:
    """Every level of ``levels`` and knob of ``knobs`` on ``pulses`` of the pass's pulses (:func:`sampled_pass`), against the
    reference level run on the same pulses and seed. Returns the JSON-ready result (:func:`write_tradeoff`).
    ``convergence``: also run the reference at :data:`CONVERGENCE_SUBRAYS` sub-rays and compare it with the
    reference (``reference_convergence``). ``progress``: called with each run's name as it starts. ``repeat``:
    timed passes per run, the fastest kept (:func:`best_speed`)."""
    base = sampled_pass(config, pulses)
    plan = run_plan(levels, knobs, convergence)
    finer = f"reference, {CONVERGENCE_SUBRAYS} sub-rays"
    runs = {}
    for name, level in plan:
        if progress:
            progress(name)
        runs[name] = run_level(base, level, waveform_pulses)
    if progress and repeat > 1:
        progress(f"{repeat - 1} more timed passes of each")
    runs = best_speed(base, runs, repeat)
    reference = runs[REFERENCE]
    started = time.time()
    result = {"scene": config.name, "seed": config.survey.seed, "pulses": reference.n_pulses,
              "stretches": [list(stretch) for stretch in base.stretches], "timed_passes": repeat,
              "waveform_pulses": min(waveform_pulses, reference.n_pulses), "reference": REFERENCE,
              "match_tolerance_m": accuracy.MATCH_TOLERANCE_M,
              "levels": {n: level_metrics(runs[n], reference) for n in levels},
              "knobs": {n: level_metrics(runs[n], reference) for n in knobs}}
    if convergence:
        result["reference_convergence"] = level_metrics(runs[finer], reference)
    result["metrics_s"] = round(time.time() - started, 1)
    return result


#: Columns of the table: (title, section, key, format).
TABLE = [("pulses/s", None, "pulses_per_s", "{:,.0f}"),
         ("median abs err [m]", "vs_truth", "median_abs_range_error_m", "{:.4f}"),
         ("p95 abs err [m]", "vs_truth", "p95_abs_range_error_m", "{:.3f}"),
         ("range bias [m]", "vs_truth", "median_range_bias_m", "{:+.4f}"),
         ("false alarms /pulse", "vs_truth", "false_alarms_per_pulse", "{:.4f}"),
         ("hidden pts /pulse", "vs_truth", "hidden_points_per_pulse", "{:.4f}"),
         ("missing /pulse", "vs_reference", "missing_per_pulse", "{:.4f}"),
         ("extra /pulse", "vs_reference", "extra_per_pulse", "{:.4f}"),
         ("p95 pos diff [m]", "vs_reference", "p95_position_diff_m", "{:.4f}"),
         ("class agree", "vs_reference", "class_agreement", "{:.4f}"),
         ("coverage diff", "vs_reference", "coverage_diff", "{:+.4f}"),
         ("waveform R²", "vs_reference", "waveform_r2", "{:.5f}")]


def _cell(entry: dict, section, key, fmt) -> str:
    value = entry[key] if section is None else entry[section][key]
    return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) else fmt.format(value)


def markdown_table(result: dict) -> str:
    """The levels and knobs, one row each, in a Markdown table."""
    head = "| run | " + " | ".join(t for t, *_ in TABLE) + " |"
    rows = [head, "|" + "---|" * (len(TABLE) + 1)]
    for group in ("levels", "knobs"):
        for name, entry in result[group].items():
            rows.append(f"| {name} | " + " | ".join(_cell(entry, *spec[1:]) for spec in TABLE) + " |")
    notes = [decisions_note(name, entry["decisions"]) for group in ("levels", "knobs")
             for name, entry in result[group].items() if entry.get("decisions")]
    return "\n".join(rows) + "\n" + "".join(f"\n{note}\n" for note in notes)


def decisions_note(name: str, d: dict) -> str:
    """One paragraph: what the adaptive level ``name`` decided (:func:`level_decisions`'s ``d``), and where it
    falls back to ``balanced``'s way, why."""
    missed = d["proven_missed"]
    cast = 1.0 - d["proven"] - missed
    text = (f"`{name}` decided: sub-ray hits found on the height field, no shadow ray cast, for {d['proven']:.1%} of "
            f"pulses; ")
    if missed > 0:
        text += f"proven to meet nothing, no sub-ray but the axis cast, for {missed:.1%}; "
    if d["falls_back"]:
        text += f"the rest cast by Embree as `balanced` casts them, because {d['falls_back']}; "
    elif cast > 0:
        text += (f"the rest ({cast:.1%}) cast by Embree as `balanced` casts them: "
                 f"{1.0 - d['axis_on_seabed'] - missed:.1%} whose axis met an object or nothing first (and not proven "
                 f"clear), {d['axis_on_seabed'] - d['proven']:.1%} where "
                 "something might stand in a sub-ray's or the receiver's way or the seabed rises more steeply than "
                 "a ray; ")
    text += (f"echoes collapsed to two for {d['simple']:.1%}, one echo per sub-ray kept for "
             f"{1.0 - d['simple'] - d['no_hit']:.1%} (a footprint over an edge or two surfaces, or spread over more "
             f"range than the collapse allows), and {d['no_hit']:.1%} met nothing")
    if d["channels_per_window"] is not None:
        text += f"; {d['channels_per_window']:.2f} of {d['channels']} channels digitised per record window"
    return text + "."


#: Columns of docs/fidelity.md's failure-scene table after the scene and the level: (section, key, format).
FAILURE_ROW = [(None, "pulses_per_s", "{:,.0f}"), ("vs_truth", "points_per_pulse", "{:.3f}"),
               ("vs_truth", "median_abs_range_error_m", "{:.3f}"), ("vs_truth", "p95_abs_range_error_m", "{:.3f}"),
               ("vs_truth", "false_alarms_per_pulse", "{:.4f}"), ("vs_truth", "hidden_points_per_pulse", "{:.4f}"),
               ("vs_reference", "missing_per_pulse", "{:.4f}"), ("vs_reference", "extra_per_pulse", "{:.4f}"),
               ("vs_reference", "p95_position_diff_m", "{:.4f}"), ("vs_reference", "class_agreement", "{:.4f}"),
               ("vs_reference", "coverage_diff", "{:+.4f}"), ("vs_reference", "waveform_r2", "{:.5f}")]


def failure_table_rows(result: dict) -> str:
    """The rows of docs/fidelity.md's failure-scene table: one per level, then the reference at the convergence
    sub-rays when the result has it. The reference's own row leaves its comparisons with itself out (a dash);
    ``auto``'s speed carries its ratio to ``balanced``'s in the same run."""
    entries = list(result["levels"].items())
    converged = result.get("reference_convergence")
    if converged:
        entries.append((f"reference at {converged['subrays']}", converged))
    balanced = result["levels"].get("balanced")
    rows = []
    for name, entry in entries:
        cells = ["–" if name == REFERENCE and section == "vs_reference" else _cell(entry, section, key, fmt)
                 for section, key, fmt in FAILURE_ROW]
        if name == "auto" and balanced:
            cells[0] += f" (×{entry['pulses_per_s'] / balanced['pulses_per_s']:.2f})"
        rows.append(f"| {result['scene']} | {name} | " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


def write_tradeoff(result: dict, out_dir: str | Path, render: bool = True) -> Path:
    """tradeoff.json, tradeoff.md and (``render``) tradeoff.png in ``out_dir``, each written atomically; returns
    the path of tradeoff.json. The folder is locked while they are written: a second writer is refused
    (:func:`~scanner_sim.io.run_dir.hold_output`)."""
    out = Path(out_dir)
    with hold_output(out):
        return _write_tradeoff(result, out, render)


def _write_tradeoff(result: dict, out: Path, render: bool) -> Path:
    from scanner_sim.render.tradeoff_chart import plot_tradeoff

    out.mkdir(parents=True, exist_ok=True)
    if render:
        plot_tradeoff(out / "tradeoff.png", result)
    stretches = result.get("stretches") or []
    slots = ", ".join(f"{first:,}-{end - 1:,}" for first, end in stretches)
    sample = (", the whole pass" if not stretches else f" about the middle of the pass (pulse slots {slots})"
              if len(stretches) == 1 else f" in {len(stretches)} stretches spread over the pass (pulse slots {slots})")
    intro = (f"# Speed against accuracy: {result['scene']}\n\n{result['pulses']:,} pulses per run (seed "
             f"{result['seed']}){sample}, waveforms over the first {result['waveform_pulses']:,}; against the truth mesh "
             f"and against the `{result['reference']}` level on the same pulses. pulses/s: the fastest of "
             f"{result['timed_passes']} timed passes of each run (`median_pulses_per_s` in tradeoff.json: their median, "
             f"how far a pass the machine disturbed falls).\n\n")
    converged = result.get("reference_convergence")
    if converged:
        ref = converged["vs_reference"]
        intro += (f"Reference converged: at {converged['subrays']} sub-rays its returns differ from the reference's by "
                  f"{_cell(converged, 'vs_reference', 'p95_position_diff_m', '{:.4f}')} m (95th percentile), "
                  f"{ref['missing_per_pulse']:.4f} missing and {ref['extra_per_pulse']:.4f} extra per pulse.\n\n")
    io.write_text(out / "tradeoff.md", intro + markdown_table(result) + ("\n![chart](tradeoff.png)\n" if render else ""))
    io.write_summary_json(out / "tradeoff.json", result)
    return out / "tradeoff.json"
