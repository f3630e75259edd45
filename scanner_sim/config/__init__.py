"""Scene files: YAML -> validated, frozen pydantic models, converted once.

The format is versioned (``format_version: 1``) and strict: every key carries its unit, an unknown key is
rejected with the nearest valid key suggested, and every bad value raises :class:`ConfigError` (a
``ValueError``) with one line naming the dotted key, the value and what is allowed. The full format, with a
commented example, is in ``docs/scene-format.md``; ``scanner-sim schema`` prints its JSON Schema.

Entry points: :func:`load_scene` (a shipped scene's name or a path), :func:`parse_scene` (a mapping) and
:meth:`SceneConfig.with_overrides` (dotted keys, validated the same way).

Modules: ``errors`` (ConfigError and the one-line messages), ``base`` (strict base model, value types),
``sections`` (water, instrument, platform, scanner, survey, output), ``geometry`` (seabed and objects),
``scene_config`` (the whole scene, overrides, JSON Schema), ``loading`` (YAML files and shipped scenes),
``crs`` (the scene's coordinate reference system).
"""

from scanner_sim.config.errors import ConfigError, build
from scanner_sim.config.geometry import (
    OBJECT_TYPES,
    CableObject,
    ConeMineObject,
    CylinderMineObject,
    MeshObject,
    MooredMineObject,
    PanelObject,
    ReliefConfig,
    RipplesConfig,
    RocksConfig,
    SeabedConfig,
    reflectance_of,
)
from scanner_sim.config.loading import SCENES_DIR, load_scene, resolve_scene_path, shipped_scenes
from scanner_sim.config.scene_config import FORMAT_VERSION, SceneConfig, parse_scene, scene_json_schema
from scanner_sim.config.sections import (
    AttitudeConfig,
    InstrumentConfig,
    LawnmowerConfig,
    NavigationNoiseConfig,
    OutputConfig,
    PlatformConfig,
    ScannerConfig,
    SurveyConfig,
    WaterConfig,
)

__all__ = [
    "FORMAT_VERSION", "OBJECT_TYPES", "SCENES_DIR", "AttitudeConfig", "CableObject", "ConeMineObject", "ConfigError",
    "CylinderMineObject", "InstrumentConfig", "LawnmowerConfig", "MeshObject", "MooredMineObject",
    "NavigationNoiseConfig", "OutputConfig", "PanelObject", "PlatformConfig", "ReliefConfig", "RipplesConfig",
    "RocksConfig", "ScannerConfig", "SceneConfig", "SeabedConfig", "SurveyConfig", "WaterConfig", "build",
    "load_scene", "parse_scene", "reflectance_of", "resolve_scene_path", "scene_json_schema", "shipped_scenes",
]
