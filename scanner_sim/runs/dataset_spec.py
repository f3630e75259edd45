"""Dataset spec files (docs/datasets.md): a base scene, the scene keys drawn per scene and the objects placed at
random, the number of scenes, their seed and the split fractions; checked as strictly as a scene file, every
error one line naming the dotted key (``draw.seabed.depth_m.max = 5.0: must be >= min (10.0)``).

The drawing itself is :mod:`.dataset_draw`; running the scenes and writing the manifest, :mod:`.dataset`.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BeforeValidator, model_validator

from scanner_sim.config import ConfigError, build
from scanner_sim.config.base import Choice, Fraction, Integer, NonNegative, Positive, Real, StrictModel, Vector
from scanner_sim.config.errors import invalid
from scanner_sim.config.geometry import OBJECT_TYPES
from scanner_sim.config.loading import parse_yaml_text, read_scene_text
from scanner_sim.config.materials import LABELS
from scanner_sim.config.sections import MAX_SEED

__all__ = ["OWN_KEYS", "PLACED_TYPES", "DatasetSpec", "Distribution", "ObjectTemplate", "parse_dataset_spec",
           "read_spec_data"]

FORMAT_VERSION = 1
#: Scene keys the dataset sets itself (the seeds from the scene's index, the pulses from ``max_pulses``, the
#: objects from ``objects``, the files it reads): a spec may neither set nor draw them.
OWN_KEYS = ("survey.seed", "seabed.seed", "platform.navigation_noise.seed", "survey.max_pulses", "objects", "output")
#: Object types the dataset can place, and the key it writes the place into.
PLACED_TYPES = {"cable": "points_m", "cylinder_mine": "position_m", "cone_mine": "position_m",
                "moored_mine": "position_m"}
#: Most scenes in one dataset (the folder names carry at least four digits).
MAX_SCENES = 1_000_000
#: Most objects of one template in one scene.
MAX_COUNT = 1000


def _non_empty_list(value: Any) -> tuple:
    if not isinstance(value, (list, tuple)) or not value:
        raise invalid("must be a non-empty list of values", value=value)
    return tuple(value)


class Distribution(StrictModel):
    """A value drawn per scene: uniform in [``min``, ``max``] (whole numbers, each equally likely, with
    ``integer: true``), or one of the values of ``one_of``, each equally likely."""

    min: Real | None = None
    max: Real | None = None
    integer: bool = False
    """Draw whole numbers from min to max, both included."""
    one_of: Annotated[tuple[Any, ...], BeforeValidator(_non_empty_list)] | None = None
    """A list of values (numbers, names, mappings) to draw from."""

    @model_validator(mode="after")
    def _one_kind(self):
        ranged = self.min is not None or self.max is not None
        if self.one_of is not None:
            if ranged or self.integer:
                raise invalid("give one_of alone, or min and max (with integer), not both")
            return self
        if self.min is None or self.max is None:
            raise invalid("give min and max (a range), or one_of (a list)", key="min" if self.min is None else "max")
        if self.max < self.min:
            raise invalid(f"must be >= min ({self.min!r})", key="max", value=self.max)
        if self.integer and not (self.min.is_integer() and self.max.is_integer()):
            raise invalid("must be whole numbers with integer: true", key="min" if not self.min.is_integer()
                          else "max", value=self.min if not self.min.is_integer() else self.max)
        return self

    def draw(self, rng: np.random.Generator) -> Any:
        """One value from ``rng`` (a ``numpy.random.Generator``): always exactly one draw of it."""
        if self.one_of is not None:
            return self.one_of[int(rng.integers(len(self.one_of)))]
        if self.integer:
            return int(rng.integers(int(self.min), int(self.max), endpoint=True))
        return float(rng.uniform(self.min, self.max))


def _count(value: Any) -> Any:
    """``count: 2`` is short for ``{min: 2, max: 2, integer: true}``."""
    if isinstance(value, int) and not isinstance(value, bool):
        return {"min": value, "max": value, "integer": True}
    return value


def _scene_keys(allowed: str):
    """``check(value)``: a mapping whose keys are non-blank text (dotted scene keys, or an object type's keys)."""

    def check(value: Any) -> Any:
        if not isinstance(value, Mapping) or not all(isinstance(k, str) and k.strip() for k in value):
            raise invalid(f"must be a mapping of {allowed}", value=value)
        return value

    return check


Draws = Annotated[dict[str, Distribution], BeforeValidator(_scene_keys("keys to {min, max} or {one_of: [...]}"))]
Fixed = Annotated[dict[str, Any], BeforeValidator(_scene_keys("keys to values"))]


class ObjectTemplate(StrictModel):
    """Objects of one type placed at random in ``object_area_m``: how many per scene, their class and the keys of
    the object type set or drawn (``radius_m``, ``burial_fraction``...)."""

    type: Choice(*PLACED_TYPES)
    count: Annotated[Distribution, BeforeValidator(_count)] = Distribution(min=1, max=1, integer=True)
    """Objects per scene: a whole number, or a range with integer: true."""
    label: Choice(*LABELS) | None = None
    """Their class (LAS classification); default the type's (mine, cable)."""
    heading_deg: Distribution = Distribution(min=0.0, max=360.0)
    """Compass direction of a cylinder mine's axis or of a cable's line [deg]."""
    wander_m: NonNegative = 0.3
    """A cable's points leave its straight line sideways by up to this much, drawn per point [m]."""
    points: Integer(ge=2, le=100) = 5
    """A cable's points across the area."""
    set: Fixed = {}
    """Keys of the object type, the same in every scene."""
    draw: Draws = {}
    """Keys of the object type drawn per object."""

    @model_validator(mode="after")
    def _object_keys(self):
        fields = OBJECT_TYPES[self.type].model_fields
        placed = {"type", "label", PLACED_TYPES[self.type]} | ({"heading_deg"} if "heading_deg" in fields else set())
        for where, keys in (("set", self.set), ("draw", self.draw)):
            for key in keys:
                if key in placed:
                    raise invalid(f"placed by the dataset (type, label, {PLACED_TYPES[self.type]}, heading_deg are "
                                  "the template's); remove it", key=f"{where}.{key}")
                if key not in fields:
                    hint = difflib.get_close_matches(key, list(fields), n=1, cutoff=0.5)
                    raise invalid(f"not a key of {self.type}; " + (f"did you mean {hint[0]!r}? " if hint else "")
                                  + f"(allowed: {', '.join(k for k in fields if k not in placed)})", key=f"{where}.{key}")
        both = set(self.set) & set(self.draw)
        if both:
            raise invalid("is both set and drawn; give it in one place", key=f"draw.{sorted(both)[0]}")
        count = self.count
        values = count.one_of if count.one_of is not None else (count.min, count.max) if count.integer else None
        if values is None or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and float(v).is_integer()
                                     and 0 <= v <= MAX_COUNT for v in values):
            raise invalid(f"must be a whole number from 0 to {MAX_COUNT}, or a range of them with integer: true (or "
                          "one_of a list of them)", key="count", value=count.model_dump(exclude_defaults=True))
        return self


class Splits(StrictModel):
    """The share of scenes in each split; they add up to 1."""

    train: Fraction = 0.8
    validation: Fraction = 0.1
    test: Fraction = 0.1

    @model_validator(mode="after")
    def _whole(self):
        total = self.train + self.validation + self.test
        if not math.isclose(total, 1.0, abs_tol=1e-9):
            raise invalid(f"add up to {total:g}; train, validation and test must add up to 1",
                          value=self.model_dump())
        return self


def _templates(value: Any) -> tuple:
    if not isinstance(value, (list, tuple)):
        raise invalid("must be a list of object templates, each a mapping with a type", value=value)
    return tuple(value)


class DatasetSpec(StrictModel):
    """A dataset spec file (YAML): a base scene, what is drawn per scene, the objects placed, how many scenes."""

    format_version: Choice(FORMAT_VERSION) = FORMAT_VERSION
    name: str | None = None
    """Default: the file's name without .yaml."""
    description: str = ""
    scene: str
    """The base scene: a shipped scene's name, or a path to a scene file (relative to the spec file)."""
    seed: Integer(ge=0, le=MAX_SEED)
    """The dataset's seed: scene i is drawn from (seed, i) alone."""
    scenes: Integer(ge=1, le=MAX_SCENES)
    """Number of scenes."""
    max_pulses: Integer(ge=1)
    """Pulses fired per scene (survey.max_pulses)."""
    render: bool = False
    """render.png and coverage_map.png per scene."""
    splits: Splits = Splits()
    set: Fixed = {}
    """Scene keys by dotted name, the same in every scene (scanner.pulse_rate_hz: 200)."""
    draw: Draws = {}
    """Scene keys by dotted name drawn per scene (water: {one_of: [...]}, platform.altitude_m: {min, max})."""
    object_area_m: Vector(2, element=Positive) | None = None
    """Size [x, y] of the rectangle, centred on the seabed's centre, the objects are placed in [m]; default the
    seabed's size."""
    min_spacing_m: NonNegative = 0.0
    """Least plan distance of a mine's centre from every other mine's centre and every cable's line [m]; 0 places
    every object independently."""
    objects: Annotated[tuple[ObjectTemplate, ...], BeforeValidator(_templates)] | None = None
    """Templates of the objects placed per scene; without it, every scene keeps the base scene's objects."""

    @model_validator(mode="after")
    def _own_keys(self):
        for where, keys in (("set", self.set), ("draw", self.draw)):
            for key in keys:
                if any(key == own or key.startswith(f"{own}.") or own.startswith(f"{key}.") for own in OWN_KEYS):
                    raise invalid(f"is set by the dataset itself ({', '.join(OWN_KEYS)}: seeds from the scene's "
                                  "index, max_pulses, objects); remove it", key=f"{where}.{key}")
        both = set(self.set) & set(self.draw)
        if both:
            raise invalid("is both set and drawn; give it in one place", key=f"draw.{sorted(both)[0]}")
        return self


def parse_dataset_spec(data: Any, name: str = "dataset") -> DatasetSpec:
    """A spec mapping checked (:class:`ConfigError`, one line naming the dotted key); ``name`` its default name."""
    spec = build(DatasetSpec, data)
    return spec if spec.name else spec.model_copy(update={"name": name})


def read_spec_data(path: str | Path) -> dict:
    """The mapping a spec file holds, read as strictly as a scene file (size, UTF-8, YAML hazards, duplicate keys)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"spec = {str(path)!r}: file not found")
    return parse_yaml_text(read_scene_text(path, "dataset spec"), path, "dataset spec", "format_version, scene, seed, ...")
