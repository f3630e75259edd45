"""The Monte Carlo's transport core against a published benchmark: problems 1 and 2 of Mobley et al. (1993)
(``muls mobley1993``), and the plane-parallel transport it runs (:mod:`muls.montecarlo.slab`) against closed
forms: Beer's law, single scattering, Gershun's law, the energy budget."""

import json
import math

import numba
import numpy as np
import pytest
from conftest import run_muls as _run
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import simpson

from muls.montecarlo import run_slab
from muls.montecarlo.slab import ENERGY_KEYS, TALLIES, fresnel_reflectance
from muls.validation.mobley1993 import ALBEDOS, OPTICAL_DEPTHS, QUANTITIES, codes_range, paper_rows, parse_printed
from muls.water.phase import (
    MOBLEY1993_PARTICLE_PER_SR,
    MOBLEY1993_PRINTED_0_50119_PER_SR,
    MOBLEY1993_SMALL_ANGLE_SLOPE,
    PETZOLD_ANGLES_DEG,
    phase_function,
)

#: Statistical comparisons allow this many standard errors.
SIGMAS = 3.5
N_WATER = 1.34  # Mobley et al. (1993) Section 3
MU_SUN = math.cos(math.radians(60.0))  # the sun at 60 deg (Section 3)
MU_W = math.sqrt(1.0 - (1.0 - MU_SUN**2) / N_WATER**2)  # Snell
#: Irradiance the refracted sun carries across a horizontal plane just below the surface, per E_perp.
E_IN = MU_SUN * (1.0 - fresnel_reflectance(MU_SUN, N_WATER))


# ----------------------------------------------------------------------------------------------------------
# The surface and the published inputs


def test_fresnel_reflectance_closed_forms():
    normal = ((N_WATER - 1.0) / (N_WATER + 1.0)) ** 2  # 0.0211: the paper's L(180)/L(0) at tau = 0 is 0.021
    assert fresnel_reflectance(1.0, N_WATER) == pytest.approx(normal, rel=1e-12)
    assert fresnel_reflectance(1.0, 1.0 / N_WATER) == pytest.approx(normal, rel=1e-12)
    critical = math.asin(1.0 / N_WATER)
    assert fresnel_reflectance(math.cos(critical - 1e-6), 1.0 / N_WATER) < 1.0
    assert fresnel_reflectance(math.cos(critical + 1e-6), 1.0 / N_WATER) == 1.0  # total internal reflection
    # reciprocity: the same ray path reflects the same share from either side
    assert fresnel_reflectance(MU_W, 1.0 / N_WATER) == pytest.approx(fresnel_reflectance(MU_SUN, N_WATER), rel=1e-12)
    assert E_IN / MU_SUN > 0.93  # "more than 93% of the incident solar irradiance is transmitted" (Section 4)


def test_mobley1993_particle_table_is_normalised_by_the_papers_rule_and_the_misprint_is_not():
    """The paper divided its table so that the trapezoidal rule over it, plus the power law below 0.1 deg,
    gives exactly 1. With Light and Water's 201.2 at 0.50119 deg that holds to 6e-5 (201.2 has 4 digits, the
    others 6); with the printed 218.839 it is 1.0019: the printed value is the odd one out."""
    theta = np.radians(PETZOLD_ANGLES_DEG)
    cone = 2.0 * math.pi * MOBLEY1993_PARTICLE_PER_SR[0] * theta[0] ** 2 / (2.0 - MOBLEY1993_SMALL_ANGLE_SLOPE)

    def rule(values):
        return np.trapezoid(2.0 * math.pi * values * np.sin(theta), theta) + cone

    assert rule(MOBLEY1993_PARTICLE_PER_SR) == pytest.approx(1.0, abs=1e-4)
    printed = MOBLEY1993_PARTICLE_PER_SR.copy()
    printed[7] = MOBLEY1993_PRINTED_0_50119_PER_SR
    assert rule(printed) == pytest.approx(1.0019, abs=1e-4)
    p = phase_function("mobley1993_particle")
    assert p.raw_integral == pytest.approx(1.0, abs=2e-4)
    np.testing.assert_allclose(p(theta), MOBLEY1993_PARTICLE_PER_SR, rtol=2e-3)  # the table at its own angles
    assert p.backscatter_fraction == pytest.approx(0.0183, rel=0.02)  # Petzold's average (Mobley 1994)


def test_rayleigh_phase_function_is_the_papers_equation_3():
    p = phase_function("rayleigh")
    th = np.array([1e-3, 0.4, 1.0, 0.5 * math.pi, 2.5, math.pi])
    np.testing.assert_allclose(p(th), 3.0 / (16.0 * math.pi) * (1.0 + np.cos(th) ** 2), rtol=1e-5)
    assert p.backscatter_fraction == pytest.approx(0.5, abs=1e-3)
    assert p.mean_cosine == pytest.approx(0.0, abs=1e-3)


def _printed(value: float) -> str:
    mantissa, exponent = f"{value:.2e}".split("e")
    return f"{mantissa}{int(exponent):+d}"


def test_printed_values_parse_with_half_a_unit_of_their_last_digit():
    assert parse_printed("3.66-1") == pytest.approx((0.366, 0.0005))
    assert parse_printed("4.02-9") == pytest.approx((4.02e-9, 5e-12))
    assert parse_printed("0.000") == (0.0, 0.0005)
    with pytest.raises(ValueError, match="3.66"):
        parse_printed("3.66e-1")


@settings(max_examples=300, deadline=None)
@given(st.integers(2, 9).flatmap(lambda n: st.lists(st.floats(1e-9, 1.0), min_size=n, max_size=n)),
       st.integers(-12, 0))
def test_codes_range_holds_every_value_whose_mean_and_spread_are_printed(values, exponent):
    """Samuelson's bound with the rounding of Table 5: whatever N values were averaged, each lies inside the
    range built from the printed mean (3 digits), s/x (3 decimals) and N."""
    x = np.array(values) * 10.0**exponent
    mean, s = x.mean(), x.std(ddof=1)
    lo, hi = codes_range(_printed(mean), f"{s / mean:.3f}", len(x))
    assert lo <= x.min() * (1 + 1e-12) and x.max() <= hi * (1 + 1e-12)


def test_table5_rows_cover_problems_1_and_2():
    rows = paper_rows()
    assert len(rows) == 2 * len(ALBEDOS) * len(QUANTITIES) * len(OPTICAL_DEPTHS) == 36
    assert {(r["problem"], r["albedo"], r["quantity"], r["optical_depth"]) for r in rows} == {
        (p, a, q, t) for p in (1, 2) for a in ALBEDOS for q in QUANTITIES for t in OPTICAL_DEPTHS}
    # the rows whose N is not 7: Lu deep in the absorbing waters (Table 5)
    assert {(r["problem"], r["optical_depth"], r["paper_models"]) for r in rows if r["paper_models"] != 7} == {
        (1, 10.0, 4), (2, 5.0, 6), (2, 10.0, 5)}
    first = next(r for r in rows if (r["problem"], r["albedo"], r["quantity"], r["optical_depth"]) == (1, 0.9, "Ed", 1.0))
    assert first["paper_mean"] == pytest.approx(0.366) and first["paper_rel_sd"] == 0.002
    assert all(r["paper_min"] < r["paper_mean"] < r["paper_max"] for r in rows)


# ----------------------------------------------------------------------------------------------------------
# The plane-parallel transport against closed forms


def test_unscattered_sun_follows_beers_law_exactly():
    """Albedo 0: the refracted sun alone, Ed = E_perp cos(theta_s) T exp(-c z / cos(theta_w)), to rounding."""
    c, depths = 0.7, np.array([0.5, 1.0, 5.0, 10.0])
    r = run_slab("rayleigh", 0.0, depths, attenuation_per_m=c, packets=200, seed=1)
    expected = E_IN * np.exp(-c * depths / MU_W)
    np.testing.assert_allclose(r.mean["Ed"], expected, rtol=1e-12)
    np.testing.assert_allclose(r.mean["Eod"], expected / MU_W, rtol=1e-12)
    for name in ("Eu", "Eou", "Lu"):
        assert not r.mean[name].any()
    assert r.energy["absorbed_by_water"] + r.energy["reflected_by_surface"] == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("phase", ["rayleigh", "mobley1993_particle"])
def test_unscattered_light_in_scattering_water_follows_beers_law(phase):
    """Albedo 0.9, every packet stopped at its first scattering: the light left is exp(-c z / mu_w) of the sun
    in expectation, which holds only if free paths are exponential with mean 1/b and absorption is exp(-a s)."""
    depths = np.array([0.5, 1.0, 3.0, 6.0])
    r = run_slab(phase, 0.9, depths, packets=400_000, seed=2, max_orders=0)
    expected = E_IN * np.exp(-depths / MU_W)
    assert np.all(np.abs(r.mean["Ed"] - expected) <= SIGMAS * r.sigma["Ed"]), (r.mean["Ed"] / expected, r.sigma["Ed"])
    assert not r.mean["Lu"].any() and not r.mean["Eu"].any()


def _single_scattering(phase, weight, depths, b, c=1.0):
    """(K,) light scattered once from the refracted sun and travelling up at ``depths``: E_in b exp(-c z /
    mu_w) / c times the integral over the upward directions (mu, phi) of p(Theta) weight(mu) / (mu + mu_w)
    (Gauss-Legendre in mu, the periodic trapezoidal rule in phi: both converged to 1e-6 here)."""
    p = phase_function(phase)
    nodes, weights = np.polynomial.legendre.leggauss(400)
    mu, w_mu = 0.5 * (nodes + 1.0), 0.5 * weights  # on [0, 1]
    phi = (np.arange(720) + 0.5) * (2.0 * math.pi / 720)
    cos_theta = math.sqrt(1.0 - MU_W**2) * np.sqrt(1.0 - mu[:, None] ** 2) * np.cos(phi) - MU_W * mu[:, None]
    inner = p(np.arccos(np.clip(cos_theta, -1.0, 1.0))).mean(axis=1) * 2.0 * math.pi  # over phi
    integral = float(np.sum(w_mu * inner * weight(mu) / (mu + MU_W)))
    return E_IN * b * np.exp(-c * np.asarray(depths) / MU_W) / c * integral


@pytest.mark.parametrize("phase", ["rayleigh", "mobley1993_particle"])
def test_single_scattering_matches_its_closed_form(phase):
    """Light scattered once (max_orders 1): the nadir radiance is E_in b p(pi - theta_w) exp(-c z / mu_w) /
    (c (1 + mu_w)) (the local estimate's normalisation), and the upward scalar and plane irradiances are its
    integrals over the upward hemisphere (the crossing estimators' 1/|cos| and their cut-off)."""
    depths, albedo = np.array([0.5, 1.0, 2.0, 4.0]), 0.5
    r = run_slab(phase, albedo, depths, packets=1_000_000, seed=3, max_orders=1)
    p_back = float(phase_function(phase)(math.pi - math.acos(MU_W)))
    expected = {"Lu": E_IN * albedo * p_back * np.exp(-depths / MU_W) / (1.0 + MU_W),
                "Eou": _single_scattering(phase, np.ones_like, depths, albedo),
                "Eu": _single_scattering(phase, lambda mu: mu, depths, albedo)}
    for name, value in expected.items():
        err = np.abs(r.mean[name] - value)
        assert np.all(err <= SIGMAS * r.sigma[name] + 2e-3 * value), (name, r.mean[name] / value, r.sigma[name] / value)


@pytest.mark.parametrize("phase", ["rayleigh", "mobley1993_particle"])
def test_single_scattered_light_leaves_through_the_level_surface_by_fresnel(phase):
    """Light scattered once reaches the surface from below with the radiance E_in b p(Theta) / (c (mu + mu_w));
    the share 1 - R(mu) of it leaves (none beyond the critical angle, 48.3 deg from the zenith), the rest is
    reflected down. What escapes is the budget's ``escaped_through_surface`` (a share of E_perp cos theta_s)."""
    albedo = 0.5
    r = run_slab(phase, albedo, [1.0], packets=1_000_000, seed=6, max_orders=1)
    leaves = np.vectorize(lambda mu: 1.0 - fresnel_reflectance(mu, 1.0 / N_WATER))
    expected = _single_scattering(phase, lambda mu: mu * leaves(mu), [0.0], albedo)[0] / MU_SUN
    got, sigma = r.energy["escaped_through_surface"], r.energy_sigma["escaped_through_surface"]
    assert abs(got - expected) <= SIGMAS * sigma + 2e-3 * expected, (got / expected, sigma / expected)
    assert leaves(math.cos(math.asin(1.0 / N_WATER) + 1e-9)) == 0.0


@pytest.mark.parametrize("phase, albedo", [("rayleigh", 0.9), ("mobley1993_particle", 0.2)])
def test_gershun_law_ties_the_plane_and_scalar_irradiances(phase, albedo):
    """d(Ed - Eu)/dz = -a (Eod + Eou): what the net flux loses between two depths is what the water absorbs.
    The plane crossings, the 1/|cos| scalar estimator and the absorption weight must agree, batch by batch
    (Simpson's rule over 0.1 m steps: its error is below 1e-5 of the loss here; the trapezoidal rule's,
    (K h)^2 / 12, would be 1.4e-3 in the absorbing water)."""
    a = 1.0 - albedo
    depths = np.linspace(0.5, 2.5, 21)
    r = run_slab(phase, albedo, depths, packets=200_000, seed=4)
    b = r.per_batch  # (batches, 5, K)
    net = b[:, TALLIES.index("Ed")] - b[:, TALLIES.index("Eu")]
    scalar = b[:, TALLIES.index("Eod")] + b[:, TALLIES.index("Eou")]
    lost = net[:, 0] - net[:, -1]
    absorbed = a * simpson(scalar, x=depths, axis=1)
    diff = lost - absorbed
    se = diff.std(ddof=1) / math.sqrt(diff.size)
    assert abs(diff.mean()) <= SIGMAS * se + 1e-4 * lost.mean(), (diff.mean() / lost.mean(), se / lost.mean())


@pytest.mark.parametrize("phase, albedo", [("rayleigh", 0.9), ("mobley1993_particle", 0.9),
                                           ("mobley1993_particle", 0.2)])
def test_energy_budget_closes(phase, albedo):
    """Reflected by the surface + absorbed + escaped back through it + lost at the bottom + roulette's net
    = the sun's irradiance on the surface, to rounding; roulette's net is zero in expectation."""
    r = run_slab(phase, albedo, [1.0, 5.0, 10.0], packets=100_000, seed=5)
    e = r.energy
    parts = ("reflected_by_surface", "absorbed_by_water", "escaped_through_surface", "passed_bottom", "roulette_net",
             "stopped_at_max_orders")
    assert set(e) == {"reflected_by_surface", *ENERGY_KEYS}
    assert sum(e[k] for k in parts) == pytest.approx(1.0, abs=1e-12)
    assert e["transmitted"] + e["reflected_by_surface"] == pytest.approx(1.0, abs=1e-15)
    assert abs(e["roulette_net"]) < 1e-4 and e["passed_bottom"] < 1e-3 and e["stopped_at_max_orders"] == 0.0
    # upwelling leaves through the surface: more of it the more the water scatters and the more it backscatters
    assert 0.0 < e["escaped_through_surface"] < 0.5


def test_seed_fixes_the_result_whatever_the_thread_count():
    args = ("mobley1993_particle", 0.9, [1.0, 5.0])
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = run_slab(*args, packets=20_000, seed=9)
        numba.set_num_threads(max(2, threads))
        two = run_slab(*args, packets=20_000, seed=9)
    finally:
        numba.set_num_threads(threads)
    other = run_slab(*args, packets=20_000, seed=10)
    assert np.array_equal(one.per_batch, two.per_batch) and one.energy == two.energy
    assert not np.array_equal(one.per_batch, other.per_batch)


def test_seed_fixes_the_result_whatever_the_parts(monkeypatch):
    """A run is traced in parts so that a signal can end it (muls.montecarlo.run.in_parts): one packet a part
    gives the same tallies to the bit as the run in one part."""
    import muls.montecarlo.run as run

    args = ("mobley1993_particle", 0.9, [1.0, 5.0])
    monkeypatch.setattr(run, "FIRST_PART_PACKETS", 10**9)
    whole = run_slab(*args, packets=4_000, seed=9)
    monkeypatch.setattr(run, "FIRST_PART_PACKETS", 1)
    monkeypatch.setattr(run, "PART_S", 0.0)
    parts = run_slab(*args, packets=4_000, seed=9)
    assert np.array_equal(whole.per_batch, parts.per_batch) and whole.energy == parts.energy


def test_bad_settings_are_rejected_with_their_name():
    for kwargs, key in (({"albedo": 1.5}, "albedo"), ({"depths_m": [5.0, 1.0]}, "depths_m"),
                        ({"depths_m": [0.0, 1.0]}, "depths_m"), ({"sun_zenith_deg": 90.0}, "sun_zenith_deg"),
                        ({"max_orders": -1}, "max_orders"), ({"bottom_m": 2.0}, "bottom_m"),
                        ({"packets": 0}, "packets"), ({"packets": 10**20}, "packets")):
        args = {"phase": "rayleigh", "albedo": 0.5, "depths_m": [1.0, 5.0], **kwargs}
        with pytest.raises(ValueError, match=key):
            run_slab(**args)


# ----------------------------------------------------------------------------------------------------------
# The command


def test_mobley1993_json_keys_table_and_picture(capsys, tmp_path):
    png = tmp_path / "m.png"
    code, out, err = _run(capsys, "mobley1993", "--photons", "20000", "--json", "--out", str(png))
    assert code == 0, err
    r = json.loads(out)
    assert len(r["problems"]) == 36 and r["photons"] == 20000 and r["seed"] == 0 and "Table 5" in r["source"]
    for rec in r["problems"]:
        assert {"problem", "albedo", "quantity", "optical_depth", "value", "paper_min", "paper_max",
                "mc_sigma"} <= set(rec)
        assert rec["quantity"] in ("Ed", "Eou", "Lu") and rec["paper_min"] < rec["paper_max"]
    assert png.stat().st_size > 20_000
    code, out, err = _run(capsys, "mobley1993", "--photons", "20000", "--no-plot")
    assert code == 0, err
    assert "Mobley et al. (1993)" in out and "paper mean" in out and out.count("\n") >= 36


@pytest.mark.parametrize("argv, key", [(["--photons", "0"], "--photons"), (["--seed", "-1"], "--seed"),
                                       (["--photons", "many"], "--photons")])
def test_mobley1993_bad_arguments_exit_2_with_one_line(capsys, argv, key):
    code, out, err = _run(capsys, "mobley1993", *argv)
    assert code == 2 and out == ""
    assert key in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_every_value_lies_in_the_papers_range_widened_by_two_monte_carlo_errors(capsys):
    """The acceptance: ``muls mobley1993 --json`` (default photons, seed 0) has Ed, Eou and Lu of problems 1
    and 2, at both albedos and tau = 1, 5, 10, inside [paper_min, paper_max] of Mobley et al. (1993) Table 5
    widened by the Monte Carlo's own 2 standard errors."""
    code, out, err = _run(capsys, "mobley1993", "--json", "--no-plot")
    assert code == 0, err
    records = json.loads(out)["problems"]
    paper = {(r["problem"], r["albedo"], r["quantity"], r["optical_depth"]): r for r in paper_rows()}
    assert {(r["problem"], r["albedo"], r["quantity"], r["optical_depth"]) for r in records} == set(paper)
    outside = []
    for rec in records:
        row = paper[(rec["problem"], rec["albedo"], rec["quantity"], rec["optical_depth"])]
        assert (rec["paper_min"], rec["paper_max"]) == pytest.approx((row["paper_min"], row["paper_max"]))
        assert 0.0 < rec["mc_sigma"] < 0.05 * rec["value"]
        if not rec["paper_min"] - 2.0 * rec["mc_sigma"] <= rec["value"] <= rec["paper_max"] + 2.0 * rec["mc_sigma"]:
            outside.append(rec)
    assert not outside, outside
