"""Feature detection (docs/coverage.md, *Feature detection*): cubes of the sizes S-44 names, placed on the seabed at
seeded random positions across the swath the pass will fly, or the scene's own objects; one pass; per size, the
share of cubes detected.

A feature is *detected* when at least :data:`~scanner_sim.metrics.s44.FEATURE_MIN_SOUNDINGS` valid soundings lie on
it: points whose echo came from it (``object_id``) and whose |range error| is within the coverage tolerance. The
rule and its source travel with every result (``rule``).
"""

from __future__ import annotations

from pathlib import Path

from muls.infra.errors import ParameterError
from scanner_sim.config import SceneConfig
from scanner_sim.metrics.coverage import CoverageSettings
from scanner_sim.metrics.feature_cubes import DEFAULT_COUNT, DEFAULT_SIZES_M, detection_rule, detection_table, with_cubes
from scanner_sim.survey.feature_placement import cube_positions


def run_features(config: SceneConfig, out_dir: str | Path, sizes_m=DEFAULT_SIZES_M, count: int = DEFAULT_COUNT,
                 seed: int = 0, water: str | None = None, scene_objects: bool = False, max_pulses: int | None = None,
                 fidelity: str | None = None, settings: CoverageSettings = CoverageSettings(),
                 render: bool = True, progress: bool = False) -> dict:
    """Place the cubes (or take the scene's objects), run the pass into ``out_dir`` and write features.json (and,
    when rendering, features.png). Returns the content of features.json."""
    from scanner_sim import io
    from scanner_sim.survey.pipeline import run_pass
    from scanner_sim.survey.setup import PassOptions

    if config.seabed is None:
        raise ParameterError(f"scene '{config.name}': features stand on the seabed; the scene has no seabed section")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if water is not None:
        config = config.with_overrides({"water": water})
    placed = []
    if not scene_objects:
        placed = cube_positions(config, sizes_m, count, seed, max_pulses)
        config = with_cubes(config, placed)
    options = PassOptions(max_pulses=max_pulses, fidelity=fidelity, progress=progress, render=False,
                          write_scene=False, coverage=settings)
    summary = run_pass(config, out / "pass", options).summary
    objects = summary["coverage"]["objects"]
    result = {
        "scene": config.name, "water": summary["water"], "altitude_m": config.platform.altitude_m,
        "seed": seed, "pulses": summary["pulses"], "rule": detection_rule(settings),
        "cubes": detection_table(objects, placed) if placed else {},
        "placements": placed,
        "objects": [{k: o[k] for k in ("name", "kind", "valid_points", "detected", "gap_cause")} for o in objects],
        "dir": "pass",
    }
    io.write_summary_json(out / "features.json", result)
    if render:
        from scanner_sim.render.features import plot_feature_detection

        plot_feature_detection(out / "features.png", out / "pass" / "coverage_grid.npz", result,
                               title=f"{config.name}, {summary['water']}: feature detection")
    return result
