"""scanner-sim features (scanner_sim/studies/features.py): cubes placed across the swath, detected by the stated
rule; detection does not fall as cubes grow and falls from clean to turbid water at the same altitude."""

import json

import pytest

from scanner_sim.cli import main
from scanner_sim.config import load_scene
from scanner_sim.metrics import s44
from scanner_sim.studies.features import run_features

# 60,000 pulses fly 7.2 m of cable_survey's track (12 m swath at 6 m): room for 4 cubes of each size apart
PULSES, COUNT = 60000, 4


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    out = tmp_path_factory.mktemp("clean")
    return run_features(load_scene("cable_survey"), out, (0.5, 1.0, 2.0), COUNT, 3, "clean_ocean",
                        max_pulses=PULSES, render=False)


@pytest.fixture(scope="module")
def turbid(tmp_path_factory):
    out = tmp_path_factory.mktemp("turbid")
    code = main(["features", "cable_survey", "--cubes-m", "0.5", "1", "2", "--water", "turbid_harbor", "--count",
                 str(COUNT), "--seed", "3", "--max-pulses", str(PULSES), "--out", str(out), "--json"])
    assert code == 0
    return json.loads((out / "features.json").read_text()), out


def test_features_json_has_cubes_per_size_and_the_rule(turbid):
    result, out = turbid
    assert list(result["cubes"]) == ["0.5", "1", "2"]
    for c in result["cubes"].values():
        assert c["placed"] == COUNT and 0 <= c["detected"] <= c["reached"] <= COUNT
        assert c["reached"] == COUNT - c["not_reached"] - c["shadowed"]
        assert c["fraction"] == pytest.approx(c["detected"] / c["reached"])
        # the rule, counted again from the soundings of each cube
        assert c["detected"] == sum(n >= s44.FEATURE_MIN_SOUNDINGS for n in c["valid_soundings"])
    assert result["rule"]["min_valid_soundings"] == s44.FEATURE_MIN_SOUNDINGS and "S-44" in result["rule"]["source"]
    assert (out / "features.png").stat().st_size > 10_000


def test_same_seed_places_the_same_cubes_in_any_water(clean, turbid):
    assert [(p["x_m"], p["y_m"], p["size_m"]) for p in clean["placements"]] == \
        [(p["x_m"], p["y_m"], p["size_m"]) for p in turbid[0]["placements"]]


def test_detection_does_not_fall_as_cubes_grow(clean, turbid):
    for result in (clean, turbid[0]):
        fractions = [c["fraction"] for c in result["cubes"].values()]
        assert fractions == sorted(fractions)


def test_detection_falls_from_clean_to_turbid_water(clean, turbid):
    c, t = clean["cubes"], turbid[0]["cubes"]
    assert sum(v["detected"] for v in t.values()) < sum(v["detected"] for v in c.values())
    assert t["0.5"]["fraction"] < c["0.5"]["fraction"]
    # every cube gets fewer valid soundings in turbid water (the same cubes, the same pulses)
    assert all(sum(t[k]["valid_soundings"]) < sum(c[k]["valid_soundings"]) for k in c)


def test_a_cube_too_big_for_the_swath_is_refused_in_one_line(tmp_path, capsys):
    assert main(["features", "cable_survey", "--cubes-m", "20", "--max-pulses", "1000", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cubes_m" in err[0]


def test_coverage_study_gains_feature_detection_per_size(tmp_path):
    from scanner_sim.studies.coverage_study import CubePlan, StudyPlan, run_study

    study = run_study(load_scene("cable_survey"), StudyPlan(waters=("clean_ocean",), instruments=("mul2023",)),
                      tmp_path / "study", max_pulses=PULSES, render=False, progress=False,
                      cubes=CubePlan((1.0, 2.0), 2, 5))
    assert [c["size_m"] for c in study["cubes"]] == [2.0, 2.0, 1.0, 1.0]
    (record,) = study["records"]
    assert list(record["features"]) == ["1", "2"]
    by_name = {o["name"]: o for o in record["objects"]}
    for size, row in record["features"].items():
        cubes = [by_name[c["name"]] for c in study["cubes"] if f"{c['size_m']:g}" == size]
        assert row["placed"] == 2 and row["detected"] == sum(o["valid_points"] >= 5 for o in cubes)
    assert "## Feature detection" in (tmp_path / "study" / "coverage.md").read_text()


def test_campaign_table_gains_feature_detection_per_size(tmp_path):
    import csv

    from scanner_sim.runs.campaign import parse_campaign, run_campaign

    campaign = parse_campaign({"scene": "cable_survey", "sweep": {"water": ["clean_ocean", "turbid_harbor"]},
                               "options": {"max_pulses": PULSES, "render": False, "cubes_m": [0.5, 2.0],
                                           "cube_count": 2, "cube_seed": 3}})
    result = run_campaign(campaign, tmp_path / "c", progress=False)
    assert [c["size_m"] for c in result["cubes"]] == [2.0, 2.0, 0.5, 0.5]
    rows = list(csv.DictReader((tmp_path / "c" / "campaign.csv").open()))
    assert [r["water"] for r in rows] == ["clean_ocean", "turbid_harbor"]
    for row, p in zip(rows, result["passes"]):
        objects = {o["name"]: o for o in p["summary"]["coverage"]["objects"]}
        for size in ("0.5", "2"):
            mine = [objects[c["name"]] for c in result["cubes"] if f"{c['size_m']:g}" == size]
            assert int(row[f"features.{size}.detected"]) == sum(o["valid_points"] >= 5 for o in mine)
            assert float(row[f"features.{size}.fraction"]) == pytest.approx(int(row[f"features.{size}.detected"]) / 2)
        assert 0.0 <= float(row["coverage.orders.exclusive.compliant_fraction"]) <= 1.0
