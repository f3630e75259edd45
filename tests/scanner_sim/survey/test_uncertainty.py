"""THU and TVU per point (scanner_sim/survey/uncertainty.py, ranging_precision.py) and their calibration against the
truth (scanner_sim/survey/tpu_calibration.py)."""

from __future__ import annotations

import dataclasses
import json
import math

import laspy
import numpy as np
import pytest

from muls import mul2023
from scanner_sim.cli import main
from scanner_sim.config import load_scene, shipped_scenes
from scanner_sim.motion.trajectory import rotation_matrices
from scanner_sim.studies.tpu_ensemble import ensemble_calibration, ensemble_seeds
from scanner_sim.survey.pipeline import pass_chunks, run_pass, simulate_pass, warm_up
from scanner_sim.survey.ranging_precision import tabulate
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.survey.tpu_calibration import UncertaintySink
from scanner_sim.survey.uncertainty import NavigationSigmas, TpuModel

WATERS = ("clean_ocean", "coastal_ocean", "turbid_harbor")
SEABED_SCENES = sorted(name for name in shipped_scenes() if load_scene(name).seabed is not None)
#: Passes and pulses per pass of the ensemble each shipped scene is judged by (docs/uncertainty.md). A scene with
#: navigation noise (cable_survey: drifting over 20 s) draws it once per 0.06 s pass, so the pooled share's
#: standard deviation is the per-pass spread (0.14-0.16 in clean and coastal water) over sqrt(passes): 256 passes
#: give about 0.01 (1,024 passes: 0.946, 0.947, 0.960 in the three waters; 256: 0.947, 0.945, 0.960; 64: 0.972,
#: 0.968, 0.961). Without navigation noise the passes differ in their instrument noise alone (spread 0.01-0.03).
NAVIGATION_NOISE_PASSES, ENSEMBLE_PASSES, ENSEMBLE_PULSES = 256, 64, 300
#: Navigation noise decorrelated from pulse to pulse (the pass's grid at its pulse rate, 2 ms correlation), for the
#: ablation test: a short pass then samples the noise's distribution instead of one slowly drifting draw.
DECORRELATED = {"platform.navigation_noise.correlation_time_s": 0.002, "platform.navigation_noise.rate_hz": 5000}


def _model(**navigation) -> TpuModel:
    table = tabulate(np.zeros(20), np.full(20, 1), np.full(20, 50.0), np.zeros(20, bool), np.zeros(20, bool),
                     np.zeros(20, np.int64), 3, (5.0,))
    return TpuModel(table, NavigationSigmas(**navigation), 0.01, 0.004, 0.65)


def test_attitude_and_heading_jacobians_match_a_turned_rotation():
    """The variances of an attitude-only model equal the diagonal of sum sigma^2 J J^T with J the finite difference
    of X = p + R(roll, pitch, yaw) v_platform for each angle, taken through the trajectory's own rotation matrices."""
    rng = np.random.default_rng(4)
    n = 50
    roll, pitch, yaw = rng.uniform(-0.3, 0.3, n), rng.uniform(-0.3, 0.3, n), rng.uniform(-3, 3, n)
    v_platform = np.c_[rng.uniform(-1, 1, n), rng.uniform(-4, 4, n), rng.uniform(-8, -3, n)]  # lever in the vehicle
    base = rotation_matrices(yaw, pitch, roll)
    lever = np.einsum("nij,nj->ni", base, v_platform)
    s_att, s_head, h = math.radians(0.5), math.radians(1.0), 1e-6
    expected = np.zeros((n, 3))
    for sigma, axis in ((s_att, 2), (s_att, 1), (s_head, 0)):  # roll, pitch, heading: central differences
        turned = [np.array([yaw, pitch, roll]) + sign * h * np.eye(3)[axis][:, None] for sign in (1, -1)]
        x = [np.einsum("nij,nj->ni", rotation_matrices(*angles), v_platform) for angles in turned]
        j = (x[0] - x[1]) / (2 * h)
        expected += sigma**2 * j**2
    model = _model(attitude_rad=s_att, heading_rad=s_head)
    got = model.variances(lever, np.tile([0.0, 0.0, -1.0], (n, 1)), np.c_[roll, pitch, yaw], np.zeros(n))
    np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())


def test_footprint_spread_is_the_std_of_a_disc_met_on_a_slope():
    """(w / 4) tan(theta) against the standard deviation of x tan(theta) over points drawn uniformly in the disc."""
    rng = np.random.default_rng(1)
    model = _model()
    range_m, incidence = 6.0, 50.0
    width = 0.01 + 2 * range_m * math.tan(0.002)
    r, phi = 0.5 * width * np.sqrt(rng.random(400_000)), rng.uniform(0, 2 * math.pi, 400_000)
    drawn = np.std(r * np.cos(phi) * math.tan(math.radians(incidence)))
    got = model.footprint_sigma_m(np.array([range_m]), np.array([incidence]))[0]
    assert got == pytest.approx(drawn, rel=0.01)
    assert model.footprint_sigma_m(np.array([range_m]), np.array([np.nan]))[0] == 0.0


def test_footprint_widens_the_ranging_spread_as_it_widens_the_echo():
    """A footprint met obliquely spreads its echo's delays about the axis's; the ranged echo is the digitised pulse
    convolved with them, and the timing's noise grows with the echo's rms length. Here the echo is built by hand:
    mul2023's pulse sampled in time, convolved with the delays 2 x tan(theta) / v across a uniformly lit footprint
    0.3 m wide (x's density over a disc of radius a: sqrt(1 - (x / a)^2)) met at 85 degrees, far wider than a pass's
    footprint so that the widening is large; the ratio of its standard deviation to the bare pulse's is the factor on
    the ranging's standard deviation. At normal incidence the footprint adds nothing."""
    pulse, speed, dt = mul2023().pulse, 2.2e8, 0.02e-9
    table = tabulate(np.tile([-0.01, 0.01], 10), np.full(20, 1), np.full(20, 50.0), np.zeros(20, bool),
                     np.zeros(20, bool), np.zeros(20, np.int64), 3, (5.0,))
    model = TpuModel(table, NavigationSigmas(), 0.3, 0.0, 0.5 * speed * pulse.rms_width_s)

    def width(profile):  # standard deviation [s] of a profile sampled every dt
        i = np.arange(profile.size)
        mean = np.sum(i * profile) / np.sum(profile)
        return dt * math.sqrt(np.sum((i - mean) ** 2 * profile) / np.sum(profile))

    bare = pulse(np.arange(0.0, 300e-9, dt))
    for incidence, widening in ((0.0, 1.0), (85.0, 1.5)):
        x = np.linspace(-0.15, 0.15, 20_001)
        delay_bin = np.rint(2.0 * x * math.tan(math.radians(incidence)) / speed / dt).astype(np.int64)
        spread = np.bincount(delay_bin - delay_bin.min(), weights=np.sqrt(np.clip(1.0 - (x / 0.15) ** 2, 0.0, None)))
        expected = width(np.convolve(bare, spread)) / width(bare)
        _, var = model.error_model(np.array([[0.0, 0.0, -5.0]]), np.array([[0.0, 0.0, -1.0]]), np.zeros((1, 3)),
                                   np.ones(1, np.int64), np.array([50.0]), np.zeros(1, bool), np.zeros(1, bool),
                                   np.array([5.0]), np.array([incidence]))
        assert math.sqrt(var[0, 2]) / 0.01 == pytest.approx(expected, rel=1e-3), incidence
        assert expected >= widening


def test_predict_is_the_error_model_on_the_gathered_arrays_to_the_bit():
    """``TpuModel.predict`` runs point by point in one kernel; its mean and variances must be ``error_model``'s (the
    numpy form the propagation is written in) on the arrays gathered per point, bit for bit: with the navigation's
    attitude and without it, normals known, unknown (NaN), near vertical (no surface reading) or not given, and
    points out of pulse order (the kernel's row search then falls back from its guess)."""
    from scanner_sim.survey.chunk import cast_chunk, finish_chunk

    setup = PassSetup.build(load_scene("cable_survey"), PassOptions(fidelity="fast", max_pulses=2000))
    cast = cast_chunk(setup, next(setup.slot_chunks()))
    points, sight = finish_chunk(setup, cast).points, cast.sight
    n = len(points.xyz)
    normal = np.tile([0.1, -0.2, 0.97], (n, 1))
    normal[::7] = np.nan
    normal[::11] = [1.0, 0.0, 0.0]  # a vertical facet
    order = np.r_[np.arange(n)[::2], np.arange(n)[1::2][::-1]]
    shuffled = dataclasses.replace(points, **{f.name: getattr(points, f.name)[order]
                                              for f in dataclasses.fields(points)
                                              if isinstance(getattr(points, f.name), np.ndarray)})

    def numpy_form(model, points, normal):
        row = np.searchsorted(sight.slot, points.pulse_index)
        direction = sight.direction[row]
        range_m = np.einsum("ij,ij->i", points.xyz - sight.origin_m[row], direction)
        return model.error_model(points.xyz - sight.platform_m[row], direction, sight.attitude_rad[row],
                                 points.channel, points.snr, points.saturated, points.return_number > 1, range_m,
                                 points.incidence_deg, normal)

    still = dataclasses.replace(setup.tpu, navigation=NavigationSigmas())
    assert setup.tpu.navigation.attitude_rad > 0
    for model in (setup.tpu, still):
        for pts, nrm in ((points, normal), (points, None), (shuffled, normal[order])):
            got, expected = model.predict(pts, sight, nrm), numpy_form(model, pts, nrm)
            for a, b in zip(got, expected):
                assert a.tobytes() == b.tobytes()
    var = setup.tpu.predict(points, sight, normal)[1]  # the surface reading lost only where the facet stands vertical
    assert np.isnan(var[::11, 3]).all() and np.isfinite(np.delete(var[:, 3], np.s_[::11])).all()
    with pytest.raises(IndexError):  # as numpy's gathers refused it: no row to read past the chunk's last pulse
        setup.tpu.predict(points, sight._replace(slot=sight.slot - 1), normal)


def test_ranging_table_holds_mean_and_spread_per_bin_and_fills_empty_bins_from_the_nearest():
    """Two SNR bins with known errors: each keeps its mean and standard deviation; a bin without returns takes the
    nearest filled bin's; a far panel range without returns the nearest range's."""
    errors = np.r_[np.full(20, 0.05) + np.tile([-0.01, 0.01], 10), np.full(20, -0.02)]
    snr = np.r_[np.full(20, 10.0), np.full(20, 1000.0)]
    table = tabulate(errors, np.ones(40, np.int64), snr, np.zeros(40, bool), np.zeros(40, bool),
                     np.zeros(40, np.int64), 3, (5.0, 9.0))
    bias, std = table.of(np.ones(4, np.int64), np.array([10.0, 1000.0, 12.0, 1e5]), np.zeros(4, bool),
                         np.zeros(4, bool), np.array([5.0, 5.0, 9.0, 9.0]))
    np.testing.assert_allclose(bias, [0.05, -0.02, 0.05, -0.02])
    np.testing.assert_allclose(std, [0.01, 0.0, 0.01, 0.0], atol=1e-12)


def test_run_writes_thu_and_tvu_extra_bytes_that_laspy_reads(tmp_path):
    """`scanner-sim run`'s points.las carries thu_m and tvu_m, the same as the pass in memory, and the summary their
    quantiles."""
    options = PassOptions(max_pulses=400, progress=False, render=False, write_scene=False)
    config = load_scene("cable_survey")
    summary = run_pass(config, tmp_path, options).summary
    las = laspy.read(tmp_path / "points.las")
    memory = simulate_pass(config, options).points
    np.testing.assert_array_equal(np.asarray(las["tvu_m"]), memory.tvu_m)
    np.testing.assert_array_equal(np.asarray(las["thu_m"]), memory.thu_m)
    assert np.all(memory.tvu_m > 0.0) and np.all(memory.thu_m > 0.0)
    assert summary["uncertainty"]["tvu_m"]["median"] == pytest.approx(float(np.median(memory.tvu_m)), abs=1e-3)


def _calibration(setup: PassSetup, options: PassOptions) -> dict:
    warm_up(setup, options)
    sink = UncertaintySink(setup.tpu)
    for chunk in pass_chunks(setup, options):
        sink.add(chunk)
    return sink.figures()["calibration"]


def _setup(scene: str, water: str, pulses: int, overrides: dict | None = None) -> tuple[PassSetup, PassOptions]:
    options = PassOptions(water=water, max_pulses=pulses, progress=False, render=False)
    return PassSetup.build(load_scene(scene).with_overrides(overrides or {}), options), options


@pytest.mark.slow
@pytest.mark.parametrize("water", WATERS)
@pytest.mark.parametrize("scene", SEABED_SCENES)
def test_tvu_holds_90_to_99_percent_of_true_vertical_errors_on_every_seabed_scene(scene, water):
    """On every shipped seabed scene as shipped, in three waters, |true vertical error| <= TVU for 90-99 % of the
    judged points of an ensemble of passes of derived seeds (module constants): a navigation error
    that drifts over seconds (cable_survey: 20 s) is one draw per short pass, so only many passes sample the
    distribution the TPU's variances describe. The pooled share is the points-weighted mean of the passes' own."""
    config = load_scene(scene)
    noise = config.platform.navigation_noise
    passes = NAVIGATION_NOISE_PASSES if any((noise.position_sigma_m, noise.depth_sigma_m, noise.attitude_sigma_deg,
                                             noise.heading_sigma_deg)) else ENSEMBLE_PASSES
    options = PassOptions(water=water, max_pulses=ENSEMBLE_PULSES, progress=False, render=False)
    figures = ensemble_calibration(config, options, passes)
    cal, members = figures["calibration"], figures["ensemble"]["seeds"]
    assert cal["points"] >= 3000  # the per-point part of the share to about 0.4 % (binomial, 0.95)
    assert 0.90 <= cal["vertical_within_tvu"] <= 0.99, (cal, figures["ensemble"])
    weighted = sum(m["points"] * m["vertical_within_tvu"] for m in members) / sum(m["points"] for m in members)
    assert cal["vertical_within_tvu"] == pytest.approx(weighted, abs=1e-4)
    assert len({m["seed"] for m in members}) == len({m["navigation_seed"] for m in members}) == passes


@pytest.mark.slow
def test_one_short_pass_of_a_drifting_navigation_error_is_one_draw_not_a_calibration():
    """cable_survey as shipped (navigation noise correlated over 20 s): its own 3,000-pulse pass (0.6 s) holds more
    than 99 % of its points within TVU, one small draw of the drift; passes of other seeds scatter from well under
    90 % to 100 % (the draws' spread): a pass's share is one sample of a correlated error, its ensemble's pool the
    calibration (the test above)."""
    options = PassOptions(water="clean_ocean", max_pulses=3000, progress=False, render=False)
    assert _calibration(*_setup("cable_survey", "clean_ocean", 3000))["vertical_within_tvu"] > 0.99
    ensemble = ensemble_calibration(load_scene("cable_survey"), dataclasses.replace(options, max_pulses=300), 64)
    shares = [m["vertical_within_tvu"] for m in ensemble["ensemble"]["seeds"]]
    assert min(shares) < 0.80 and max(shares) == 1.0


def test_ensemble_seeds_are_the_spawned_sequences_first_words_halved():
    """Member i's survey and navigation seeds against numpy's own spawn of the seed's sequence."""
    spawned = np.random.SeedSequence(5).spawn(3)
    expected = [tuple(int(w) >> 1 for w in child.generate_state(2, np.uint64)) for child in spawned]
    assert ensemble_seeds(5, 3) == expected
    assert len(set(expected)) == 3


def test_a_pass_with_other_seeds_reuses_the_built_pass_and_equals_a_fresh_build():
    """PassSetup.with_seeds gives the points (and their navigation noise) a pass built afresh with those survey and
    navigation seeds gives, bit for bit; and other points than the base pass."""
    options = PassOptions(water="clean_ocean", max_pulses=200, progress=False, render=False)
    config = load_scene("cable_survey")
    base = PassSetup.build(config, options)
    seeds = {"survey.seed": 12345, "platform.navigation_noise.seed": 678}
    fresh = PassSetup.build(config.with_overrides(seeds), options, base.scene)
    reseeded = base.with_seeds(12345, 678)
    slots = next(iter(base.slot_chunks()))
    got, want = reseeded.simulate_chunk(slots).points, fresh.simulate_chunk(slots).points
    np.testing.assert_array_equal(got.xyz, want.xyz)
    assert not np.array_equal(got.xyz, base.simulate_chunk(slots).points.xyz)
    assert reseeded.target is base.target


@pytest.mark.slow
def test_a_tpu_without_the_attitude_term_fails_the_calibration_the_full_model_passes():
    """The pass keeps 0.5 degree attitude noise (decorrelated); the TPU with every term holds 90-99 % of the true
    vertical errors, the same TPU with its attitude term turned off (the pass unchanged) under 90 %: the model is
    not padded, the attitude term carries its share."""
    overrides = {**DECORRELATED, "platform.navigation_noise.attitude_sigma_deg": 0.5,
                 "platform.navigation_noise.position_sigma_m": 0.0, "platform.navigation_noise.depth_sigma_m": 0.0,
                 "platform.navigation_noise.heading_sigma_deg": 0.0}
    setup, options = _setup("cable_survey", "clean_ocean", 3000, overrides)
    full = _calibration(setup, options)
    blind = dataclasses.replace(setup, tpu=dataclasses.replace(
        setup.tpu, navigation=dataclasses.replace(setup.tpu.navigation, attitude_rad=0.0)))
    without = _calibration(blind, options)
    assert 0.90 <= full["vertical_within_tvu"] <= 0.99, full
    assert without["vertical_within_tvu"] < 0.90, without


@pytest.mark.slow
def test_uncertainty_command_prints_the_calibration_as_json(capsys, tmp_path):
    chart = tmp_path / "calibration.png"
    assert main(["uncertainty", "mine_field", "--water", "coastal_ocean", "--max-pulses", "1500", "--json",
                 "--chart", str(chart)]) == 0
    out = json.loads(capsys.readouterr().out)
    cal = out["calibration"]
    assert set(cal["per_incidence_deg"]) == {"0-15", "15-30", "30-45", "45-60", "60-90"}
    assert sum(v["points"] for v in cal["per_channel"].values()) == cal["points"]
    assert 0.90 <= cal["vertical_within_tvu"] <= 0.99
    assert chart.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_uncertainty_command_pools_passes_of_derived_seeds(capsys):
    """`--seeds 3`: the JSON names the three passes' seeds (the derived ones), their points add up to the pool's and
    their shares, weighted by points, make the pooled share; `--seeds 0` is refused in one line, exit 2."""
    assert main(["uncertainty", "mine_field", "--max-pulses", "200", "--seeds", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    members = out["ensemble"]["seeds"]
    assert [(m["seed"], m["navigation_seed"]) for m in members] == ensemble_seeds(out["seed"], 3)
    assert sum(m["points"] for m in members) == out["calibration"]["points"] and out["pulses"] == 600
    weighted = sum(m["points"] * m["vertical_within_tvu"] for m in members) / out["calibration"]["points"]
    assert out["calibration"]["vertical_within_tvu"] == pytest.approx(weighted, abs=1e-4)
    assert main(["uncertainty", "mine_field", "--seeds", "0"]) == 2
    assert "--seeds: must be an integer >= 1, not '0'" in capsys.readouterr().err


def test_the_calibration_charts_counts_are_those_of_the_sorted_levels():
    """The chart counts, per nominal coverage, the levels at or under it; counted without sorting the chunk's levels
    (0.55 of a 10,000-pulse chunk's 1.0 ms in the sink), they must equal the sorted levels' right-hand
    ``searchsorted``: levels on a chart level, at 0 and 1, NaN (no level: counted nowhere)."""
    from scanner_sim.survey.tpu_calibration import CHART_LEVELS, _at_or_under

    rng = np.random.default_rng(2)
    for n in (0, 1, 60, 10000):
        levels = rng.random(n)
        if n > 2:
            levels[::7] = np.nan
            levels[::11] = CHART_LEVELS[rng.integers(0, CHART_LEVELS.size, levels[::11].size)]
            levels[:2] = 0.0, 1.0
        expected = np.searchsorted(np.sort(levels), CHART_LEVELS, side="right")
        np.testing.assert_array_equal(_at_or_under(levels), expected)
