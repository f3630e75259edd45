"""The survey planner's files in its output folder (docs/planning.md, docs/outputs.md): plan.json, plan.md,
plan_chart.png, plan.html, lines.geojson (the chosen plans' lines, in the site's CRS) and per water scene-WATER.yaml,
the scene of its chosen plan's confirmation pass. Each is written atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from scanner_sim import io
from scanner_sim.config import SceneConfig
from scanner_sim.motion.trajectory import lawnmower_waypoints
from scanner_sim.studies.planning import SurveyPlan


def scene_yaml(config: SceneConfig) -> str:
    """A scene file of ``config`` that runs from anywhere: every value as validated, a raster seabed by its absolute
    path."""
    data = config.model_dump(mode="json", exclude_none=True)
    raster = getattr(config.seabed, "resolved_raster", None)
    if raster is not None:
        data["seabed"]["raster"] = str(Path(raster).resolve())
    return yaml.safe_dump(data, sort_keys=False)


def line_features(plan: SurveyPlan) -> list[dict]:
    """One LineString per line of each water's chosen plan over the whole area, with ``water``, ``line``,
    ``altitude_m``, ``speed_m_s``, ``spacing_m`` and ``length_m``."""
    from scanner_sim.survey.gis_products import _feature, _line

    features = []
    for water in plan.waters:
        c = water.chosen
        if c is None:
            continue
        ends = lawnmower_waypoints(plan.area.center_m, plan.area.size_m, plan.area.heading_deg, c.spacing_m)
        for k in range(0, len(ends) - 1, 2):
            features.append(_feature(_line(ends[k:k + 2]), {
                "water": water.water, "line": k // 2 + 1, "altitude_m": c.altitude_m, "speed_m_s": c.speed_m_s,
                "spacing_m": round(c.spacing_m, 4), "length_m": round(float(np.linalg.norm(ends[k + 1] - ends[k])), 3)}))
    return features


def write_plan_files(plan: SurveyPlan, out: Path, render: bool = True) -> dict:
    """Every file of the plan into ``out``; returns plan.json's content (with the files' names)."""
    from scanner_sim.render.plan_report import plan_html, plan_markdown

    data = plan.as_json()
    scenes = {}
    for water, config in plan.confirm_configs.items():
        name = f"scene-{water}.yaml"
        io.write_text(out / name, scene_yaml(config.with_overrides({"output.dir": str(out / f"run-{water}")})))
        scenes[water] = name
    from scanner_sim.survey.setup_cache import cached_scene

    crs = cached_scene(plan.config).crs  # a site without a CRS is in a local frame: no GIS file, as for a pass
    lines_file = None
    if crs is not None:
        io.write_geojson(out / "lines.geojson", "lines", crs, line_features(plan))
        lines_file = "lines.geojson"
    data["files"] = {"scenes": scenes, "lines": lines_file, "chart": "plan_chart.png" if render else None,
                     "markdown": "plan.md", "html": "plan.html" if render else None}
    io.write_summary_json(out / "plan.json", data)
    io.write_text(out / "plan.md", plan_markdown(data))
    if render:
        from scanner_sim.render.plan_chart import plot_plan_chart

        plot_plan_chart(out / "plan_chart.png", data)
        io.write_text(out / "plan.html", plan_html(data, out))
    return data
