"""Campaigns (docs/campaigns.md): a base scene and the axes to sweep; every combination of the
axes' values (their cartesian product) is one survey pass, run as a Dask task (:mod:`.pass_runner`).

The flow: :func:`load_campaign` reads and checks the file (a strict model, the scene files' one-line errors)
and validates every combination's scene through :meth:`SceneConfig.with_overrides` before any pass runs;
:func:`run_campaign` runs the passes (skipping those already complete in the output folder) and writes the
campaign table (campaign.csv, campaign.parquet, campaign.json) and its charts.
"""

from __future__ import annotations

import csv
import dataclasses
import io as stdio
import itertools
import json
import math
import re
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import BeforeValidator, model_validator

from muls.infra.command import NAME_MAX_BYTES
from scanner_sim import io
from scanner_sim.config import ConfigError, SceneConfig, build, load_scene
from scanner_sim.config.base import Choice, Integer, Positive, StrictModel
from scanner_sim.config.errors import invalid
from scanner_sim.config.loading import parse_yaml_text, read_scene_text
from scanner_sim.io.run_dir import hold_output
from scanner_sim.metrics.coverage import CoverageSettings
from scanner_sim.render.sweep_charts import plot_sweep
from scanner_sim.runs.jobs import PassOutcome, run_jobs, run_pass_segmented
from scanner_sim.runs.tasks import DEFAULT_RETRIES, PassJob
from scanner_sim.survey.setup import PassOptions

__all__ = ["AXIS_ALIASES", "CHART_FIGURES", "OPTION_KEYS", "Campaign", "CampaignConfig", "load_campaign", "parse_campaign",
           "run_campaign", "run_pass_segmented"]

FORMAT_VERSION = 1
#: Sweep axes that are not dotted scene keys, and the key each one sets.
AXIS_ALIASES = {"water": "water", "instrument": "instrument.preset", "fidelity": "survey.fidelity",
                "seed": "survey.seed"}
#: Most passes (combinations of the axes' values) in one campaign, counted before any is expanded. Each pass is a
#: survey simulated in seconds to minutes and a folder of files, checked in full before the first runs: 10,000
#: passes of 10 s are a day on a 2-core machine and a chart of 10,000 points. A larger sweep (2 x 10**12 expands
#: to more combinations than memory holds) is refused at once, not found out of memory or after hours.
MAX_PASSES = 10_000
#: Options that set a scene key, and the key each one sets.
OPTION_KEYS = {"max_pulses": "survey.max_pulses", "chunk_pulses": "survey.chunk_pulses"}
#: Figures a chart can draw: name -> (the campaign table's column, scale, axis label).
CHART_FIGURES = {
    "covered_fraction": ("coverage.covered_fraction", 100.0, "covered fraction of the reached area [%]"),
    "density_pts_per_m2": ("coverage.density_pts_per_m2", 1.0, "valid points per m² reached [1/m²]"),
    "points_per_pulse": ("points_per_pulse", 1.0, "points per pulse"),
    "points": ("points", 1.0, "points"),
    "range_error_median_m": ("range_error_m.median", 1.0, "median |range error| [m]"),
    "range_error_p95_m": ("range_error_m.p95", 1.0, "95th percentile |range error| [m]"),
}


def _sweep(value: Any) -> dict[str, tuple]:
    """The sweep: axis name -> a non-empty list of distinct values; two axes may not set one key."""
    if not isinstance(value, Mapping):
        raise invalid("must be a mapping of axis name to a list of values", value=value)
    keys: dict[str, str] = {}
    for axis, values in value.items():
        if not isinstance(axis, str) or not axis.strip():
            raise invalid("an axis is a scene key by its dotted name, or water, instrument, fidelity or seed",
                          value=axis)
        if not isinstance(values, (list, tuple)) or not values:
            raise invalid("must be a non-empty list of values", key=axis, value=values)
        repeated = [v for i, v in enumerate(values) if v in values[:i]]
        if repeated:
            raise invalid(f"{repeated[0]!r} is repeated; each value once", key=axis, value=list(values))
        key = AXIS_ALIASES.get(axis, axis)
        if key in keys:
            raise invalid(f"sets {key!r}, as axis {keys[key]!r} does; sweep it once", key=axis)
        keys[key] = axis
    combinations = math.prod(len(values) for values in value.values())
    if combinations > MAX_PASSES:
        sizes = " x ".join(f"{len(values):,}" for values in value.values())
        raise invalid(f"{sizes} values give {combinations:,} combinations, more than the {MAX_PASSES:,} passes a "
                      "campaign runs; sweep fewer values, or split the sweep into campaigns")
    return {axis: tuple(values) for axis, values in value.items()}


def _names(value: Any) -> tuple:
    if isinstance(value, str):
        return (value,)
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        raise invalid("must be an axis name or a list of them", value=value)
    return tuple(value)


def _charts(value: Any) -> tuple | None:
    if value is not None and not isinstance(value, (list, tuple)):
        raise invalid("must be a list of charts, each a mapping with x, lines and y", value=value)
    return None if value is None else tuple(value)


class ChartConfig(StrictModel):
    """One chart: a figure (``y``) against axis ``x``, one line per value of the ``lines`` axes."""

    x: str
    """The sweep axis along the chart."""
    lines: Annotated[tuple[str, ...], BeforeValidator(_names)] = ()
    """The axes (one, or a list) whose values each get a line."""
    y: Choice(*CHART_FIGURES) = "covered_fraction"


def _cube_sizes(value: Any) -> tuple:
    """Cube sizes: a non-empty list of distinct numbers (each checked > 0 as ``Positive``), kept as a tuple."""
    if not isinstance(value, (list, tuple)) or not value or len(set(map(str, value))) != len(value):
        raise invalid("must be a non-empty list of distinct cube sizes [m]", value=value)
    return tuple(value)


class CampaignOptions(StrictModel):
    """How every pass of the campaign runs."""

    max_pulses: Integer(ge=1) | None = None
    """Stop each pass after this many pulses (survey.max_pulses)."""
    chunk_pulses: Integer(ge=1) | None = None
    """Pulses per chunk (survey.chunk_pulses; does not change the results)."""
    segments: Integer(ge=1) = 1
    """Cut each pass into this many runs of pulse slots, each a task (byte-identical results)."""
    render: bool = True
    """render.png and coverage_map.png per pass."""
    waveforms: Integer(ge=0) = 0
    """Also write the full records of this many sampled pulses per pass."""
    retries: Integer(ge=0) = DEFAULT_RETRIES
    """Times a task that raised is tried again."""
    cell_m: Positive = CoverageSettings.cell_m
    min_points: Integer(ge=1) = CoverageSettings.min_points
    tolerance_m: Positive = CoverageSettings.tolerance_m
    cubes_m: Annotated[tuple[Positive, ...], BeforeValidator(_cube_sizes)] | None = None
    """Cube edge sizes [m] placed across the base scene's swath for feature detection (scanner-sim features)."""
    cube_count: Integer(ge=1) = 8
    """Cubes of each size."""
    cube_seed: Integer(ge=0) = 0
    """Seed of the cube positions."""


class CampaignConfig(StrictModel):
    """A campaign file (YAML): a base scene, the axes to sweep, the options of every pass, the charts."""

    format_version: Choice(FORMAT_VERSION) = FORMAT_VERSION
    name: str | None = None
    """Default: the file's name without .yaml."""
    description: str = ""
    scene: str
    """A shipped scene's name, or a path to a scene file (relative to the campaign file's folder)."""
    sweep: Annotated[dict[str, tuple[Any, ...]], BeforeValidator(_sweep)]
    options: CampaignOptions = CampaignOptions()
    charts: Annotated[tuple[ChartConfig, ...] | None, BeforeValidator(_charts)] = None
    """Default: each numeric axis along x, one line per combination of the other axes."""

    @model_validator(mode="after")
    def _sweep_and_options_apart(self):
        """An option and an axis may not set one key (or the section holding it): the option would silently
        replace every swept value."""
        swept = {AXIS_ALIASES.get(axis, axis): axis for axis in self.sweep}
        for option, key in OPTION_KEYS.items():
            value = getattr(self.options, option)
            for swept_key, axis in swept.items():
                if value is not None and (key == swept_key or key.startswith(f"{swept_key}.")):
                    raise invalid(f"sets {key!r}, which the sweep's axis {axis!r} sweeps; give it in one place",
                                  key=f"options.{option}", value=value)
        return self

    @model_validator(mode="after")
    def _charts_name_axes(self):
        for i, chart in enumerate(self.charts or ()):
            for where, axis in [("x", chart.x)] + [(f"lines[{j}]", a) for j, a in enumerate(chart.lines)]:
                if axis not in self.sweep:
                    raise invalid(f"must be one of the sweep's axes ({', '.join(self.sweep)})",
                                  key=f"charts[{i}].{where}", value=axis)
        return self


@dataclass(frozen=True)
class Campaign:
    """A checked campaign: its file, base scene, and one job per combination (``values`` in job order)."""

    config: CampaignConfig
    name: str
    scene: SceneConfig
    values: list[dict[str, Any]]
    jobs: list[PassJob]
    source_path: Path | None = None
    cubes: list[dict] = dataclasses.field(default_factory=list)
    """The cubes placed for feature detection (:func:`scanner_sim.survey.feature_placement.cube_positions`)."""

    @property
    def axes(self) -> list[str]:
        return list(self.config.sweep)


def parse_campaign(data: Any, base_dir: Path | None = None, name: str = "campaign",
                   source_path: Path | None = None) -> Campaign:
    """A campaign mapping checked, its scene loaded and every combination's scene validated.
    Raises :class:`ConfigError` (one line naming the dotted key)."""
    config = build(CampaignConfig, data)
    base = load_base_scene(config.scene, base_dir)
    opts = config.options
    fixed = {key: getattr(opts, option) for option, key in OPTION_KEYS.items() if getattr(opts, option) is not None}
    cubes = []
    if opts.cubes_m:
        from scanner_sim.metrics.feature_cubes import with_cubes
        from scanner_sim.survey.feature_placement import cube_positions

        cubes = cube_positions(base.with_overrides(fixed), opts.cubes_m, opts.cube_count, opts.cube_seed,
                               opts.max_pulses, "options.cube_count")
        base = with_cubes(base, cubes)
    options = PassOptions(progress=False, render=opts.render, waveforms=opts.waveforms,
                          coverage=CoverageSettings(opts.cell_m, opts.min_points, opts.tolerance_m))
    axes = list(config.sweep)
    values = [dict(zip(axes, combo)) for combo in itertools.product(*config.sweep.values())]
    jobs, names = [], {}
    for combo in values:
        overrides = {AXIS_ALIASES.get(axis, axis): value for axis, value in combo.items()}
        try:
            scene = base.with_overrides({**overrides, **fixed})
        except ConfigError as exc:
            raise ConfigError(f"sweep: {exc}") from None
        name = pass_name(config.sweep, combo) or base.name
        if len(name.encode()) > NAME_MAX_BYTES:
            raise ConfigError(f"sweep: the pass folder {name[:60] + '...'!r} is {len(name.encode()):,} bytes long, more "
                              f"than the {NAME_MAX_BYTES} a name may have; use shorter values (or fewer axes)")
        if name in names:
            raise ConfigError(f"sweep: {names[name]} and {combo} give the same folder name {name!r}; "
                              "make the values differ more")
        names[name] = combo
        jobs.append(PassJob(name, scene, options, opts.segments))
    return Campaign(config, config.name or name, base, values, jobs, source_path, cubes)


def load_base_scene(scene: str, base_dir: Path | None) -> SceneConfig:
    """The base scene of a campaign or dataset file: a shipped scene's name, or a scene file's path (relative to
    ``base_dir``, the file's folder, where it lies there)."""
    scene_path = Path(scene)
    if base_dir is not None and not scene_path.is_absolute() and (base_dir / scene_path).is_file():
        scene_path = base_dir / scene_path
    return load_scene(scene_path if scene_path.suffix in (".yaml", ".yml") else scene)


def load_campaign(path: str | Path) -> Campaign:
    """Read and check a campaign file (see :func:`parse_campaign`)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"campaign = {str(path)!r}: file not found")
    # the scene files' bounds and one-line refusals naming the file: empty, binary, not UTF-8, not a mapping
    data = parse_yaml_text(read_scene_text(path, "campaign"), path, "campaign", "format_version, scene, sweep, ...")
    return parse_campaign(data, path.parent, path.stem, path)


def _folder_value(value: Any, index: int) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (int, float)):
        return f"{value:g}"
    if isinstance(value, str):
        return re.sub(r"[^A-Za-z0-9._+-]+", "-", value) or f"v{index + 1}"
    return f"v{index + 1}"  # a list or a mapping: its position in the axis


def pass_name(sweep: Mapping[str, tuple], combo: Mapping[str, Any]) -> str:
    """The folder of a combination, from its axis values: ``water=clean_ocean__platform.altitude_m=4``."""
    return "__".join(f"{axis}={_folder_value(value, sweep[axis].index(value))}" for axis, value in combo.items())


# -- running and the table --------------------------------------------------------------------------------
def run_campaign(campaign: Campaign, out_dir: str | Path, client=None, *, redo: bool = False,
                 progress: bool = True) -> dict:
    """Run every pass of ``campaign`` into ``out_dir`` (on ``client``, else in this process) and write the
    campaign table and charts. Returns the content of campaign.json; its ``failed`` counts the passes whose
    task failed (re-running the campaign redoes them). The folder is locked while the campaign runs
    (:func:`~scanner_sim.io.run_dir.hold_output`): a second writer is refused."""
    out = Path(out_dir)
    with hold_output(out):
        return _run_campaign(campaign, out, client, redo, progress)


def _run_campaign(campaign: Campaign, out: Path, client, redo: bool, progress: bool) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    outcomes = run_jobs(campaign.jobs, out, client, retries=campaign.config.options.retries, redo=redo,
                        progress=progress)
    sweep = campaign.config.sweep
    rows = [table_row(axis_labels(sweep, values), outcome, campaign.cubes)
            for values, outcome in zip(campaign.values, outcomes)]
    io.write_text(out / "campaign.csv", csv_text(rows))
    tables = ["campaign.csv", "campaign.json"]
    if write_parquet(out / "campaign.parquet", rows):
        tables.append("campaign.parquet")
    elif progress:
        print("pyarrow is not installed: campaign.csv and campaign.json only, no campaign.parquet "
              "(pip install pyarrow)")
    charts = [draw_chart(out, campaign, chart, rows) for chart in campaign_charts(campaign)]
    result = {
        "campaign": campaign.name,
        "file": str(campaign.source_path) if campaign.source_path else None,
        "scene": campaign.scene.name,
        "sweep": campaign.config.sweep,
        "options": campaign.config.options.model_dump(),
        "cubes": campaign.cubes,
        "wall_s": round(time.perf_counter() - started, 1),
        "ran": sum(o.status == "ran" for o in outcomes),
        "skipped": sum(o.status == "skipped" for o in outcomes),
        "failed": sum(o.status == "failed" for o in outcomes),
        "tables": tables,
        "charts": [c for c in charts if c],
        "passes": [{"dir": o.job.name, "values": values, "status": o.status, "error": o.error, "summary": o.summary}
                   for values, o in zip(campaign.values, outcomes)],
    }
    io.write_summary_json(out / "campaign.json", result)
    return result


def _flatten(summary: Mapping, prefix: str = "") -> dict[str, Any]:
    """The summary's numbers and texts by dotted name; lists (cables, objects) are left to campaign.json."""
    flat: dict[str, Any] = {}
    for key, value in summary.items():
        if isinstance(value, Mapping):
            flat |= _flatten(value, f"{prefix}{key}.")
        elif not isinstance(value, list):
            flat[f"{prefix}{key}"] = value
    return flat


def axis_labels(sweep: Mapping[str, tuple], values: Mapping[str, Any]) -> dict[str, Any]:
    """A combination's values as the campaign table and charts name them: numbers and texts as they are, a list or
    a mapping (a custom water) by its sweep label, its position in the axis as its folder shows it (``v2``)."""
    return {axis: v if v is None or isinstance(v, (bool, int, float, str)) else _folder_value(v, sweep[axis].index(v))
            for axis, v in values.items()}


def table_row(values: Mapping[str, Any], outcome: PassOutcome, cubes: list[dict] = ()) -> dict[str, Any]:
    """One row of the campaign table: the axis values (``values``: already labelled, :func:`axis_labels`), the
    folder, the status, the summary's figures, and with ``cubes`` placed, per size ``features.SIZE.placed``,
    ``.detected`` and ``.fraction``. An axis keeps its column where the summary has a figure of the same name (the
    ``water`` axis and the summary's resolved water name, the same for every custom water of one scene)."""
    axes = {axis: v if v is None or isinstance(v, (bool, int, float, str)) else json.dumps(v)
            for axis, v in values.items()}
    row = {**axes, "dir": outcome.job.name, "status": outcome.status, "error": outcome.error}
    if outcome.summary is not None:
        summary = outcome.summary
        row["points_per_pulse"] = summary["points"] / summary["pulses"] if summary.get("pulses") else None
        row |= _flatten(summary)
        if cubes and summary.get("coverage"):
            from scanner_sim.metrics.feature_cubes import detection_table

            table = detection_table(summary["coverage"]["objects"], cubes)
            row |= _flatten({"features": {size: {k: v for k, v in c.items() if k != "valid_soundings"}
                                          for size, c in table.items()}})
    return row | axes


def _columns(rows: list[dict]) -> list[str]:
    return list(dict.fromkeys(key for row in rows for key in row))


def csv_text(rows: list[dict]) -> str:
    """The rows as CSV, one column per key any row has (empty where a row lacks it)."""
    text = stdio.StringIO()
    writer = csv.DictWriter(text, fieldnames=_columns(rows), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return text.getvalue()


def write_parquet(path: Path, rows: list[dict]) -> bool:
    """The rows as Parquet (a column of mixed numbers and texts is stored as text); False without pyarrow."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return False
    columns = {}
    for key in _columns(rows):
        column = [row.get(key) for row in rows]
        kinds = {type(v) for v in column if v is not None}
        if kinds - {int, float} and len(kinds) > 1:
            column = [None if v is None else str(v) for v in column]
        elif kinds == {int, float}:
            column = [None if v is None else float(v) for v in column]
        columns[key] = column
    with io.atomic_path(path) as tmp:
        pq.write_table(pa.table(columns), tmp)
    return True


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def campaign_charts(campaign: Campaign) -> list[ChartConfig]:
    """The file's charts, or by default one per numeric axis along x, one line per combination of the
    other axes (the first axis along x when no axis is numeric)."""
    if campaign.config.charts is not None:
        return list(campaign.config.charts)
    sweep = campaign.config.sweep
    y = "covered_fraction" if campaign.scene.has_seabed else "points_per_pulse"
    numeric = [axis for axis, values in sweep.items() if all(_is_number(v) for v in values)]
    along = numeric or list(sweep)[:1]
    return [ChartConfig(x=x, lines=tuple(a for a in sweep if a != x), y=y) for x in along]


def draw_chart(out: Path, campaign: Campaign, chart: ChartConfig, rows: list[dict]) -> str | None:
    """Draw ``chart`` from the table ``rows``; returns its file name (None when no pass has the figure)."""
    column, scale, label = CHART_FIGURES[chart.y]
    records = [{**{a: row[a] for a in (chart.x, *chart.lines)}, chart.y: scale * row[column]}
               for row in rows if _is_number(row.get(column))]
    if not records:
        return None
    slug = lambda text: re.sub(r"[^A-Za-z0-9_]+", "-", text)  # noqa: E731
    name = f"{chart.y}_vs_{slug(chart.x)}" + (f"_by_{'_'.join(map(slug, chart.lines))}" if chart.lines else "") + ".png"
    plot_sweep(out / name, records, chart.x, chart.y, lines=chart.lines, y_label=label,
               title=f"{campaign.name} ({campaign.scene.name}): {chart.y.replace('_', ' ')} against {chart.x}")
    return name
