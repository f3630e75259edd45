"""muls multiscatter and muls multiscatter-study: JSON keys, pictures, one-line errors."""

import json

import numpy as np
import pytest
from conftest import run_muls as _run

from muls import water_preset
from muls.validation.check import worst_errors


def test_multiscatter_json_has_exactly_the_issue_keys_and_a_picture(capsys, tmp_path):
    png = tmp_path / "ms.png"
    code, out, err = _run(capsys, "multiscatter", "--water", "coastal_ocean", "--range-m", "6", "--packets", "20000",
                          "--json", "--out", str(png))
    assert code == 0, err
    r = json.loads(out)
    assert set(r) == {"time_ns", "mc_w", "mc_rel_err", "muls_w", "mc_column_w", "mc_column_rel_err", "mc_target_w",
                      "mc_target_rel_err", "target", "column_peak_ratio", "effective_attenuation_per_m", "packets",
                      "seconds"}
    n = len(r["time_ns"])
    assert all(len(r[k]) == n for k in ("mc_w", "mc_rel_err", "muls_w", "mc_column_w", "mc_column_rel_err",
                                        "mc_target_w", "mc_target_rel_err"))
    # the parts add up to the total, bin by bin (each rounded to 6 significant digits: 5e-6 each)
    total = np.array(r["mc_column_w"]) + np.array(r["mc_target_w"])
    np.testing.assert_allclose(total, r["mc_w"], rtol=1.1e-5, atol=1e-9 * max(r["mc_w"]))
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


@pytest.mark.slow
def test_pond_at_10_m_column_and_echo_within_5_percent_where_within_100_times_of_their_peaks(capsys):
    """The issue's acceptance: ``muls multiscatter --water pond --range-m 10 --json`` (default packets) has the
    column and the target echo at a relative error below 5 % wherever each is within 100 times of its peak
    (the check of ``python3 -m muls.validation.check``).

    Root cause of the failure this pins (10 % at 4 million packets, median 4.9 %): the column's error came
    from rare packets. A packet that scattered back towards the instrument outside the ghosts' narrow cone
    launched ghosts a hundred times heavier than the usual ones, and ghosts landing in the aperture through
    the forward cone were counted one by one; their variance grew with the number of packets. The wide
    ghost cone, the forward cone's own estimate, splitting of heavy aimed ghosts and more ghosts from near
    events (muls.montecarlo.transport) removed those tails."""
    code, out, err = _run(capsys, "multiscatter", "--water", "pond", "--range-m", "10", "--json", "--no-plot")
    assert code == 0, err
    worst = worst_errors(json.loads(out))
    assert worst["column"]["max_rel_err"] < 0.05, worst["column"]
    assert worst["target"]["max_rel_err"] < 0.05, worst["target"]
    assert worst["column"]["bins"] > 50 and worst["target"]["bins"] > 50
