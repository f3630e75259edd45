"""Feature cubes (docs/coverage.md, *Feature detection*): cubes of the sizes S-44 names, placed on the seabed at
seeded random positions across the swath the pass will fly, and the detection table of a pass over them.

A feature is *detected* when at least :data:`~scanner_sim.metrics.s44.FEATURE_MIN_SOUNDINGS` valid soundings lie on
it: points whose echo came from it (``object_id``) and whose |range error| is within the coverage tolerance. The
rule and its source travel with every result (``rule``, :func:`detection_rule`).
"""

from __future__ import annotations

from scanner_sim.config import SCENES_DIR, SceneConfig
from scanner_sim.metrics import s44
from scanner_sim.metrics.coverage import NOT_REACHED_OBJECT, SHADOWED, CoverageSettings

#: Cubes per size unless asked otherwise.
DEFAULT_COUNT = 8
DEFAULT_SIZES_M = (0.5, 1.0, 2.0)
#: The shipped unit cube (centred on the origin), scaled to each cube's size.
CUBE_MESH = SCENES_DIR / "assets" / "unit_cube.obj"


def detection_rule(settings: CoverageSettings) -> dict:
    """The detection rule as JSON: soundings needed, the tolerance that makes one valid, and the source."""
    return {"min_valid_soundings": s44.FEATURE_MIN_SOUNDINGS, "tolerance_m": settings.tolerance_m,
            "text": f"a feature is detected when at least {s44.FEATURE_MIN_SOUNDINGS} points whose echo came from it "
                    f"lie within {settings.tolerance_m:g} m of its surface along their line of sight",
            "source": "IHO S-44 Edition 6.0.0 (2020) Annex D, Sample Density: at least five samples per grid node, "
                      "with a grid cell no larger than the feature, so a feature is at least one node"}


def cube_name(size_m: float, k: int) -> str:
    return f"cube_{size_m:g}m_{k:02d}"


def with_cubes(config: SceneConfig, placed: list[dict]) -> SceneConfig:
    """``config`` with the cubes ``placed`` added as ``mesh`` objects: the shipped unit cube, scaled."""
    objects = [o.model_dump(exclude_unset=True) for o in config.objects]
    objects += [{"type": "mesh", "name": p["name"], "file": str(CUBE_MESH), "scale": p["size_m"],
                 "translate_m": [p["x_m"], p["y_m"]], "rotate_deg": [0.0, 0.0, p["heading_deg"]],
                 "label": "object"} for p in placed]
    return config.with_overrides({"objects": objects})


def detection_table(objects: list[dict], placed: list[dict]) -> dict:
    """Per cube size (key: the size as text, e.g. ``"0.5"``): placed, those no pulse reached (``not_reached``) and
    those another object hides (``shadowed``), counted apart, the ``reached`` rest, ``detected``, the ``fraction``
    detected of those reached (None when none is), and per cube its valid soundings; ``objects``: the pass's
    coverage ``objects`` figures."""
    by_name = {o["name"]: o for o in objects}
    table: dict[str, dict] = {}
    for size in sorted({p["size_m"] for p in placed}):
        mine = [by_name[p["name"]] for p in placed if p["size_m"] == size]
        apart = {cause: sum(o["gap_cause"] == cause for o in mine) for cause in (NOT_REACHED_OBJECT, SHADOWED)}
        reached = len(mine) - sum(apart.values())
        detected = sum(o["detected"] for o in mine)
        table[f"{size:g}"] = {"placed": len(mine), **apart, "reached": reached, "detected": detected,
                              "fraction": detected / reached if reached else None,
                              "valid_soundings": [o["valid_points"] for o in mine]}
    return table
