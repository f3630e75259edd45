"""Scene-file validation: strict keys with suggestions, units, one-line errors naming key and value; overrides
through the same validation; the fidelity table."""

import math

import pytest
import yaml

from muls.infra.errors import ParameterError
from muls.receiver.record_windows import RECORD_MODES
from scanner_sim.config import (
    SCENES_DIR,
    ConfigError,
    InstrumentConfig,
    OutputConfig,
    PlatformConfig,
    ScannerConfig,
    SceneConfig,
    SeabedConfig,
    SurveyConfig,
    load_scene,
    parse_scene,
    shipped_scenes,
)
from scanner_sim.fidelity import FIDELITY_LEVELS, fidelity_level
from scanner_sim.rays.beams import SUBRAY_COUNTS

SHIPPED = ["cable_survey", "mine_field", "seabed_lawnmower", "pool_panel", "pond_panel"]


def _base():
    return yaml.safe_load((SCENES_DIR / "cable_survey.yaml").read_text())


def test_all_issue_scenes_are_shipped():
    assert set(SHIPPED) <= set(shipped_scenes())


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scene_loads(name):
    cfg = load_scene(name)
    assert isinstance(cfg, SceneConfig) and cfg.name == name and cfg.format_version == 1
    cfg.water_model()
    cfg.instrument_model()


def test_tank_scenes_set_the_paper_gates():
    pool = load_scene("pool_panel").instrument_model()
    pond = load_scene("pond_panel").instrument_model()
    assert pool.channel("ch3").gate_delay_s == pytest.approx(150e-9)
    assert pond.channel("ch3").gate_delay_s == pytest.approx(100e-9)
    assert pond.channel("ch3").gate_width_s == pytest.approx(400e-9)
    assert load_scene("pool_panel").water_model().name == "pool"


def _error(mutate) -> str:
    data = _base()
    mutate(data)
    with pytest.raises(ConfigError) as exc:
        parse_scene(data, base_dir=SCENES_DIR)
    message = str(exc.value)
    assert "\n" not in message
    return message


def test_typo_suggests_the_nearest_key():
    msg = _error(lambda d: d["platform"].update(altitud_m=d["platform"].pop("altitude_m")))
    assert msg.startswith("platform.altitud_m: unknown key") and "did you mean 'altitude_m'" in msg


def test_top_level_typo():
    msg = _error(lambda d: d.update(scaner=d.pop("scanner")))
    assert "scaner: unknown key" in msg and "'scanner'" in msg


def test_negative_altitude():
    msg = _error(lambda d: d["platform"].update(altitude_m=-4))
    assert msg == "platform.altitude_m = -4.0: must be a number > 0"


def test_reflectance_above_one():
    msg = _error(lambda d: d["objects"][0].update(reflectance=1.2))
    assert msg == "objects[0].reflectance = 1.2: must be a number >= 0 and <= 1"


def test_nan_is_rejected():
    msg = _error(lambda d: d["seabed"].update(resolution_m=float("nan")))
    assert msg.startswith("seabed.resolution_m = nan: must be a finite number")


def test_missing_mesh_file():
    def mutate(d):
        d["objects"].append({"type": "mesh", "file": "assets/no_such_wreck.stl"})

    msg = _error(mutate)
    assert msg.startswith("objects[1].file = 'assets/no_such_wreck.stl': file not found")


def test_bad_choice_lists_allowed_values():
    msg = _error(lambda d: d["scanner"].update(mode="spiral"))
    assert "scanner.mode = 'spiral': must be one of 'continuous', 'oscillating', 'static'" in msg
    msg = _error(lambda d: d.update(water="coastal"))
    assert "water.preset = 'coastal'" in msg and "coastal_ocean" in msg


def test_format_version_and_required_keys():
    assert "format_version = 2: must be one of 1" in _error(lambda d: d.update(format_version=2))
    assert "platform: missing required key" in _error(lambda d: d.pop("platform"))


def test_units_convert_once():
    d = _base()
    d["water"] = {"attenuation_per_m": 1.44, "absorption_per_m": 0.22}
    d["instrument"] = {"preset": "mul2023", "gate_delay_ns": 120, "gate_width_ns": 300}
    cfg = parse_scene(d)
    assert cfg.water_model().scattering_per_m == pytest.approx(1.22)
    assert cfg.instrument_model().channel("ch3").gate_delay_s == pytest.approx(120e-9)


def test_water_needs_consistent_properties():
    assert "exactly one of scattering_per_m" in _error(lambda d: d.update(water={"absorption_per_m": 0.1}))


def test_numbers_written_without_a_dot_parse():
    d = _base()
    d["instrument"] = {"beam_divergence_full_rad": "4e-3"}  # PyYAML reads 4e-3 as a string
    assert parse_scene(d).instrument_model().transmitter.beam_divergence_full_rad == pytest.approx(4e-3)


def test_duplicate_keys_rejected(tmp_path):
    p = tmp_path / "dup.yaml"
    p.write_text((SCENES_DIR / "pool_panel.yaml").read_text() + "\nname: again\n")
    with pytest.raises(ConfigError, match="name: duplicate key"):
        load_scene(p)


def test_unknown_scene_name_suggests():
    with pytest.raises(ConfigError, match="did you mean 'cable_survey'"):
        load_scene("cable_survy")


def test_defaults_are_complete():
    cfg = load_scene("pool_panel")
    assert cfg.survey.level == FIDELITY_LEVELS["reference"]
    assert cfg.scanner.mounting == "along_track" and math.isclose(cfg.survey.start_s, 0.0)


def test_every_key_names_itself_in_its_error():
    """A value no key accepts, put at every key of every section, fails with one line starting at that key."""
    sections = {"platform": PlatformConfig, "instrument": InstrumentConfig, "seabed": SeabedConfig,
                "scanner": ScannerConfig, "survey": SurveyConfig, "output": OutputConfig}
    for section, model in sections.items():
        for key in model.model_fields:
            data = _base()
            data[section] = {**data.get(section, {}), key: [[]]}
            with pytest.raises(ConfigError) as exc:
                parse_scene(data, base_dir=SCENES_DIR)
            assert str(exc.value).startswith(f"{section}.{key}") and "\n" not in str(exc.value), str(exc.value)


def test_object_errors_name_the_index_not_the_type():
    msg = _error(lambda d: d["objects"].append({"type": "cylinder_mine", "position_m": [0, 0], "radius_m": 0}))
    assert msg == "objects[1].radius_m = 0.0: must be a number > 0"
    msg = _error(lambda d: d["objects"].append({"type": "cylindre_mine", "position_m": [0, 0]}))
    assert msg.startswith("objects[1].type = 'cylindre_mine': must be one of 'cable',")
    assert msg.endswith("(did you mean 'cylinder_mine'?)")
    msg = _error(lambda d: d["objects"][0].update(colour="red"))
    assert msg.startswith("objects[0].colour: unknown key; (allowed: material, reflectance, label, type, name, ")


def test_translate_takes_two_or_three_numbers():
    def with_block(translate):
        return lambda d: d["objects"].append({"type": "mesh", "file": "assets/mooring_block.obj",
                                              "translate_m": translate})

    data = _base()
    with_block([1, 2])(data)
    assert parse_scene(data, base_dir=SCENES_DIR).objects[1].translate_m == (1.0, 2.0)
    assert _error(with_block([1])) == "objects[1].translate_m = [1]: must be a list of 2 or 3 numbers"


def test_empty_section_takes_the_defaults():
    data = _base()
    data["scanner"] = None  # `scanner:` with nothing below it
    assert parse_scene(data).scanner.mode == "continuous"


def test_sections_are_frozen():
    cfg = load_scene("pool_panel")
    with pytest.raises(ValueError):
        cfg.survey.seed = 3
    with pytest.raises(ValueError):
        cfg.platform = cfg.platform
    assert cfg.survey.seed == load_scene("pool_panel").survey.seed


# -- fidelity ------------------------------------------------------------------------------------------

def test_fidelity_table():
    assert {name: (lv.subrays, lv.shadow_rays, lv.record_mode, lv.column_cut) for name, lv in FIDELITY_LEVELS.items()} \
        == {"fast": (7, True, "windowed", "pulse"), "balanced": (19, True, "windowed", "subray"),
            "auto": (19, True, "windowed", "subray"),
            "reference": (91, True, "full", "subray")}
    for name, level in FIDELITY_LEVELS.items():
        assert level.name == name and level.subrays in SUBRAY_COUNTS and level.record_mode in RECORD_MODES
    assert fidelity_level("fast") is FIDELITY_LEVELS["fast"]
    with pytest.raises(ParameterError) as exc:
        fidelity_level("fastest")
    assert str(exc.value) == "fidelity = 'fastest': must be one of 'fast', 'balanced', 'auto', 'reference'"


def test_survey_level_applies_the_scene_overrides():
    def level(**survey):
        data = _base()
        data["survey"] = survey
        return parse_scene(data).survey.level

    assert level(fidelity="fast") == FIDELITY_LEVELS["fast"]
    assert level(fidelity="fast", subrays=61).subrays == 61
    assert not level(fidelity="fast", shadow_rays=False).shadow_rays
    overridden = level(fidelity="reference", subrays=37, shadow_rays=False)
    assert (overridden.name, overridden.subrays, overridden.shadow_rays, overridden.record_mode) == \
        ("reference", 37, False, "full")


def test_fidelity_choices_come_from_the_table():
    msg = _error(lambda d: d["survey"].update(fidelity="balance"))
    assert msg == ("survey.fidelity = 'balance': must be one of "
                   f"{', '.join(map(repr, FIDELITY_LEVELS))} (did you mean 'balanced'?)")


# -- overrides -----------------------------------------------------------------------------------------

def test_overrides_replace_dotted_keys():
    cfg = load_scene("cable_survey")
    new = cfg.with_overrides({"survey.seed": 3, "water": "turbid_harbor", "platform.altitude_m": 5,
                              "instrument.gate_delay_ns": 20, "survey.fidelity": "fast"})
    assert new.survey.seed == 3 and new.survey.level == FIDELITY_LEVELS["fast"]
    assert new.water_model().name == "turbid_harbor" and new.platform.altitude_m == 5.0
    assert new.instrument_model().channel("ch3").gate_delay_s == pytest.approx(20e-9)
    assert new.platform.waypoints_m == cfg.platform.waypoints_m and new.seabed == cfg.seabed
    assert cfg.survey.seed != 3 and cfg.water.preset == "coastal_ocean"  # the original is untouched
    assert cfg.with_overrides({}) == cfg


def test_overrides_are_validated_like_a_file():
    cfg = load_scene("cable_survey")
    with pytest.raises(ConfigError) as exc:
        cfg.with_overrides({"survey.chunk_pulses": 0})
    assert str(exc.value) == "survey.chunk_pulses = 0: must be an integer >= 1"
    with pytest.raises(ConfigError, match=r"^platform: give exactly one of altitude_m"):
        cfg.with_overrides({"platform.depth_m": 10})
    assert cfg.with_overrides({"platform.depth_m": 10, "platform.altitude_m": None}).platform.depth_m == 10.0


def test_unknown_override_keys_are_rejected_like_unknown_scene_keys():
    cfg = load_scene("cable_survey")
    with pytest.raises(ConfigError, match=r"^survey\.sed: unknown key; did you mean 'seed'\?"):
        cfg.with_overrides({"survey.sed": 3})
    with pytest.raises(ConfigError, match=r"^srvey: unknown key; did you mean 'survey'\?"):
        cfg.with_overrides({"srvey.seed": 3})
    with pytest.raises(ConfigError, match=r"^survey\.seed = 1: not a section, so 'survey\.seed\.x' cannot be set"):
        cfg.with_overrides({"survey.seed.x": 3})


def test_overrides_keep_the_source_and_the_mesh_files():
    cfg = load_scene("mine_field")
    new = cfg.with_overrides({"survey.seed": 9})
    assert new.source_path == cfg.source_path == SCENES_DIR / "mine_field.yaml"
    assert new.objects[3].resolved_path == cfg.objects[3].resolved_path
    assert new.objects[3].resolved_path.is_file()


def test_docs_example_validates():
    """The complete commented example in docs/scene-format.md is a valid scene."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[3] / "docs" / "scene-format.md").read_text()
    block = text.split("```yaml\n", 1)[1].split("```", 1)[0]
    cfg = parse_scene(yaml.safe_load(block), base_dir=SCENES_DIR)
    assert cfg.name == "example_cable_survey" and cfg.platform.navigation_noise.seed == 11
