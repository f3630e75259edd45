"""A campaign over custom waters (mappings of optical properties) names each apart in its table and charts."""

import csv
import json

import yaml

from scanner_sim.cli import main

#: Two custom waters, a clear and a murky one (absorption and scattering [1/m]).
CLEAR = {"absorption_per_m": 0.05, "scattering_per_m": 0.05}
MURKY = {"absorption_per_m": 0.3, "scattering_per_m": 1.0}


def test_campaign_over_two_custom_waters_names_them_apart(tmp_path):
    """Two custom waters swept against the far channel's gate delay: campaign.csv named both ``pool_panel_water`` and the
    chart drew them as one line.

    Root cause: a row took the axis values first and then the pass summary's figures, whose ``water`` (the resolved
    water's name, ``SCENE_water`` for every custom water of the scene) replaced the axis's value. The axis columns
    now keep their values, a custom water by its sweep label (its position in the axis, as its folder shows it)."""
    path = tmp_path / "waters.yaml"
    path.write_text(yaml.safe_dump({
        "format_version": 1, "scene": "pool_panel",
        "sweep": {"water": [CLEAR, MURKY], "instrument.gate_delay_ns": [0, 20]},
        "options": {"max_pulses": 20, "render": False},
        "charts": [{"x": "instrument.gate_delay_ns", "lines": "water", "y": "points_per_pulse"}]}, sort_keys=False))
    assert main(["campaign", str(path), "--workers", "0", "--quiet", "--out", str(tmp_path / "out")]) == 0
    rows = list(csv.DictReader((tmp_path / "out" / "campaign.csv").open()))
    assert [(r["water"], r["dir"].split("__")[0]) for r in rows] == [
        ("v1", "water=v1"), ("v1", "water=v1"), ("v2", "water=v2"), ("v2", "water=v2")]
    result = json.loads((tmp_path / "out" / "campaign.json").read_text())
    assert [p["values"]["water"] for p in result["passes"]] == [CLEAR, CLEAR, MURKY, MURKY]
    # the murky water returns less light: the two waters' passes differ, so merging them would hide a difference
    clear, murky = (float(rows[0]["points_per_pulse"]), float(rows[2]["points_per_pulse"]))
    assert clear >= murky
