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

The public names below load on first use (a module ``__getattr__``): importing one submodule (``materials``,
``loading``) does not import pydantic's models of every section, nor the physics presets behind them.
"""

from muls.infra.lazy_names import lazy_names

#: public name -> the module that defines it.
_WHERE = {
    **dict.fromkeys(("ConfigError", "build"), "scanner_sim.config.errors"),
    **dict.fromkeys(("OBJECT_TYPES", "CableObject", "ConeMineObject", "CylinderMineObject", "MeshObject",
                     "MooredMineObject", "PanelObject", "ReliefConfig", "RipplesConfig", "RocksConfig", "SeabedConfig",
                     "reflectance_of"), "scanner_sim.config.geometry"),
    **dict.fromkeys(("SCENES_DIR", "load_scene", "resolve_scene_path", "shipped_scenes"), "scanner_sim.config.loading"),
    **dict.fromkeys(("FORMAT_VERSION", "SceneConfig", "parse_scene", "scene_json_schema"),
                    "scanner_sim.config.scene_config"),
    **dict.fromkeys(("AttitudeConfig", "InstrumentConfig", "LawnmowerConfig", "NavigationNoiseConfig", "OutputConfig",
                     "PlatformConfig", "ScannerConfig", "SurveyConfig", "WaterConfig"), "scanner_sim.config.sections"),
}

__all__, __getattr__, __dir__ = lazy_names(__name__, _WHERE)
