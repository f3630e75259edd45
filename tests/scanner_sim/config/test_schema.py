"""`scanner-sim schema`: the JSON Schema editors use accepts every shipped scene and rejects what the loader
rejects (an unknown key, a wrong object type, a value out of range)."""

import contextlib
import io
import json
from pathlib import Path

import jsonschema
import pytest
import yaml

from scanner_sim.cli import main
from scanner_sim.config import SCENES_DIR, shipped_scenes


@pytest.fixture(scope="module")
def validator():
    """A validator for the schema ``scanner-sim schema`` prints."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["schema"]) == 0
    schema = json.loads(out.getvalue())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def _scene(name="mine_field"):
    return yaml.safe_load((SCENES_DIR / f"{name}.yaml").read_text())


@pytest.mark.parametrize("name", sorted(shipped_scenes()))
def test_every_shipped_scene_validates(validator, name):
    validator.validate(_scene(name))


def test_docs_example_validates(validator):
    text = (Path(__file__).resolve().parents[3] / "docs" / "scene-format.md").read_text()
    validator.validate(yaml.safe_load(text.split("```yaml\n", 1)[1].split("```", 1)[0]))


def _errors(validator, data) -> list[str]:
    return [e.message for e in validator.iter_errors(data)]


def test_unknown_key_is_rejected(validator):
    data = _scene()
    data["platform"]["altitud_m"] = 4.0
    assert any("'altitud_m' was unexpected" in m for m in _errors(validator, data))
    data = _scene()
    data["scaner"] = {}
    assert any("'scaner' was unexpected" in m for m in _errors(validator, data))


def test_wrong_object_type_is_rejected(validator):
    data = _scene()
    data["objects"][0]["type"] = "sea_mine"
    assert _errors(validator, data)


def test_values_out_of_range_are_rejected(validator):
    data = _scene()
    data["platform"]["altitude_m"] = -4.0
    assert _errors(validator, data)
    data = _scene()
    data["objects"][1]["burial_fraction"] = 1.5
    assert _errors(validator, data)
    data = _scene()
    data["water"] = "coastal"
    assert _errors(validator, data)


def test_every_section_is_closed_and_keys_carry_units(validator):
    schema = validator.schema
    assert all(section["additionalProperties"] is False for section in [schema, *schema["$defs"].values()])
    assert "[m]" in schema["$defs"]["PlatformConfig"]["properties"]["altitude_m"]["description"]


def test_out_writes_the_same_schema(tmp_path, capsys):
    out = tmp_path / "scene.schema.json"
    assert main(["schema", "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    assert main(["schema"]) == 0
    assert json.loads(out.read_text()) == json.loads(capsys.readouterr().out)
