"""A whole scene: its sections, the checks across them, validation of a mapping, and overrides."""

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

from pydantic import Discriminator, PrivateAttr, Tag, model_validator

from scanner_sim.config.base import Choice, StrictModel, choice_check
from scanner_sim.config.crs import Crs
from scanner_sim.config.errors import ConfigError, build, checked_at, invalid
from scanner_sim.config.geometry import Objects, SeabedConfig
from scanner_sim.config.map_inputs import restore_given, to_map
from scanner_sim.config.raster_seabed import RasterSeabedConfig
from scanner_sim.config.sections import (
    InstrumentConfig,
    OutputConfig,
    PlatformConfig,
    ScannerConfig,
    SurveyConfig,
    WaterConfig,
    WaterSection,
)

FORMAT_VERSION = 1


def _seabed_kind(value: Any) -> str:
    """The seabed section's kind: a raster's when it names one, else the procedural one."""
    named = isinstance(value, RasterSeabedConfig) or (isinstance(value, Mapping) and "raster" in value)
    return "raster_seabed" if named else "procedural_seabed"


#: The ``seabed`` section: procedural, or from a raster (a section that names ``raster``).
SeabedSection = Annotated[Annotated[SeabedConfig, Tag("procedural_seabed")]
                          | Annotated[RasterSeabedConfig, Tag("raster_seabed")], Discriminator(_seabed_kind)]


class SceneConfig(StrictModel):
    """A muls-scanner scene file (YAML): water, instrument, seabed and objects, platform and trajectory,
    scanner, survey and output settings. Units are in the keys; the format is in docs/scene-format.md."""

    format_version: Choice(FORMAT_VERSION)
    """Version of the scene format."""
    name: str
    platform: PlatformConfig
    description: str = ""
    """Its first line is what ``scanner-sim scenes`` prints."""
    crs: Crs | None = None
    """The projected CRS (metres) whose map coordinates the world frame is in: an EPSG code (32631 or
    'EPSG:32631') or WKT; none: a local frame."""
    lonlat: bool = False
    """Plan positions (waypoints, lawnmower and seabed centres, static position, objects) are [longitude,
    latitude] in degrees, WGS 84, converted to ``crs``."""
    water: WaterSection = WaterConfig(preset="coastal_ocean")
    instrument: InstrumentConfig = InstrumentConfig()
    seabed: SeabedSection | None = None
    """The seabed: procedural, or from a bathymetry raster (``raster``); tank scenes have none."""
    objects: Objects = ()
    scanner: ScannerConfig = ScannerConfig()
    survey: SurveyConfig = SurveyConfig()
    output: OutputConfig = OutputConfig()
    _source_path: Path | None = PrivateAttr(None)
    _base_dir: Path | None = PrivateAttr(None)
    _overrides: dict[str, Any] = PrivateAttr(default_factory=dict)
    _given_positions: dict[tuple, Any] = PrivateAttr(default_factory=dict)

    def model_post_init(self, context: Any) -> None:
        context = context or {}
        self._source_path, self._base_dir = context.get("source_path"), context.get("base_dir")
        self._overrides = dict(context.get("overrides") or {})
        self._given_positions = dict(context.get("given_positions") or {})

    @model_validator(mode="before")
    @classmethod
    def _version_first(cls, data: Any) -> Any:
        """A file of another format version fails on its version, not on the keys that changed."""
        if isinstance(data, Mapping) and "format_version" in data:
            checked_at("format_version", choice_check(FORMAT_VERSION), data["format_version"])
        return data

    @model_validator(mode="after")
    def _sections_agree(self):
        if self.platform.mode == "static" and self.survey.duration_s is None and self.survey.max_pulses is None:
            raise invalid("a static platform needs survey.duration_s or survey.max_pulses", key="survey")
        if not self.has_seabed and (self.platform.altitude_m is not None
                                    or any(o.rests_on_seabed for o in self.objects)):
            raise invalid("missing; altitude_m and objects placed on the bottom need a seabed section (or a panel "
                          "or mesh labelled seabed)", key="seabed")
        lawnmower = self.platform.lawnmower if self.platform.mode == "lawnmower" else None
        if lawnmower is not None and lawnmower.size_m is None and not isinstance(self.seabed, RasterSeabedConfig):
            raise invalid("missing; only a lawnmower over a raster seabed may leave its area to the raster's valid "
                          "extent", key="platform.lawnmower.size_m")
        altitude = self.platform.altitude_m
        if altitude is not None and isinstance(self.seabed, SeabedConfig) and altitude >= self.seabed.depth_m:
            raise invalid(f"puts the vehicle above the water surface: the seabed lies {self.seabed.depth_m:g} m deep "
                          "(seabed.depth_m) and altitude_m is metres above it", key="platform.altitude_m",
                          value=altitude)
        return self

    @property
    def seabed_objects(self) -> tuple[int, ...]:
        """The indices in ``objects`` of the surfaces that are the seabed: the meshes and the panels not standing on
        edge (a wall has no top surface) labelled seabed. Where the scene has no seabed section their top surface
        gives its height field (:func:`scanner_sim.world.scene.build_scene`); another object labelled seabed is
        only classed so."""
        return tuple(i for i, o in enumerate(self.objects) if o.label == "seabed" and (
            o.type == "mesh" or o.type == "panel" and o.normal[2] != 0.0))

    @property
    def has_seabed(self) -> bool:
        """A seabed section, or a panel or mesh labelled seabed: something to follow and measure coverage over."""
        return self.seabed is not None or bool(self.seabed_objects)

    @property
    def source_path(self) -> Path | None:
        """The file the scene came from (None for a mapping)."""
        return self._source_path

    @property
    def overrides(self) -> dict[str, Any]:
        """Every value given on top of the scene file by dotted key (``--set``, a run's options, a campaign's sweep,
        :meth:`with_overrides` in the Python API), in the order given; a key given twice holds its last value."""
        return dict(self._overrides)

    @property
    def output_dir(self) -> str:
        return self.output.dir or f"out/{self.name}"

    def water_model(self):
        """The :class:`muls.water.properties.Water` of this scene."""
        return self.water.to_water(f"{self.name}_water")

    def instrument_model(self):
        """The :class:`muls.instrument.description.Instrument` of this scene (gate and other overrides applied)."""
        return self.instrument.to_instrument(self.water_model())

    def with_overrides(self, overrides: Mapping[str, object], *, given: bool = True) -> "SceneConfig":
        """This scene with values replaced by dotted key (``{"survey.seed": 3, "water": "turbid_harbor",
        "platform.altitude_m": 4}``), validated again as a whole the way a file is: a bad value or an unknown
        key raises the one-line :class:`ConfigError` naming it. Source path and mesh folder are kept.

        ``given``: the values are the user's, listed in :attr:`overrides` (a pass's provenance names them);
        False for values a pass derives itself (the operator's gate rule)."""
        if not isinstance(overrides, Mapping) or not all(isinstance(key, str) for key in overrides):
            raise TypeError(f"overrides must be a mapping of dotted scene keys (str) to values, "
                            f"not {type(overrides).__name__} {overrides!r:.60}")
        data = restore_given(self.model_dump(exclude_unset=True), self._given_positions)
        for key, value in overrides.items():
            *sections, last = key.split(".")
            node = data
            for i, name in enumerate(sections):
                if node.get(name) is None:  # a section left to its defaults, or absent
                    node[name] = {}
                elif not isinstance(node[name], dict):
                    where = ".".join(sections[: i + 1])
                    raise ConfigError(f"{where} = {node[name]!r}: not a section, so {key!r} cannot be set; "
                                      f"override {where!r} whole")
                node = node[name]
            node[last] = value
        given_now = {**self._overrides, **overrides} if given else self._overrides
        return parse_scene(data, base_dir=self._base_dir, source_path=self._source_path, overrides=given_now)


def parse_scene(data: Mapping, base_dir: Path | None = None, source_path: Path | None = None,
                overrides: Mapping[str, Any] | None = None) -> SceneConfig:
    """Validate a scene mapping. Mesh files are resolved against ``base_dir`` (default: the working
    directory) and must exist; ``overrides``: the values given on top of it by dotted key
    (:attr:`SceneConfig.overrides`). Longitude/latitude positions and a line plan are converted to map
    coordinates first (:mod:`scanner_sim.config.map_inputs`). Raises :class:`ConfigError` (one line)."""
    data, given_positions = to_map(data, base_dir)
    return build(SceneConfig, data, context={"base_dir": base_dir, "source_path": source_path,
                                             "given_positions": given_positions,
                                             "overrides": overrides})


def scene_json_schema() -> dict:
    """The JSON Schema (draft 2020-12) of scene files, for editors and other tools."""
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **SceneConfig.model_json_schema()}
