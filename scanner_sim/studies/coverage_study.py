"""The coverage study (docs/coverage.md): one survey pass per water type x altitude x instrument
over the same scene, measured against the truth meshes, with its table, charts, maps and report.

Decisions a planner would make (written down in docs/coverage.md):

- The scene is built once; only the water, the vehicle's altitude and the instrument change.
- ``gate="follow"`` (default): when the altitude changes, the far channel's gate moves with the nadir echo,
  keeping the scene's lead (gate delay minus nadir echo time), as an operator sets the gate for each
  altitude; ``"fixed"`` keeps the scene's gate delay. The gate width stays the scene's.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

from muls.infra.errors import ParameterError
from muls.presets import instrument_preset, water_preset
from scanner_sim.config import SceneConfig
from scanner_sim.io.run_dir import hold_output
from scanner_sim.metrics import s44
from scanner_sim.metrics.coverage import CoverageSettings
from scanner_sim.runs.cluster import maybe_client
from scanner_sim.runs.jobs import run_jobs
from scanner_sim.runs.tasks import PassJob
from scanner_sim.studies.defaults import DEFAULT_INSTRUMENTS, DEFAULT_WATERS, GATE_MODES, INSTRUMENTS
from scanner_sim.survey.setup import PassOptions
from scanner_sim.survey.setup_cache import cached_scene

#: The name that asks for the scene's own water (a preset, or a water given by its properties).
SCENE_WATER = "scene"
#: Picture size of each combination's point-cloud render in the study (the report embeds them all).
STUDY_RENDER_SIZE = (960, 600)


@dataclass(frozen=True)
class CubePlan:
    """Cubes for feature detection: edge sizes [m], how many of each, the seed of their positions."""

    sizes_m: tuple[float, ...]
    count: int
    seed: int


@dataclass(frozen=True)
class StudyPlan:
    """The combinations: every water x altitude [m] (None: the scene's) x instrument preset."""

    waters: tuple[str, ...] = DEFAULT_WATERS
    altitudes_m: tuple[float | None, ...] = (None,)
    instruments: tuple[str, ...] = DEFAULT_INSTRUMENTS
    gate: str = "follow"
    #: Fly each combination also with the phase functions of the weakest and strongest echo
    #: (:mod:`scanner_sim.studies.water_uncertainty`): its covered and Order 1a shares as (low, default, high).
    water_uncertainty: bool = False

    def __post_init__(self):
        for name, values in (("waters", self.waters), ("altitudes_m", self.altitudes_m),
                             ("instruments", self.instruments)):
            if not values:
                raise ParameterError(f"{name} = (): give at least one")
            if len(set(values)) != len(values):
                raise ParameterError(f"{name} = {list(values)}: repeated value")
        for w in self.waters:
            if w != SCENE_WATER:
                water_preset(w)
        for a in self.altitudes_m:
            if a is not None and not (isinstance(a, (int, float)) and math.isfinite(a) and a > 0):
                raise ParameterError(f"altitudes_m: {a!r} is not allowed; each must be a finite number > 0 [m]")
        for i in self.instruments:
            if i not in INSTRUMENTS:
                raise ParameterError(f"instruments: {i!r} is not allowed; must be one of {', '.join(INSTRUMENTS)}")
        if self.gate not in GATE_MODES:
            raise ParameterError(f"gate = {self.gate!r}: must be one of {', '.join(GATE_MODES)}")

    def combinations(self, config: SceneConfig):
        """(water, altitude_m, instrument) in table order: water, then instrument, then altitude."""
        for water in self.waters:
            for instrument in self.instruments:
                for altitude in self.altitudes_m:
                    yield water, altitude if altitude is not None else config.platform.altitude_m, instrument


def combination_config(config: SceneConfig, water: str, altitude_m: float | None, instrument: str,
                       gate: str = "follow") -> SceneConfig:
    """The scene's config flown at ``altitude_m`` with the ``instrument`` preset (gate per ``gate``)."""
    base_altitude = config.platform.altitude_m
    if altitude_m is not None and base_altitude is None:
        raise ParameterError(f"altitudes_m: scene '{config.name}' flies at constant depth or stands still "
                             "(platform.altitude_m is not set), so its altitude cannot be varied")
    changes: dict = {"instrument.preset": instrument}
    if water != SCENE_WATER:
        changes["water"] = water
    water_model = config.with_overrides(changes).water_model()
    gated = [ch for ch in instrument_preset(instrument, water_model).channels if ch.gated]
    own = config.instrument
    if gated and gate == "follow" and altitude_m is not None and own.gate_delay_ns is not None:
        shift_ns = 2.0 * (altitude_m - base_altitude) / water_model.speed_m_s * 1e9
        changes |= {"instrument.gate_delay_ns": max(0.0, own.gate_delay_ns + shift_ns),
                    "instrument.gate_width_ns": own.gate_width_ns}
    elif not gated:
        changes |= {"instrument.gate_delay_ns": None, "instrument.gate_width_ns": None}
    if altitude_m is not None:
        changes["platform.altitude_m"] = float(altitude_m)
    return config.with_overrides(changes)


def combination_name(water: str, altitude_m: float | None, instrument: str) -> str:
    """Directory name of one combination, e.g. ``turbid_harbor-mul2023-8m``."""
    return f"{water}-{instrument}" + (f"-{altitude_m:g}m" if altitude_m is not None else "")


def run_study(config: SceneConfig, plan: StudyPlan, out_dir: str | Path, *,
              settings: CoverageSettings = CoverageSettings(), fidelity: str | None = None, seed: int | None = None,
              max_pulses: int | None = None, render: bool = True, progress: bool = True, client=None,
              workers: int | None = None, scheduler: str | None = None, redo: bool = False,
              cubes: CubePlan | None = None, view_pass: str | None = None) -> dict:
    """Run every combination of ``plan`` and write the study's files into ``out_dir``.

    Per combination, a sub-directory with the pass's outputs (points.las, summary.json, coverage_map.png,
    render.png...); at the top, scene.ply, coverage.json, coverage.md, coverage_vs_altitude.png and
    report.html. Returns the content of coverage.json.

    The study is a campaign (docs/campaigns.md): its passes run as Dask tasks on ``client``, or on the
    scheduler at ``scheduler``, or on a local cluster of ``workers`` processes; with none of them (or
    ``workers=0``), one after another in this process. The results are the same bits either way. Passes
    already complete in ``out_dir`` are kept, unless ``redo``. ``cubes``: cubes placed once for the whole study
    across the swath of its lowest altitude (the narrowest), each record gaining ``features`` (per size placed,
    detected, fraction; :mod:`scanner_sim.studies.features`). The folder is locked while the study runs: a
    second writer is refused (:func:`~scanner_sim.io.run_dir.hold_output`).
    """
    from scanner_sim import io
    from scanner_sim.render import report

    if not config.has_seabed:
        raise ParameterError(f"scene '{config.name}': coverage is measured over the seabed's plan area; the "
                             "scene has no seabed section (nor a panel or mesh labelled seabed)")
    out = Path(out_dir)
    placed: list[dict] = []
    if cubes is not None:
        from scanner_sim.metrics.feature_cubes import with_cubes
        from scanner_sim.survey.feature_placement import cube_positions

        lowest = min(a for _, a, _ in plan.combinations(config))
        narrowest = combination_config(config, SCENE_WATER, lowest, plan.instruments[0], plan.gate)
        placed = cube_positions(narrowest, cubes.sizes_m, cubes.count, cubes.seed, max_pulses, "cube_count")
        config = with_cubes(config, placed)
    combos = list(plan.combinations(config))
    # every combination is built (and so checked) before any pass runs
    jobs = [PassJob(combination_name(water, altitude, instrument),
                    combination_config(config, water, altitude, instrument, plan.gate),
                    PassOptions(water=None if water == SCENE_WATER else water, seed=seed, fidelity=fidelity,
                                max_pulses=max_pulses, progress=False,
                                render=render, render_size=STUDY_RENDER_SIZE, write_scene=False, coverage=settings))
            for water, altitude, instrument in combos]
    names = [job.name for job in jobs]
    if view_pass is not None and view_pass not in names:
        raise ValueError(f"view_pass = {view_pass!r}: not a pass of this study; one of {', '.join(names)}")
    bands = _band_jobs(combos, jobs) if plan.water_uncertainty else []
    with hold_output(out):  # one writer at a time (io/run_dir.py)
        out.mkdir(parents=True, exist_ok=True)
        started = time.perf_counter()
        scene = cached_scene(config)
        io.write_scene_ply(out / "scene.ply", scene.vertices, scene.faces, scene.face_label, scene.face_object)
        all_jobs = jobs + [j for _, _, pair in bands for j in pair]
        with maybe_client(client, scheduler, workers, announce=progress, passes=len(all_jobs)) as dask:
            outcomes = run_jobs(all_jobs, out, dask, redo=redo, progress=progress)
        failed = [o for o in outcomes if o.status == "failed"]
        if failed:
            raise RuntimeError(f"{len(failed)} of {len(jobs)} passes failed ({failed[0].job.name}: {failed[0].error}); "
                               "the others are complete in the output folder: run the study again to redo only these")
        records = [study_record(job.config, o.summary, water, altitude, instrument, job.name)
                   for (water, altitude, instrument), job, o in zip(combos, jobs, outcomes)]
        if bands:
            from scanner_sim.studies.water_uncertainty import band_figures

            extra = outcomes[len(jobs):]
            for i, (record, o, (low, high, _)) in enumerate(zip(records, outcomes, bands)):
                record["water_uncertainty"] = band_figures(o.summary, extra[2 * i].summary, extra[2 * i + 1].summary,
                                                           low, high)
        if placed:
            from scanner_sim.metrics.feature_cubes import detection_table

            for record in records:
                record["features"] = detection_table(record["objects"], placed)
        study = {
            "scene": config.name,
            "study": {"waters": list(plan.waters),
                      "altitudes_m": [a if a is not None else config.platform.altitude_m for a in plan.altitudes_m],
                      "instruments": list(plan.instruments), "gate": plan.gate, "cell_m": settings.cell_m,
                      "min_points": settings.min_points, "tolerance_m": settings.tolerance_m,
                      "order_min_soundings": settings.order_min_soundings,
                      "phase_function": "petzold (default)", "water_uncertainty": plan.water_uncertainty},
            "s44_orders": s44.orders_table(),
            "cubes": placed,
            "s44_source": s44.SOURCE,
            "wall_s": round(time.perf_counter() - started, 1),
            "view_pass": view_pass or names[0],
            "records": records,
        }
        io.write_summary_json(out / "coverage.json", study)
        io.write_text(out / "coverage.md", report.coverage_markdown(study))
        if render:
            from scanner_sim.render.sweep_charts import plot_coverage_vs_altitude

            plot_coverage_vs_altitude(out / "coverage_vs_altitude.png", records,
                                      title=f"{config.name}: coverage against altitude")
            _calibration_charts(out, records)
            io.write_text(out / "report.html", report.report_html(study, out))
    return study


def _band_jobs(combos, jobs: list[PassJob]) -> list:
    """Per combination (weakest member, strongest member, their two passes), the members ranked at the vehicle's
    altitude (the nadir range)."""
    from dataclasses import replace

    from scanner_sim.studies.water_uncertainty import extreme_members, member_config

    out = []
    for (_, altitude, _), job in zip(combos, jobs):
        if altitude is None:
            raise ParameterError("water uncertainty: the scene flies at constant depth (platform.altitude_m is not "
                                 "set); give --altitudes-m to rank the phase functions at the nadir range")
        low, high = extreme_members(job.config, altitude)
        out.append((low, high, [PassJob(f"{job.name}-phase-{end}", member_config(job.config, member),
                                        replace(job.options, water=None))
                                for end, member in (("low", low), ("high", high))]))
    return out


def study_record(config: SceneConfig, summary: dict, water: str, altitude_m, instrument: str, name: str) -> dict:
    """One coverage.json record: the combination, its settings, pass counts and coverage figures."""
    figures = dict(summary["coverage"])
    settings = {key: figures.pop(key) for key in ("cell_m", "min_points", "tolerance_m", "order_min_soundings")}
    used = summary["settings"]
    settings.update(gate_delay_ns=used["gate_delay_ns"], gate_width_ns=used["gate_width_ns"], fidelity=summary["fidelity"],
                    seed=summary["seed"], max_pulses=summary["settings"]["max_pulses"],
                    subrays=summary["settings"]["subrays"])
    return {
        "water": water,
        "instrument": instrument,
        "altitude_m": altitude_m,
        "dir": name,
        "pulses": summary["pulses"],
        "points": summary["points"],
        "dropouts": summary["dropouts"],
        "range_error_m": summary["range_error_m"],
        "wall_s": summary["wall_s"],
        **figures,
        "tpu": _tpu_figures(summary),
        "settings": settings,
    }


def _tpu_figures(summary: dict) -> dict | None:
    """The pass's predicted THU/TVU (median, p95 [m]) and their calibration against the truth (shares within and the
    chart's levels), from summary.json's ``uncertainty``; None for a summary without one."""
    u = summary.get("uncertainty")
    if not u:
        return None
    c = u["calibration"]
    return {"thu_m": u["thu_m"], "tvu_m": u["tvu_m"], "points": c["points"],
            "vertical_within_tvu": c["vertical_within_tvu"], "horizontal_within_thu": c["horizontal_within_thu"],
            "chart": c["chart"]}


def _calibration_charts(out: Path, records: list[dict]) -> None:
    """calibration.png in each combination's folder: its TPU's predicted against observed coverage."""
    from scanner_sim.render.calibration_chart import plot_calibration

    for r in records:
        if r.get("tpu") and r["tpu"]["points"]:
            plot_calibration(out / r["dir"] / "calibration.png", r["tpu"], title=f"{r['dir']}: THU/TVU against the truth")
