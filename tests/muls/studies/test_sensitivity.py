"""A water's unknown phase function: its spec, the tables built per phase function, and the band of the echo over a
family of phase functions (muls/water/phase_family.py, muls/montecarlo/tables.py, muls/studies/sensitivity.py,
``muls sensitivity``)."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from muls import mul2023, water_preset
from muls.cli import main
from muls.infra.errors import ParameterError
from muls.montecarlo import tables as tables_module
from muls.montecarlo.scattering_tables import tables_key
from muls.montecarlo.tables import find_tables
from muls.optics.optical_model import OpticalModel
from muls.presets import study_water
from muls.studies.sensitivity import echo_quantities, sensitivity_study
from muls.water.phase import fournier_forand, henyey_greenstein, petzold
from muls.water.phase_family import (
    SENSITIVITY_FAMILY,
    fournier_forand_backscatter_ratio,
    fournier_forand_for_backscatter,
    fournier_forand_member,
    phase_from_spec,
    phase_spec,
)

#: A small run for the tests: the pond (the paper's water), three members spanning b_b/b, few packets.
TEST_PACKETS = 10_000
TEST_RANGES_M = (4.0, 10.0, 16.0)


def test_fournier_forand_backscatter_ratio_in_closed_form_matches_the_integral_of_the_tabulated_function():
    """Two engines: the closed form of b_b/b against 2 pi int_{pi/2}^{pi} p sin(theta) of the tabulated function;
    and Petzold's pair (n 1.10, mu 3.5835) gives Petzold's 0.0183, the Ocean Optics Web Book's (1.08, 3.483) 0.01."""
    for n, mu in ((1.10, 3.5835), (1.05, 3.3), (1.15, 4.2)):
        assert fournier_forand_backscatter_ratio(n, mu) == pytest.approx(fournier_forand(n, mu).backscatter_fraction,
                                                                         rel=2e-3)
    assert fournier_forand_backscatter_ratio(1.10, 3.5835) == pytest.approx(0.0183, abs=1e-4)
    assert fournier_forand_backscatter_ratio(1.08, 3.483) == pytest.approx(0.010, abs=2e-4)
    n, mu = fournier_forand_for_backscatter(0.0183)
    assert (n, mu) == (pytest.approx(1.10, abs=2e-3), pytest.approx(3.5835, abs=2e-2))


def test_a_spec_names_its_phase_function_and_a_bad_one_is_refused_by_name():
    assert phase_from_spec("petzold") is petzold()
    assert phase_from_spec(phase_spec("henyey_greenstein", g=0.9)).mean_cosine == pytest.approx(0.9, abs=1e-3)
    assert phase_spec("fournier_forand", n=1.1, mu=3.5835) == phase_spec("fournier_forand", mu=3.58350, n=1.100)
    for bad in ("", "mie", "henyey_greenstein:g", "henyey_greenstein:q=0.9", "henyey_greenstein:g=1.5"):
        with pytest.raises(ParameterError, match="phase|g ="):
            phase_from_spec(bad)
    with pytest.raises(ParameterError, match="phase_function"):
        replace(water_preset("pond"), phase_function="mie")


def test_each_phase_function_has_its_own_tables_and_the_default_keeps_the_shipped_ones():
    """The key of a table names its phase function: another one never reads Petzold's table; Petzold's key is the
    one the package ships (a preset finds its tables without a run)."""
    geometry, pond = mul2023().geometry, water_preset("pond")
    key = tables_key(geometry, pond)
    assert tables_key(geometry, pond, phase="petzold") == key
    assert find_tables(geometry, pond) is not None
    keys = {tables_key(geometry, replace(pond, phase_function=m.spec)) for m in SENSITIVITY_FAMILY}
    assert len(keys) == len(SENSITIVITY_FAMILY) and key in keys
    assert tables_key(geometry, pond, packets=20_000) != key


def test_the_column_backscatter_follows_the_phase_function_where_none_is_measured():
    """A water without a measured beta(pi): b p(pi) of its own phase function; with one, the measurement."""
    pond = water_preset("pond")
    hg = replace(pond, phase_function=phase_spec("henyey_greenstein", g=0.85))
    assert hg.beta_pi_per_m_sr == pytest.approx(pond.scattering_per_m * henyey_greenstein(0.85).value_at_pi_per_sr)
    assert pond.beta_pi_per_m_sr == pytest.approx(pond.scattering_per_m * petzold().value_at_pi_per_sr)
    harbour = water_preset("turbid_harbor")
    assert replace(harbour, phase_function=hg.phase_function).beta_pi_per_m_sr == harbour.beta_pi_per_m_sr


def test_a_flat_plate_echo_in_clear_water_has_the_lidar_equation_energy_and_no_delay():
    """In a water that absorbs but does not scatter the echo is Eq. 7 with k = a: energy E_t A_r eta (rho/pi) O
    exp(-2 a R) / R^2, computed here by hand; its peak is the pulse's own, on the straight path (delay 0)."""
    from muls import Water

    ins = mul2023()
    water = Water("clear", 0.05, 0.0)
    r = np.array([5.0, 12.0])
    q = echo_quantities(OpticalModel.build(ins, water), r, 0.1)
    rx, tx = ins.receiver, ins.transmitter
    eta = tx.efficiency * rx.efficiency * (1.0 - rx.window_reflectance) ** 2
    expected = (tx.pulse_energy_j * rx.area_m2 * eta * 0.1 / math.pi * ins.geometry.overlap(r) * np.exp(-0.1 * r)
                / r**2)
    np.testing.assert_allclose(q["echo_energy_j"], expected, rtol=1e-9)
    np.testing.assert_allclose(q["echo_delay_ns"], 0.0, atol=0.03)
    assert np.all(q["column_w"] == 0.0)


#: Petzold and Fournier-Forand at b_b/b 0.005 and 0.025: the ends of the published range, and the default.
SMALL_FAMILY = (SENSITIVITY_FAMILY[0], fournier_forand_member(0.005, "test"), fournier_forand_member(0.025, "test"))


@pytest.fixture(scope="module")
def table_cache(tmp_path_factory):
    """The Monte Carlo's user cache in a temporary folder for this file's quick table runs."""
    folder = tmp_path_factory.mktemp("tables")
    saved = tables_module.user_cache_dir
    tables_module.user_cache_dir = lambda: folder
    yield folder
    tables_module.user_cache_dir = saved


@pytest.fixture(scope="module")
def small_band(table_cache):
    """The pond's band at three ranges over :data:`SMALL_FAMILY` (10,000 packets a member)."""
    return sensitivity_study("pond", TEST_RANGES_M, packets=TEST_PACKETS, family=SMALL_FAMILY)


def test_the_band_contains_the_model_s_default(small_band):
    """The default the model gives a pass (Petzold's tables, found as any pass finds them) lies within the band of
    every quantity at every range."""
    model = OpticalModel.build(mul2023(), study_water("pond"))
    default = echo_quantities(model, np.array(TEST_RANGES_M), 0.1)
    for j, row in enumerate(small_band["ranges"]):
        for q, v in default.items():
            assert row[q]["min"] <= float(f"{v[j]:.5g}") <= row[q]["max"], (q, row["range_m"])
            assert row[q]["default"] == pytest.approx(v[j], rel=1e-4)


def test_a_more_forward_peaked_phase_function_gives_a_stronger_echo_at_10_m(small_band):
    """Expected from single scattering, not from the code: a narrow beam seen by a narrow receiver loses the light a
    scattering event throws out of the receiver's view; light scattered by a small angle stays within it and still
    comes back. Along the Fournier-Forand line a lower b_b/b (larger, softer particles) puts more of b into the
    forward peak (here 41 % of it within 0.01 rad at b_b/b 0.005, 14 % at 0.025), so less light leaves the view per
    metre, the effective attenuation lies nearer a than c, and the echo at 10 m is stronger. Its backscatter is
    lower too, so the column is weaker."""
    assert fournier_forand(*fournier_forand_for_backscatter(0.005)).forward_fraction(0.01) > 0.35
    row = next(r for r in small_band["ranges"] if r["range_m"] == 10.0)
    members = small_band["members"]
    i = small_band["ranges"].index(row)
    forward, backward = members["FF b_b/b 0.005"], members["FF b_b/b 0.025"]
    assert forward["echo_energy_j"][i] > 1.2 * backward["echo_energy_j"][i]
    assert forward["echo_peak_w"][i] > backward["echo_peak_w"][i]
    assert forward["column_w"][i] < backward["column_w"][i]
    assert row["echo_energy_j"]["max_member"] == "FF b_b/b 0.005"


def test_the_band_is_wider_than_the_monte_carlo_noise(small_band):
    """Even at 10,000 packets a member the spread of the echo energy over b_b/b 0.005-0.025 is many times the run's
    own relative error: the band is the phase function's, not the noise's."""
    for row in small_band["ranges"]:
        spread = row["echo_energy_j"]["spread"] - 1.0
        assert spread > 5.0 * row["mc_rel_err_max"], row


def test_the_study_says_which_phase_function_it_used_and_that_it_computed_a_band(small_band):
    assert small_band["band"] is True and small_band["phase_function"].startswith("petzold (default)")
    assert [m["label"] for m in small_band["phase_functions"]][0] == "Petzold (default)"
    assert all(m["source"] for m in small_band["phase_functions"])
    assert small_band["ranges"][0]["echo_energy_j"]["moved_most_by"] == "b_b/b (Fournier-Forand)"


def test_the_family_has_at_least_five_sourced_members_starting_with_the_default():
    assert len(SENSITIVITY_FAMILY) >= 5 and SENSITIVITY_FAMILY[0].spec == "petzold"
    ratios = [phase_from_spec(m.spec).backscatter_fraction for m in SENSITIVITY_FAMILY if m.label.startswith("FF")]
    assert min(ratios) == pytest.approx(0.005, rel=0.01) and max(ratios) == pytest.approx(0.025, rel=0.01)
    assert all("(19" in m.source or "(20" in m.source for m in SENSITIVITY_FAMILY)


def test_the_pond_experiment_carries_the_detected_fraction_s_band_per_channel_and_distance(small_band):
    """Run once per phase function (the same tables as the band above): the default column is the experiment's own
    prediction, and the most forward-peaked member, with the strongest echo, detects CH3's 11.5 m panel at least as
    often as the least."""
    from muls.studies.bands import experiment_band
    from muls.studies.experiment import experiment_study

    band = experiment_band("pond", shots=60, family=SMALL_FAMILY, packets=TEST_PACKETS)
    default = experiment_study("pond", shots=60, waveforms=False)["distances"]
    assert band["phase_function"] == "petzold (default)" and band["band"] is True
    for d in ("8.5", "10", "11.5"):
        for ch in ("ch1", "ch2", "ch3"):
            b = band["distances"][d][ch]["detected_fraction"]
            assert b["default"] == default[d][ch]["detected_fraction"]
            assert b["low"] <= b["median"] <= b["high"] and b["low"] <= b["default"] <= b["high"]
    members = band["members"]
    assert members["FF b_b/b 0.005"]["11.5"]["ch3"] >= members["FF b_b/b 0.025"]["11.5"]["ch3"]


@pytest.mark.parametrize("argv, key", [
    (["--water", "lake"], "--water"),
    (["--c-per-m", "1.0"], "--c-per-m"),
    (["--c-per-m", "0.5", "--a-per-m", "0.8"], "absorption"),
    (["--water", "pond", "--c-per-m", "1.0", "--a-per-m", "0.2"], "--water"),
    (["--packets", "10"], "packets"),
])
def test_bad_sensitivity_arguments_exit_2_with_one_line_naming_the_key(argv, key, capsys, tmp_path):
    out = tmp_path / "s.png"
    assert main(["sensitivity", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0]
    assert not out.exists()


@pytest.mark.slow
def test_muls_sensitivity_pond_json_lists_the_band_per_range_over_the_family(capsys, tmp_path):
    """The acceptance command: per range 2-20 m, the band of the echo energy and peak over >= 5 phase functions with
    their sources. At 10,000 packets a member's table (the default, 50,000, only narrows each member's Monte Carlo
    error, 0.6-1.2 % of the echo energy against bands of a factor 5 or more): the whole family's tables are built
    here on a fresh machine, a fifth of the default's Monte Carlo."""
    assert main(["sensitivity", "--water", "pond", "--packets", str(TEST_PACKETS), "--json",
                 "--out", str(tmp_path / "s.png")]) == 0
    result = json.loads(capsys.readouterr().out)
    assert [row["range_m"] for row in result["ranges"]] == [float(r) for r in range(2, 21)]
    assert len(result["phase_functions"]) >= 5 and all(m["source"] for m in result["phase_functions"])
    for row in result["ranges"]:
        for q in ("echo_energy_j", "echo_peak_w"):
            assert row[q]["min"] <= row[q]["default"] <= row[q]["max"]
            assert row[q]["min"] <= row[q]["median"] <= row[q]["max"]
    assert (tmp_path / "s.png").is_file()


@pytest.mark.slow
def test_the_pond_s_unknowns_each_move_the_prediction_the_expected_way(small_band):
    """Opening CH3's gate earlier can only add CH3 detections at 8.5 and 10 m (their echoes start before the
    100 ns gate opens: 76.9 and 90.5 ns); a wider tolerance counts every detection a narrower one does; the near
    channels never see the gate. All together the count is at least any single unknown's."""
    from muls.studies.pond_unknowns import pond_unknowns_study

    result = pond_unknowns_study(shots=60, family=SMALL_FAMILY, packets=TEST_PACKETS)
    cases = {(c["unknown"], c["setting"]): c["detected"] for c in result["cases"]}
    default = cases[("none", "the model's defaults")]
    gate = [v for (u, _), v in cases.items() if u == "gate reference"]
    for d in ("8.5", "10", "11.5"):
        for ch in ("ch1", "ch2"):
            assert all(g[d][ch] == default[d][ch] for g in gate)
    assert gate[-1]["8.5"]["ch3"] >= default["8.5"]["ch3"] and gate[-1]["10"]["ch3"] >= default["10"]["ch3"]
    wide = cases[("detection criterion", "within 10 range bins")]
    assert all(wide[d][ch] >= default[d][ch] for d in default for ch in default[d])
    together = result["cases"][-1]
    assert together["unknown"] == "all together"
    total = sum(f for chans in together["detected"].values() for f in chans.values())
    assert total >= max(sum(f for chans in v.values() for f in chans.values()) for v in cases.values()) - 0.1
    assert result["phase_function"] == "petzold (default)" and result["band"] is True


def test_a_band_leaves_out_members_without_a_value_and_names_its_ends():
    """A member with no maximum range (None: nothing detectable) is not a range of 0 m: the band is over the others;
    the default is the first member's value, whatever its place in the band."""
    from muls.studies.bands import band

    b = band([4.2, None, 6.0, 3.1], ["default", "a", "b", "c"], 3)
    assert (b["low"], b["median"], b["high"], b["default"]) == (3.1, 4.2, 6.0, 4.2)
    assert (b["low_member"], b["high_member"]) == ("c", "b")
    assert band([None, None], ["default", "a"])["low"] is None
