"""muls multiscatter and muls multiscatter-study: JSON keys, pictures, one-line errors."""

import json

import pytest

from muls import water_preset
from muls.cli import main


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_multiscatter_json_has_exactly_the_issue_keys_and_a_picture(capsys, tmp_path):
    png = tmp_path / "ms.png"
    code, out, err = _run(capsys, "multiscatter", "--water", "coastal_ocean", "--range-m", "6", "--packets", "20000",
                          "--json", "--out", str(png))
    assert code == 0, err
    r = json.loads(out)
    assert set(r) == {"time_ns", "mc_w", "mc_rel_err", "muls_w", "target", "column_peak_ratio",
                      "effective_attenuation_per_m", "packets", "seconds"}
    assert len(r["time_ns"]) == len(r["mc_w"]) == len(r["mc_rel_err"]) == len(r["muls_w"])
    assert set(r["target"]) == {"mc_energy_j", "muls_energy_j", "ratio"}
    assert r["target"]["ratio"] == pytest.approx(r["target"]["mc_energy_j"] / r["target"]["muls_energy_j"])
    water = water_preset("coastal_ocean")
    assert water.kd_estimate_per_m * 0.8 < r["effective_attenuation_per_m"] < water.attenuation_per_m
    assert r["packets"] == 20000
    assert png.stat().st_size > 20_000


def test_multiscatter_table_and_coaxial_geometry(capsys):
    code, out, err = _run(capsys, "multiscatter", "--water", "pool", "--range-m", "8", "--geometry", "coaxial",
                          "--packets", "20000", "--no-plot")
    assert code == 0, err
    assert "coaxial" in out and "MC/MULS" in out and "effective attenuation" in out


@pytest.mark.parametrize("argv, key", [
    (["multiscatter", "--water", "mud", "--range-m", "5"], "--water"),
    (["multiscatter", "--water", "pond", "--range-m", "-1"], "--range-m"),
    (["multiscatter", "--water", "pond", "--range-m", "5", "--geometry", "biaxial"], "--geometry"),
    (["multiscatter", "--water", "pond", "--range-m", "5", "--packets", "0"], "--packets"),
])
def test_multiscatter_bad_arguments_exit_2_with_one_line(capsys, argv, key):
    code, out, err = _run(capsys, *argv)
    assert code == 2 and out == ""
    assert key in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_multiscatter_study_writes_its_chart_and_json(capsys, tmp_path):
    out_dir = tmp_path / "study"
    code, out, err = _run(capsys, "multiscatter-study", "--waters", "turbid_harbor", "--packets", "20000",
                          "--out", str(out_dir))
    assert code == 0, err
    assert "turbid_harbor" in out and "R_det" in out
    assert (out_dir / "multiscatter_study.png").stat().st_size > 20_000
    saved = json.loads((out_dir / "multiscatter_study.json").read_text())
    assert saved["settings"]["waters"] == ["turbid_harbor"]
