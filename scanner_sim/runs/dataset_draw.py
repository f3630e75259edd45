"""Drawing a dataset's scenes (docs/datasets.md): scene i is drawn from the spec's seed and i alone, so it is the
same whatever the number of scenes, the workers or the order passes finish in; its split follows from a hash of
the same two numbers.

Scene i's random stream is ``numpy.random.default_rng(SeedSequence(seed, spawn_key=(i,)))`` (what
``SeedSequence(seed).spawn(n)[i]`` gives), and its survey and seabed seeds are that sequence's first two 64-bit
words halved (:func:`scene_seeds`). The stream is drawn in one fixed order: the spec's ``draw`` keys as the file
lists them, then per object template its count and, per object, its heading, place and ``draw`` keys.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from scanner_sim.config import ConfigError, SceneConfig
from scanner_sim.config.geometry import OBJECT_TYPES, SeabedConfig
from scanner_sim.runs.dataset_spec import DatasetSpec, ObjectTemplate
from scanner_sim.world.raster import lawnmower_area, plan_bounds

__all__ = ["OUTPUT_KEYS", "SPLITS", "DrawnScene", "draw_scene", "scene_folder", "scene_seeds", "split_of"]

#: The split names, in the order their fractions are laid out on [0, 1).
SPLITS = ("train", "validation", "test")
#: The outputs every scene writes, whatever the base scene asks: one points.las per scene.
OUTPUT_KEYS = {"output.las": True, "output.laz": False, "output.split_legs": False,
               "output.waveform_every_n_pulses": 0}


@dataclass(frozen=True)
class DrawnScene:
    """Scene ``index`` of a dataset: its folder name, seeds, drawn values by dotted key (the spec's ``draw`` keys
    and ``objects``, the placed objects as scene-file mappings), split, and the scene as validated."""

    index: int
    name: str
    seed: int
    seabed_seed: int | None
    drawn: dict[str, Any]
    split: str
    config: SceneConfig


def scene_seeds(seed: int, index: int) -> tuple[np.random.SeedSequence, int, int, int]:
    """Scene ``index``'s seed sequence and its survey, seabed and navigation-noise seeds (each in 0 .. 2**63 - 1: the
    sequence's first three 64-bit words halved; the first two do not depend on how many words are drawn)."""
    sequence = np.random.SeedSequence(seed, spawn_key=(index,))
    survey_seed, seabed_seed, navigation_seed = (int(w >> np.uint64(1)) for w in sequence.generate_state(3, np.uint64))
    return sequence, survey_seed, seabed_seed, navigation_seed


def split_of(seed: int, index: int, fractions: dict[str, float]) -> str:
    """The split of scene ``index``: u = the first 8 bytes of SHA-256 of the text ``"SEED:INDEX"`` as a big-endian
    integer over 2**64, in [0, 1); ``train`` when u < f_train, ``validation`` when u < f_train + f_validation,
    else ``test``."""
    u = int.from_bytes(hashlib.sha256(f"{seed}:{index}".encode()).digest()[:8], "big") / 2.0**64
    edge = 0.0
    for name in SPLITS[:-1]:
        edge += fractions[name]
        if u < edge:
            return name
    return SPLITS[-1]


def scene_folder(index: int, count: int) -> str:
    """``scene_0007``: the index with at least four digits, as many as the largest index needs."""
    return f"scene_{index:0{max(4, len(str(count - 1)))}d}"


def _with(config: SceneConfig, overrides: dict, spec: DatasetSpec, name: str, templates: Sequence[int] = ()) -> SceneConfig:
    """``config`` with ``overrides``; an error on a key of the spec's ``set`` or ``draw`` is named as the spec's key
    (``draw.seabed.depth_m = -2.0: must be a number >= 0 (scene_0003)``), or of a template's (``templates``: the
    template of each placed object); any other names the scene."""
    try:
        return config.with_overrides(overrides)
    except ConfigError as exc:
        message = str(exc)
        for where, keys in (("draw", spec.draw), ("set", spec.set)):
            if any(message.startswith((f"{key} ", f"{key}:", f"{key}.", f"{key}[")) for key in keys):
                raise ConfigError(f"{where}.{message} ({name})") from None
        for k, t in enumerate(templates):  # a drawn object's key: named in its template
            template = spec.objects[t]
            for where, keys in (("draw", template.draw), ("set", template.set)):
                if any(message.startswith(f"objects[{k}].{key}") for key in keys):
                    raise ConfigError(f"objects[{t}].{where}.{message.removeprefix(f'objects[{k}].')} ({name}, "
                                      f"object {k})") from None
        raise ConfigError(f"{name}: {message}") from None


def draw_scene(spec: DatasetSpec, base: SceneConfig, index: int) -> DrawnScene:
    """Draw scene ``index`` of ``spec`` over ``base`` and validate it whole (a drawn value a scene does not allow
    raises the one-line ConfigError, naming the scene)."""
    sequence, survey_seed, seabed_seed, navigation_seed = scene_seeds(spec.seed, index)
    rng = np.random.default_rng(sequence)
    name = scene_folder(index, spec.scenes)
    drawn: dict[str, Any] = {key: distribution.draw(rng) for key, distribution in spec.draw.items()}
    overrides = {**spec.set, **drawn, "survey.seed": survey_seed, "platform.navigation_noise.seed": navigation_seed,
                 "survey.max_pulses": spec.max_pulses, **OUTPUT_KEYS}
    config = _with(base, overrides, spec, name)
    if isinstance(config.seabed, SeabedConfig):
        overrides["seabed.seed"] = seabed_seed
    else:  # no seabed to draw: none, or a raster's (its micro_relief.seed is the spec's to set or draw)
        seabed_seed = None
    templates: list[int] = []
    if spec.objects is not None:
        drawn["objects"], templates = place_objects(spec, config, rng, name)
        overrides["objects"] = drawn["objects"]
    config = _with(base, overrides, spec, name, templates)
    return DrawnScene(index, name, survey_seed, seabed_seed, drawn, split_of(spec.seed, index, spec.splits.model_dump()),
                      config)


#: Tries at placing one object at ``min_spacing_m`` from those placed before it.
PLACING_TRIES = 100


def place_objects(spec: DatasetSpec, config: SceneConfig, rng: np.random.Generator,
                  name: str) -> tuple[list[dict], list[int]]:
    """The objects of every template, as scene-file mappings, placed uniformly in the object area (centred on the
    seabed's centre) and turned to a uniform heading by default; and the template of each. An object closer than
    ``min_spacing_m`` to one placed before it (:func:`_spaced`) is drawn again, heading, place and keys."""
    centre, size = _object_area(spec, config, name)
    low, high = centre - size / 2, centre + size / 2
    objects: list[dict] = []
    templates: list[int] = []
    for t, template in enumerate(spec.objects):
        for _ in range(int(template.count.draw(rng))):
            for _ in range(PLACING_TRIES):
                obj = _placed(template, len(objects), low, high, rng)
                if _spaced(obj, objects, spec.min_spacing_m):
                    break
            else:
                raise ConfigError(f"min_spacing_m = {spec.min_spacing_m!r}: {name} could not place its "
                                  f"{obj['name']} that far from the {len(objects)} objects before it in "
                                  f"{PLACING_TRIES} tries; give a larger object_area_m, fewer objects or a smaller "
                                  "spacing")
            objects.append(obj)
            templates.append(t)
    return objects, templates


def _object_area(spec: DatasetSpec, config: SceneConfig, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(centre (2,), size (2,)) [m] of the rectangle objects are placed in: ``object_area_m`` (default: the
    procedural seabed's size) centred on the procedural seabed's centre, on the survey plan's centre over a raster
    seabed (whose extent is no area to fill), on the origin without a seabed section."""
    if spec.object_area_m is None and not isinstance(config.seabed, SeabedConfig):
        what = "a raster seabed, whose whole extent" if config.seabed is not None else "no seabed section, which"
        raise ConfigError(f"{name}: object_area_m: missing; the base scene has {what} gives no area to place "
                          "objects in: give object_area_m [x, y] (centred on the survey's plan)")
    if isinstance(config.seabed, SeabedConfig):
        centre = config.seabed.center_m
    elif config.seabed is not None:
        bounds = plan_bounds(config)
        centre = ((bounds[0] + bounds[1]) / 2, (bounds[2] + bounds[3]) / 2) if bounds is not None else (
            lawnmower_area(config.platform.lawnmower, config.seabed)[0])
    else:
        centre = (0.0, 0.0)
    return np.array(centre, float), np.array(spec.object_area_m or config.seabed.size_m, float)


def _spaced(obj: dict, placed: list[dict], spacing_m: float) -> bool:
    """Whether ``obj`` keeps ``spacing_m`` in plan from every object in ``placed``: a mine's centre from the other
    mines' centres and from the cables' lines, a cable's line from the mines' centres (cables may cross)."""
    if spacing_m <= 0.0:
        return True
    if "position_m" in obj:
        centre = np.array(obj["position_m"][:2])
        return all(_distance_m(centre, other) >= spacing_m for other in placed)
    line = np.array(obj["points_m"])[:, :2]
    return all(_distance_m(np.array(other["position_m"][:2]), {"points_m": line}) >= spacing_m
               for other in placed if "position_m" in other)


def _distance_m(point: np.ndarray, other: dict) -> float:
    """Plan distance [m] from ``point`` (2,) to an object's centre, or to the nearest segment of a cable's line."""
    if "position_m" in other:
        return float(np.hypot(*(point - np.array(other["position_m"][:2]))))
    line = np.asarray(other["points_m"], float)[:, :2]
    a, ab = line[:-1], np.diff(line, axis=0)
    t = np.clip(np.einsum("ij,ij->i", point - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0.0, 1.0)
    return float(np.hypot(*(a + t[:, None] * ab - point).T).min())


def _placed(template: ObjectTemplate, number: int, low: np.ndarray, high: np.ndarray,
            rng: np.random.Generator) -> dict:
    """One object of ``template``: heading, place, then its ``draw`` keys, in that order."""
    heading_deg = template.heading_deg.draw(rng)
    obj: dict[str, Any] = {"type": template.type, "name": f"{template.type}_{number}"}
    if template.label is not None:
        obj["label"] = template.label
    if template.type == "cable":
        obj["points_m"] = cable_points(low, high, heading_deg, template.points, template.wander_m, rng)
    else:
        obj["position_m"] = [float(v) for v in rng.uniform(low, high)]
        if "heading_deg" in OBJECT_TYPES[template.type].model_fields:
            obj["heading_deg"] = heading_deg
    obj |= template.set
    obj |= {key: distribution.draw(rng) for key, distribution in template.draw.items()}
    return obj


def cable_points(low: np.ndarray, high: np.ndarray, heading_deg: float, count: int, wander_m: float,
                 rng: np.random.Generator) -> list[list[float]]:
    """``count`` [x, y] points [m] of a cable across the rectangle [low, high]: along the chord through a uniform
    point at compass heading ``heading_deg`` (0 north, 90 east), each moved sideways by uniform(-wander_m, wander_m)
    and kept within the rectangle."""
    through = rng.uniform(low, high)
    along = np.array([math.sin(math.radians(heading_deg)), math.cos(math.radians(heading_deg))])
    side = np.array([along[1], -along[0]])
    # the chord: t with low <= through + t along <= high, on both axes
    with np.errstate(divide="ignore"):
        ends = np.sort(np.stack([(low - through) / along, (high - through) / along]), axis=0)
    moving = np.abs(along) > 1e-12
    t0, t1 = ends[0][moving].max(), ends[1][moving].min()
    t = np.linspace(t0, t1, count)
    offsets = rng.uniform(-wander_m, wander_m, count)
    points = np.clip(through + t[:, None] * along + offsets[:, None] * side, low, high)
    return [[float(x), float(y)] for x, y in points]
