"""The scene's ``crs`` key: a projected CRS in metres checked by pyproj, on Scene as a pyproj.CRS, named in the
pass's summary; a geographic CRS or an unknown code refused in one line naming ``crs``."""

import json

import pytest
import yaml
from conftest import utm_scene_data

from scanner_sim.cli import main
from scanner_sim.config import ConfigError, parse_scene
from scanner_sim.world.scene import build_scene


def _error(crs) -> str:
    with pytest.raises(ConfigError) as exc:
        parse_scene(utm_scene_data(crs))
    message = str(exc.value)
    assert "\n" not in message and message.startswith("crs = ")
    return message


@pytest.mark.parametrize("given", [32631, "EPSG:32631", " epsg:32631 "])
def test_an_epsg_code_gives_the_utm_zone(given):
    from pyproj import CRS

    config = parse_scene(utm_scene_data(given))
    scene = build_scene(config)
    assert scene.crs == CRS.from_epsg(32631)
    assert scene.crs.is_projected and scene.crs.utm_zone == "31N"


def test_wkt_is_taken_as_the_crs():
    from pyproj import CRS

    wkt = CRS.from_epsg(32631).to_wkt()
    assert build_scene(parse_scene(utm_scene_data(wkt))).crs.equals(CRS.from_epsg(32631))


def test_a_compound_crs_with_a_vertical_datum_is_taken():
    scene = build_scene(parse_scene(utm_scene_data("EPSG:32631+5703")))
    assert scene.crs.is_compound and scene.crs.sub_crs_list[1].is_vertical


def test_a_scene_without_crs_has_none():
    config = parse_scene(utm_scene_data(None))
    assert config.crs is None and build_scene(config).crs is None


def test_a_geographic_crs_is_refused_for_the_world_frame():
    message = _error("EPSG:4326")
    assert "geographic" in message and "must be projected, in metres" in message


def test_a_crs_in_feet_is_refused():
    message = _error(2227)  # NAD83 / California zone 3 (ftUS)
    assert "US survey foot" in message and "metres" in message


@pytest.mark.parametrize("bad", ["EPSG:99999", "not a crs", True, 3.5, [32631]])
def test_an_unknown_crs_is_one_line_naming_crs(bad):
    message = _error(bad)
    assert "must be a projected coordinate system in metres" in message


def test_validate_exits_2_on_a_geographic_crs(tmp_path, capsys):
    path = tmp_path / "geo.yaml"
    path.write_text(yaml.safe_dump(utm_scene_data("EPSG:4326")))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "error: crs = 'EPSG:4326'" in err


def test_the_summary_names_the_crs(tmp_path):
    from scanner_sim.survey.pipeline import run_pass
    from scanner_sim.survey.setup import PassOptions

    options = PassOptions(max_pulses=300, fidelity="fast", progress=False, render=False, write_scene=False)
    run_pass(parse_scene(utm_scene_data(32631)), tmp_path, options)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["settings"]["crs"] == "EPSG:32631"
    block = summary["provenance"]["crs"]
    assert block["given"] == 32631 and block["name"] == "WGS 84 / UTM zone 31N" and "UTM zone 31N" in block["wkt"]
