"""Ranging (Eq. 14, muls/ranging/returns.py): noise-free ranges, channel choice, dropout causes, returns behind
clipped echoes and plateaus."""

import numpy as np
import pytest
from conftest import RANGE_TOL_NOISE_FREE_M, paper_water
from conftest import detection_model as _model
from conftest import dropout_causes as _causes

from muls import mul2023, water_preset
from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.ranging.returns import DROPOUT_CAUSES, NO_DROPOUT
from muls.simulate import simulate


@pytest.mark.parametrize("range_m", [7.0, 9.0, 12.0, 16.0, 19.0])
def test_noise_free_ranging_within_1_cm(range_m):
    """Echoes of 150 LSB and more: only the sampling phase and 10-bit rounding remain."""
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.full(20, range_m), pulse_id=np.arange(20))
    _, ranging = simulate(model, batch, seed=5, noise=False)
    assert ranging.returns.pulse.size == 20
    assert np.all(np.abs(ranging.returns.range_m - range_m) < RANGE_TOL_NOISE_FREE_M)



@pytest.mark.parametrize("range_m", [22.0, 30.0])
def test_noise_free_ranging_of_weak_echoes_is_quantisation_limited(range_m):
    """A 24 LSB echo at 30 m ranges to several cm with 10 bits; a 14-bit digitiser brings it within 1 cm."""
    from dataclasses import replace

    base = mul2023(150e-9, 400e-9)
    fine = replace(base, digitizer=replace(base.digitizer, bits=14))
    model = OpticalModel.build(fine, paper_water("pool"))
    batch = PulseBatch.flat_target(fine, np.full(20, range_m), pulse_id=np.arange(20))
    _, ranging = simulate(model, batch, seed=5, noise=False)
    assert np.all(np.abs(ranging.returns.range_m - range_m) < RANGE_TOL_NOISE_FREE_M)



def test_channel_choice_high_gain_saturated_falls_to_low_gain():
    model = _model()
    batch = PulseBatch.flat_target(model.instrument, np.full(30, 9.0), pulse_id=np.arange(30))
    _, ranging = simulate(model, batch, seed=3)
    ch1_peaks = ranging.peaks.select(ranging.peaks.channel == 1)
    assert ch1_peaks.saturated.all()
    assert np.all(ranging.returns.channel == 2)
    assert not ranging.returns.saturated.any()



def test_channel_choice_echo_in_gate_uses_ch3():
    model = _model("pond", (100e-9, 400e-9))
    batch = PulseBatch.flat_target(model.instrument, np.full(30, 13.0), pulse_id=np.arange(30))
    _, ranging = simulate(model, batch, seed=3)
    assert np.all(ranging.returns.channel == 3)
    assert np.all(np.abs(ranging.returns.range_m - 13.0) < 0.2)



@pytest.mark.parametrize("water, gate, range_m, rho, cause", [
    ("pool", (150e-9, 400e-9), np.inf, 0.1, "no_hit"),
    ("pool", (150e-9, 400e-9), 1.0, 0.1, "blind_zone"),
    ("turbid_harbor", (100e-9, 400e-9), 20.0, 0.1, "below_threshold"),
    ("coastal_ocean", (100e-9, 400e-9), 3.0, 0.1, "saturated"),
    ("turbid_harbor", (100e-9, 400e-9), 3.5, 0.001, "masked_by_backscatter"),
    ("pond", (200e-9, 400e-9), 13.0, 0.1, "outside_gate"),
])
def test_each_dropout_cause_is_reached(water, gate, range_m, rho, cause):
    from dataclasses import replace

    model = _model(water, gate)
    ins = model.instrument
    model = OpticalModel.build(replace(ins, processing=replace(ins.processing, saturation_policy="drop")), model.water)
    batch = PulseBatch.flat_target(model.instrument, np.full(20, range_m), rho)
    _, ranging = simulate(model, batch, seed=6)
    assert ranging.returns.pulse.size == 0
    assert _causes(ranging) == {cause: 20}



def test_saturated_returns_kept_under_keep_policy():
    model = _model("coastal_ocean", (100e-9, 400e-9))
    ins = model.instrument
    assert ins.processing.saturation_policy == "keep"  # the default
    _, ranging = simulate(model, PulseBatch.flat_target(ins, np.full(20, 3.0)), seed=6)
    assert ranging.returns.pulse.size == 20
    assert ranging.returns.saturated.all()
    assert np.all(ranging.dropout_cause == NO_DROPOUT)
    # The clipped plateau's width recovers the peak time through the known pulse shape.
    assert np.all(np.abs(ranging.returns.range_m - 3.0) < 0.1)



def test_regression_clipped_run_after_backscatter_blindness_is_not_an_echo():
    """Root cause: a far channel gated open at 40 ns in turbid water is clipped by the column itself; the echo
    lies inside that blind stretch, and the clipped samples that follow it were taken as an echo plateau,
    ranged ~0.8 m long. A run must rise from samples where the channel can see."""
    model = _model("turbid_harbor", (40e-9, 400e-9))
    _, ranging = simulate(model, PulseBatch.flat_target(model.instrument, np.full(30, 7.5), 0.14), seed=1)
    far = ranging.peaks.select(ranging.peaks.channel == 3)
    assert far.pulse.size == 0
    assert set(np.unique(ranging.dropout_cause[ranging.dropout_cause >= 0])) <= {DROPOUT_CAUSES.index("masked_by_backscatter")}



def test_regression_plateau_through_backscatter_blindness_is_not_an_echo():
    """Root cause: in turbid water at 3.2 m the column alone clips CH1 from 23 to 31 ns and the echo keeps it
    clipped after that; the plateau was measured from its first clipped sample (in the column), so CH1 ranged
    the seabed ~0.7 m short and a second, true return came from CH2. A plateau that passes through samples
    the backscatter alone clips has an unknown start: the channel cannot range it."""
    model = _model("turbid_harbor", (35e-9, 400e-9))
    _, ranging = simulate(model, PulseBatch.flat_target(model.instrument, np.full(40, 3.2), 0.14), seed=3)
    assert np.all(ranging.number_of_returns[ranging.return_number == 1] == 1)
    assert np.all(np.abs(ranging.returns.range_m - 3.2) < 0.15)



def test_regression_second_plateau_explained_by_the_first_echo_does_not_hang():
    """Root cause: two clipped plateaus one sample apart (a moored mine's top, then the seabed, at 1.9 m in
    single_channel coastal water). Once the first echo's model was taken off, the second plateau's clip level
    was negative, log() gave NaN, the peak index -inf, and adding that echo's model looped ~2^63 times.
    A plateau whose clip level the echoes before it already explain is not ranged; the grid lookup is total."""
    from muls.infra.lookup import on_geometric_grid

    ratio, rise, _ = _model().clip_table
    for x in (0.0, -1.0, float("nan")):
        assert on_geometric_grid(x, ratio, rise) == rise[0]
    code = (
        "import numpy as np\n"
        "from scanner_sim.config import load_scene\n"
        "from scanner_sim.studies.coverage_study import combination_config\n"
        "from scanner_sim.survey.setup import PassOptions, PassSetup\n"
        "cfg = combination_config(load_scene('mine_field'), 'coastal_ocean', 3.0, 'single_channel')\n"
        "chunk = PassSetup.build(cfg, PassOptions(water='coastal_ocean')).simulate_chunk(np.array([44049]))\n"
        "assert np.all(np.isfinite(chunk.points.xyz)) and len(chunk.points) >= 1\n"
    )
    import subprocess
    import sys

    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)



def test_two_echoes_in_one_footprint_give_two_returns_and_close_ones_merge():
    model = _model()

    def batch_for(ranges):
        n = 20
        return PulseBatch(
            pulse_id=np.arange(n), return_pulse=np.repeat(np.arange(n), 2),
            return_range_m=np.tile(ranges, n), return_weight_per_sr=np.full(2 * n, 0.5 * 0.05 / np.pi),
            column_cut_m=np.full((n, 1), max(ranges)), column_cut_weight=np.ones((n, 1)), background_w=np.zeros(n))

    _, apart = simulate(model, batch_for([15.0, 17.0]), seed=1)
    assert np.all(apart.number_of_returns == 2)
    assert np.allclose(apart.returns.range_m[apart.return_number == 1], 15.0, atol=0.1)
    assert np.allclose(apart.returns.range_m[apart.return_number == 2], 17.0, atol=0.15)
    _, close = simulate(model, batch_for([15.0, 15.3]), seed=1)
    assert np.all(close.number_of_returns == 1)
    merged = close.returns.range_m
    assert np.all((merged > 15.0) & (merged < 15.3))  # one biased range between the two surfaces



@pytest.mark.parametrize("near_reflectance", [0.5, 0.9])
@pytest.mark.parametrize("mode, deciding_only", [("windowed", False), ("windowed", True), ("full", False)])
def test_return_behind_clipped_echo_is_ranged(mode, deciding_only, near_reflectance):
    """Root cause: the peak search went on behind an unclipped peak (its modelled pulse taken off, the search
    resumed right after it) but not behind a clipped one: it resumed after the whole run, and a clipped echo's
    tail runs on over a surface a few metres behind, so that surface was never reported (0 of 1000 pulses, no
    dropout, no flag) while the same plate 10 % darker, unclipped, let it be ranged on every pulse. Half the beam on
    a plate 7 m away whose echo clips every channel open there, half on sand 2 m behind: the sand is ranged at 9 m
    on every pulse, in both record modes and with only the deciding channels (every fidelity level's path). With
    the whiter plate CH1's plateau runs on over the sand's echo (one plateau, two echoes): the model fitted to it
    is wrong behind it, and what that leaves in the residual must not be reported as a third surface."""
    from muls.optics.radiometry import lambertian_weight

    model = _model()
    ins = model.instrument
    n, near_m, far_m = 200, 7.0, 7.0 + 2.0
    half = [0.5 * lambertian_weight(ins, r, rho) for r, rho in ((near_m, near_reflectance), (far_m, 0.43))]
    batch = PulseBatch(
        pulse_id=np.arange(n), return_pulse=np.repeat(np.arange(n), 2), return_range_m=np.tile([near_m, far_m], n),
        return_weight_per_sr=np.tile(half, n), column_cut_m=np.full((n, 1), far_m), column_cut_weight=np.ones((n, 1)),
        background_w=np.zeros(n))
    _, ranging = simulate(model, batch, seed=4, mode=mode, deciding_only=deciding_only)
    first, second = (ranging.returns.select(ranging.return_number == k) for k in (1, 2))
    # The premise: the plate's return is clipped in every channel (a return keeps a clipped peak only then).
    assert first.pulse.size == n and first.saturated.all() and np.all(np.abs(first.range_m - near_m) < 0.15)
    assert second.pulse.size == n and not second.saturated.any()
    assert np.all(np.abs(second.range_m - far_m) < 0.15)  # IHO S-44 Exclusive Order, the coverage tolerance
    assert np.all(ranging.number_of_returns == 2)



def test_no_late_return_from_an_echo_rising_inside_a_plateau():
    """Root cause: behind a clipped plateau the search goes on once the single pulse fitted to the plateau is taken
    off. Where a second echo rises before the first echo's plateau ends (a step 1 m down, 8.9 ns behind, under a
    10 ns pulse), the plateau holds both: the fitted pulse is off, and what it leaves of the second echo peaks
    late, where it was reported as a third surface (step_edges, slot 749: CH1 at 7.19 m, 0.49 m behind the step
    CH2 ranges at 6.75 m). An echo whose peak lies less than the pulse's rise behind the plateau's end began
    inside the plateau, so the clipping channel cannot time it and no longer reports it; CH2, which does not clip,
    ranges it. Two-thirds of the beam on sand 5.7 m away, a third on sand 1 m lower (step_edges' geometry, CH1
    clipped over the upper echo on every pulse): every return lies on one of the two surfaces, within 0.25 m (the
    late points lay 0.3-0.54 m behind the lower one)."""
    from muls.optics.radiometry import lambertian_weight

    ins = mul2023(26e-9, 158e-9)  # step_edges' gate (a CH3 gate that opens past both echoes)
    model = OpticalModel.build(ins, water_preset("coastal_ocean"))
    n, upper_m, lower_m = 400, 5.7, 6.7
    weights = [share * lambertian_weight(ins, r, 0.43) for share, r in ((2 / 3, upper_m), (1 / 3, lower_m))]
    batch = PulseBatch(
        pulse_id=np.arange(n), return_pulse=np.repeat(np.arange(n), 2), return_range_m=np.tile([upper_m, lower_m], n),
        return_weight_per_sr=np.tile(weights, n), column_cut_m=np.full((n, 1), lower_m),
        column_cut_weight=np.ones((n, 1)), background_w=np.zeros(n))
    records, ranging = simulate(model, batch, seed=7)
    assert np.all(records.codes[:, 0].max(axis=1) == ins.digitizer.max_code)  # the premise: CH1 clips every pulse
    ranges = ranging.returns.range_m
    off = np.minimum(np.abs(ranges - upper_m), np.abs(ranges - lower_m))
    assert np.all(off < 0.25), np.sort(ranges[off >= 0.25])
    assert np.count_nonzero(np.abs(ranges - lower_m) < 0.15) >= 0.9 * n  # the lower step is still ranged
