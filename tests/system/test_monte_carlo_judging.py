"""Comparisons with the Monte Carlo say when they cannot judge, and refuse what no comparison can mean."""

import json

import pytest

from muls import instrument_preset
from muls.cli import main
from muls.validation.validate import MAX_MC_REL_ERR


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_validate_pass_with_one_packet_is_refused_not_within(capsys, tmp_path):
    """``muls validate-pass --waters pond --packets 1`` exited 0 and printed ratios such as 3.6e21 marked "within: yes".

    Root cause: a case whose Monte Carlo error was over the 3 % limit was exempt from the acceptance and printed as
    within, so a run that could judge nothing passed every case. Such a case is now "not judged", and a packet count
    under which every case's error is over the limit (the error falls as 1/sqrt(packets), 0.28 % at best with
    400,000) is refused up front."""
    from muls.validation.validate import judge

    code, out, err = _run(capsys, "validate-pass", "--waters", "pond", "--packets", "1")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "--packets = 1: at least 3,500" in err
    # the case the issue printed: ratios of 3.6e21 at a Monte Carlo error of 195 % are neither within nor out
    assert judge({"echo_energy_ratio": 3.856e21, "echo_peak_ratio": 1.93e21, "column_ratio": 1.754,
                  "mc_rel_err": 1.9544}) is None
    assert judge({"echo_energy_ratio": 1.0, "echo_peak_ratio": 1.0, "column_ratio": 1.0, "mc_rel_err": None}) is None
    assert judge({"echo_energy_ratio": 1.5, "echo_peak_ratio": 1.0, "column_ratio": 1.0,
                  "mc_rel_err": MAX_MC_REL_ERR / 2}) is False


def test_validate_pass_json_where_the_monte_carlo_saw_no_light_is_valid_json(capsys):
    """``validate-pass --json`` failed with "Out of range float values are not JSON compliant" where a Monte Carlo
    quantity saw no light (its relative error 0/0 = inf). Root cause: the error was kept as ``inf``; it is now null,
    and the case not judged. With 4,000 packets in the pool (errors of 2.6 % at 5 and 10 m, the plate at 2 m catching
    no column light in 0-50 ns) the cases near 3 % are judged and the uncertain ones are not."""
    code, out, err = _run(capsys, "validate-pass", "--waters", "pool", "--packets", "4000", "--json")
    assert code == 0, err

    def refuse(constant):
        raise AssertionError(f"{constant} in JSON")

    cases = json.loads(out, parse_constant=refuse)["cases"]
    for case in cases:
        uncertain = case["mc_rel_err"] is None or case["mc_rel_err"] >= MAX_MC_REL_ERR
        assert (case["within"] is None) == uncertain, case
    assert any(c["within"] is None for c in cases) and any(c["within"] is True for c in cases)


@pytest.mark.parametrize("range_m", ["1e-6", "1.0"])
def test_multiscatter_plate_in_the_blind_zone_is_refused(capsys, range_m):
    """``muls multiscatter --range-m 1e-6`` printed a table of zeros with exit 0 (1.0 m: an internal error). Root
    cause: only the far end of the range was checked; with the MUL's receiver 130 mm beside the beam, a plate closer
    than the blind zone (1.68 m, where the beam enters the field of view) returns nothing to MULS's model and the
    ratios are 0/0. Such a range is refused, naming the blind zone and the coaxial geometry that has none."""
    blind_m = instrument_preset("mul2023").geometry.blind_zone_m
    assert 1.6 < blind_m < 1.7
    code, out, err = _run(capsys, "multiscatter", "--water", "pond", "--range-m", range_m, "--packets", "2000")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1
    assert f"--range-m = {float(range_m)!r}" in err and "blind zone" in err and f"{blind_m:.2f} m" in err
    # the coaxial geometry has no blind zone: the same plate is a meaningful study there
    code, out, err = _run(capsys, "multiscatter", "--water", "pond", "--range-m", range_m, "--packets", "2000",
                          "--geometry", "coaxial", "--json")
    assert code == 0, err
    assert 0.9 < json.loads(out)["target"]["ratio"] < 1.1


def test_mobley1993_value_whose_two_sigma_exceeds_the_codes_range_is_not_judged():
    """``muls mobley1993 --photons 100`` marked problem 2's Eou at tau 1 (0.001241, 2 standard errors 102 %) "yes":
    the band [paper_min - 2 sigma, paper_max + 2 sigma] was twelve times the codes' own range (0.000914-0.001018), so
    almost any value was within. Root cause: a Monte Carlo too uncertain to judge widened the band instead of saying
    so. Such a value is now not judged (None); the default run's values (2 sigma of 0.01 % to 3 %) are all judged."""
    from muls.validation.mobley1993 import judge

    assert judge(0.001241, 0.5 * 1.0207 * 0.001241, 0.000914, 0.001018) is None
    assert judge(0.0, 0.0, 0.000914, 0.001018) is None  # no photon: no spread to judge by
    assert judge(0.1621, 0.5 * 0.0001 * 0.1621, 0.1613, 0.1627) is True  # the default run's problem 2, 0.2, Ed
    assert judge(0.1700, 0.5 * 0.0001 * 0.1621, 0.1613, 0.1627) is False
