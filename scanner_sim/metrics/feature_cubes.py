"""Feature cubes (docs/coverage.md, *Feature detection*): cubes of the sizes S-44 names, placed on the seabed at
seeded random positions across the swath the pass will fly, and the detection table of a pass over them.

A feature is *detected* when at least :data:`~scanner_sim.metrics.s44.FEATURE_MIN_SOUNDINGS` valid soundings lie on
it: points whose echo came from it (``object_id``) and whose |range error| is within the coverage tolerance. The
rule and its source travel with every result (``rule``, :func:`detection_rule`).
"""

from __future__ import annotations

import math

import numpy as np

from muls.infra.errors import ParameterError
from scanner_sim.config import SCENES_DIR, SceneConfig
from scanner_sim.metrics import s44
from scanner_sim.metrics.coverage import CoverageSettings
from scanner_sim.metrics.planned_swath import planned_swath

#: Cubes per size unless asked otherwise.
DEFAULT_COUNT = 8
DEFAULT_SIZES_M = (0.5, 1.0, 2.0)
#: The shipped unit cube (centred on the origin), scaled to each cube's size.
CUBE_MESH = SCENES_DIR / "assets" / "unit_cube.obj"
#: Gap kept between two cubes' bounding circles [m].
CUBE_GAP_M = 0.25  # assumption: cubes apart (docs/assumptions.md)


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


def cube_positions(config: SceneConfig, sizes_m, count: int, seed: int, max_pulses: int | None = None,
                   count_key: str = "count") -> list[dict]:
    """Seeded random placements (name, size_m, x_m, y_m, heading_deg) of ``count`` cubes of each size [m] inside the
    swath a pass of ``config`` flies (its first ``max_pulses``), whole inside it and apart from each other;
    ``count_key``: the option's name in messages."""
    import shapely

    from scanner_sim.motion.trajectory import trajectory_of
    from scanner_sim.world.scene import build_scene

    sizes = sorted(float(s) for s in sizes_m)
    if not sizes or len(set(sizes)) != len(sizes) or any(not (math.isfinite(s) and s > 0) for s in sizes):
        raise ParameterError(f"cubes_m = {list(sizes_m)}: give distinct finite sizes > 0 [m]")
    if not (isinstance(count, int) and count >= 1):
        raise ParameterError(f"{count_key} = {count!r}: must be an integer >= 1")
    scene = build_scene(config)
    trajectory = trajectory_of(config, scene)
    rate = config.scanner.pulse_rate_hz or config.instrument_model().transmitter.repetition_rate_hz
    swath = planned_swath(config, trajectory, rate)
    if swath is None:
        raise ParameterError(f"scene '{config.name}': its plan has no swath to place cubes across (a moving platform "
                             "with cross-track scan lines is needed); use --scene-objects to count its own objects")
    start = config.survey.start_s
    stop = start + (max_pulses / rate if max_pulses else trajectory.duration_s)
    x0, x1, y0, y1 = scene.heightfield.extent_m
    area = swath.polygon(start, stop).intersection(shapely.box(x0, y0, x1, y1))
    rng = np.random.default_rng(seed)
    placed: list[dict] = []
    for size in reversed(sizes):  # the largest first, while there is room
        radius = size / math.sqrt(2.0)
        inner = area.buffer(-radius)
        if inner.is_empty:
            raise ParameterError(f"cubes_m: a {size:g} m cube does not fit inside the swath flown "
                                 f"({area.area:.1f} m²); give smaller cubes or a longer pass")
        bx0, by0, bx1, by1 = inner.bounds
        for k in range(count):
            for _ in range(2000):
                x, y = rng.uniform(bx0, bx1), rng.uniform(by0, by1)
                if shapely.contains_xy(inner, x, y) and all(
                        math.hypot(x - p["x_m"], y - p["y_m"]) > radius + p["size_m"] / math.sqrt(2.0) + CUBE_GAP_M
                        for p in placed):
                    break
            else:
                raise ParameterError(f"{count_key} = {count}: {count} cubes of each size do not fit apart inside the swath "
                                     f"flown ({area.area:.1f} m²); give fewer or a longer pass")
            placed.append({"name": cube_name(size, k), "size_m": size, "x_m": float(x), "y_m": float(y),
                           "heading_deg": float(rng.uniform(0.0, 90.0))})
    return placed


def detection_table(objects: list[dict], placed: list[dict]) -> dict:
    """Per cube size (key: the size as text, e.g. ``"0.5"``): placed, detected, fraction, and per cube its valid
    soundings; ``objects``: the pass's coverage ``objects`` figures."""
    by_name = {o["name"]: o for o in objects}
    table: dict[str, dict] = {}
    for size in sorted({p["size_m"] for p in placed}):
        mine = [by_name[p["name"]] for p in placed if p["size_m"] == size]
        detected = sum(o["detected"] for o in mine)
        table[f"{size:g}"] = {"placed": len(mine), "detected": detected, "fraction": detected / len(mine),
                              "valid_soundings": [o["valid_points"] for o in mine]}
    return table
