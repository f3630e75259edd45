"""Every dropout cause checked against its definition (docs/outputs.md, *Dropout causes*).

The terms each cause is defined by are recomputed here from what the instrument records, not by the cause function:
the noise-free records of each pulse (``keep_noise_free``), of the same pulse with its echoes dark (the column as the
target cuts it, and background) and with nothing in the beam (the open-water column the processor subtracts), the
echoes' starts and energies, and the channels' settings."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from muls import mul2023
from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.presets import study_water
from muls.ranging.returns import DROPOUT_CAUSES, NO_DROPOUT, echo_span
from muls.simulate import simulate
from scanner_sim.config.loading import load_scene
from scanner_sim.survey.setup import PassOptions, PassSetup

SCENES = Path(__file__).resolve().parents[3] / "scenes" / "failures"
#: The scene file's water of scenes/failures/turbid_water.yaml: c 5 per m, a 0.5 per m.
TURBID = load_scene(SCENES / "turbid_water.yaml").water_model()
#: Relative margin within which a term is too close to its threshold to say on which side the float32 records lie.
MARGIN = 0.01


def _model(water, gate_delay_s, gate_width_s=400e-9, policy="keep"):
    ins = mul2023(gate_delay_s, gate_width_s)
    ins = replace(ins, processing=replace(ins.processing, saturation_policy=policy))
    return OpticalModel.build(ins, water)


def _dark(batch: PulseBatch) -> PulseBatch:
    """The same pulses with their echoes dark: the column cut where the targets cut it, and the background."""
    return replace(batch, return_weight_per_sr=np.zeros_like(batch.return_weight_per_sr))


def _open_water(batch: PulseBatch) -> PulseBatch:
    """The same pulses meeting nothing: the open-water column and background, the processor's baseline."""
    n = batch.n_pulses
    return replace(batch, return_pulse=np.zeros(0, np.int64), return_range_m=np.zeros(0),
                   return_weight_per_sr=np.zeros(0), column_cut_m=np.full((n, 1), np.inf),
                   column_cut_weight=np.ones((n, 1)))


def _echo_watts(total, column, times, chans):
    """(n, samples) the echoes alone [W]: the record less the record with the echoes dark, read in the channel open
    at each sample whose float32 codes resolve it best (a shut channel records its dark level only)."""
    best, error = np.zeros(times.shape), np.full(times.shape, np.inf)
    for j in range(total.shape[1]):
        c = j + 1
        is_open = (chans.gate_open_s[c] <= times) & (times < chans.gate_close_s[c])
        resolution = np.spacing(np.maximum(total[:, j], column[:, j]).astype(np.float32)) / chans.lsb_per_w[c]
        better = is_open & (resolution < error)
        best = np.where(better, (total[:, j] - column[:, j]) / chans.lsb_per_w[c], best)
        error = np.where(better, resolution, error)
    return best


def expected_causes(model: OpticalModel, batch: PulseBatch, seed, margin=0.0):
    """(reported causes, causes by definition) of every pulse of ``batch``; a definition's thresholds scaled by
    ``1 + margin``. The terms come from noise-free full records (1 GS/s, one window per pulse)."""
    ins, chans = model.instrument, model.channels
    dig, k = ins.digitizer, ins.processing.threshold_sigma
    rec, ranging = simulate(model, batch, seed, mode="full", keep_noise_free=True)
    dark, _ = simulate(model, _dark(batch), seed, mode="full", keep_noise_free=True)
    base, _ = simulate(model, _open_water(batch), seed, mode="full", keep_noise_free=True)
    total = rec.noise_free_lsb.astype(float)  # (n, channels, samples), the windows are the pulses
    column, baseline = dark.noise_free_lsb.astype(float), base.noise_free_lsb.astype(float)
    times = rec.sample_times_s(model)
    echo_w = _echo_watts(total, column, times, chans)
    # The records the shut channels would make with their gates open: whether opening the gate would range the echo.
    ungated = replace(ins, channels=tuple(replace(ch, gate_delay_s=None, gate_width_s=None) for ch in ins.channels))
    opened = OpticalModel.build(ungated, model.water, model.multiple_scattering)
    rec_open, _ = simulate(opened, batch, seed, mode="full", keep_noise_free=True)
    base_open, _ = simulate(opened, _open_water(batch), seed, mode="full", keep_noise_free=True)
    total_open, baseline_open = rec_open.noise_free_lsb.astype(float), base_open.noise_free_lsb.astype(float)

    echoes = model.echoes(batch)
    expected = np.full(batch.n_pulses, NO_DROPOUT)
    for p in np.flatnonzero(ranging.dropout_cause >= 0):
        delay = echoes.delay_s[echoes.offsets[p]:echoes.offsets[p + 1]]
        energy = echoes.energy_j[echoes.offsets[p]:echoes.offsets[p + 1]]
        inside = delay < dig.record_length_s
        if not inside.any():
            expected[p] = DROPOUT_CAUSES.index("no_hit")
            continue
        if not (energy[inside] > 0.0).any():
            expected[p] = DROPOUT_CAUSES.index("blind_zone")
            continue
        peaks = ranging.peaks.select(ranging.peaks.pulse == p)
        if ins.processing.saturation_policy == "drop" and peaks.saturated.any():
            expected[p] = DROPOUT_CAUSES.index("saturated")
            continue
        start = delay[inside][np.argmax(energy[inside])]  # the strongest echo, the earliest of equals
        span = (times[p] >= start) & (times[p] <= start + ins.pulse.duration_s)
        peak = np.flatnonzero(span)[np.argmax(echo_w[p, span])]
        t = times[p, peak]
        masked = seen_open = ranged_if_open = hidden_if_open = False
        for j in range(len(ins.channels)):
            c = j + 1
            is_open = chans.gate_open_s[c] <= t < chans.gate_close_s[c]
            dark_sigma = np.sqrt(chans.dark_std_lsb[c] ** 2 + 1.0 / 12.0)
            visible = chans.lsb_per_w[c] * echo_w[p, peak] > k * dark_sigma * (1 + margin)
            base_w = (baseline[p, j, peak] - chans.dark_mean_lsb[c]) / chans.lsb_per_w[c]
            sigma = np.sqrt(dark_sigma**2 + chans.shot_lsb2_per_w[c] * base_w)
            under = total[p, j, peak] - baseline[p, j, peak] <= k * sigma * (1 + margin)
            top = dig.max_code * (1 + margin)
            clipped = bool(np.any(span & ((baseline[p, j] >= top) | (total[p, j] >= top))))
            masked |= is_open and visible and (under or clipped)
            seen_open |= is_open and visible
            if not is_open and visible:  # would the channel range it, its gate open at the peak?
                base_open_w = (baseline_open[p, j, peak] - chans.dark_mean_lsb[c]) / chans.lsb_per_w[c]
                sigma_open = np.sqrt(dark_sigma**2 + chans.shot_lsb2_per_w[c] * base_open_w)
                under_open = total_open[p, j, peak] - baseline_open[p, j, peak] <= k * sigma_open * (1 + margin)
                clipped_open = max(total_open[p, j, peak], baseline_open[p, j, peak]) >= top
                ranged_if_open |= not (under_open or clipped_open)
                hidden_if_open |= under_open or clipped_open
        name = ("masked_by_backscatter" if masked else "outside_gate" if ranged_if_open and not seen_open
                else "masked_by_backscatter" if hidden_if_open and not seen_open else "below_threshold")
        expected[p] = DROPOUT_CAUSES.index(name)
    return ranging.dropout_cause.astype(int), expected


def assert_causes_match_definitions(model, batch, seed):
    """Every dropped pulse whose terms lie clear of their thresholds has the cause its terms define; returns the
    reported causes' counts."""
    reported, low = expected_causes(model, batch, seed, -MARGIN)
    _, high = expected_causes(model, batch, seed, MARGIN)
    lost = reported >= 0
    decided = low == high
    assert not lost.any() or decided[lost].mean() > 0.95
    bad = np.flatnonzero(decided & (reported != low))
    assert bad.size == 0, [(int(p), DROPOUT_CAUSES[reported[p]], DROPOUT_CAUSES[low[p]]) for p in bad[:5]]
    return {DROPOUT_CAUSES[c]: int(n) for c, n in enumerate(np.bincount(reported[lost], minlength=6)) if n}


def _scene_batch(name, pulses=150, **overrides):
    config = load_scene(SCENES / f"{name}.yaml")
    if overrides:
        config = config.with_overrides(overrides)
    setup = PassSetup.build(config, PassOptions(max_pulses=pulses, progress=False))
    slots = next(setup.slot_chunks())
    return setup.physics.model, setup.cast_chunk(slots).batch, setup.seed


@pytest.mark.parametrize("name, overrides, lost", [
    ("turbid_water", {}, {"masked_by_backscatter": 150}),
    ("blind_zone_edge", {}, {}),
    ("blind_zone_edge", {"platform.position_m": [0, 0, -1.05]}, {"blind_zone": 150}),  # the plate 1.70 m away
    ("blind_zone_edge", {"water": "jerlov_9C"}, {"masked_by_backscatter": 150}),
    ("weak_echo_5m", {}, {"masked_by_backscatter": 150}),
    ("saturation_2m", {}, {}),  # every channel clips; the clipped returns are kept
    # the far gate shut over the echo, but the column would hide it there too: opening the gate ranges nothing
    ("weak_echo_5m", {"instrument.gate_delay_ns": 10, "instrument.gate_width_ns": 20}, {"masked_by_backscatter": 150}),
    ("../pond_panel", {}, {"outside_gate": 93}),  # the far gate opens 9 ns after the echo starts
])
def test_dropout_causes_of_shipped_scenes_follow_their_definitions(name, overrides, lost):
    """The first 150 pulses of failure scenes (and the pond's), as a pass casts them (sub-rays, cuts, multiple
    scattering): every dropped pulse has the cause its terms define, and the counts are those of the situation."""
    model, batch, seed = _scene_batch(name, **overrides)
    assert assert_causes_match_definitions(model, batch, seed) == lost


@pytest.mark.parametrize("water, gate_delay_s", [(TURBID, 0.0), (TURBID, 100e-9), ("turbid_harbor", 0.0),
                                                 ("turbid_harbor", 100e-9)])
def test_dropout_causes_of_plates_in_turbid_water_follow_their_definitions(water, gate_delay_s):
    """Plates from the blind-zone edge to beyond the far channel's reach, dark to white, the far channel open from
    the start or shut over the near range: every cause but no_hit, blind_zone and saturated is met."""
    model = _model(study_water(water) if isinstance(water, str) else water, gate_delay_s)
    r, rho = np.meshgrid([1.7, 1.75, 1.8, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.1, 8.0], [0.005, 0.01, 0.03, 0.1, 0.3, 0.9])
    batch = PulseBatch.flat_target(model.instrument, np.repeat(r.ravel(), 20), np.repeat(rho.ravel(), 20))
    counts = assert_causes_match_definitions(model, batch, seed=5)
    assert counts.get("masked_by_backscatter", 0) > 0


def test_no_hit_blind_zone_and_saturated_follow_their_definitions():
    """Nothing in the record, a plate inside the blind zone, and a clipping plate under the ``drop`` policy."""
    model = _model(study_water("pool"), 100e-9, policy="drop")
    batch = PulseBatch.flat_target(model.instrument, np.repeat([np.inf, 1.0, 2.0], 20), 0.9)
    counts = assert_causes_match_definitions(model, batch, seed=6)
    assert counts == {"no_hit": 20, "blind_zone": 20, "saturated": 20}


def _lost_to(model, batch, seed):
    _, ranging = simulate(model, batch, seed=seed)
    lost = ranging.dropout_cause[ranging.dropout_cause >= 0]
    return {DROPOUT_CAUSES[c]: int(n) for c, n in enumerate(np.bincount(lost, minlength=6)) if n}


def test_dropout_under_clipping_column_is_masked_by_backscatter():
    """A plate 5 m down in the turbid failure scene's water (c 5 per m), the far channel open from the start: the
    column alone clips CH3 over the echo's rise, and the echo alone is 5 times (reflectance 0.3) to 16 times (0.9)
    CH3's threshold; about half the pulses are lost (21 of 40 with seed 5).

    Root cause: the cause judged the column's clipping over the span of the strongest part of the echo, and with a
    spread echo in equal parts that was the last part, which starts after the column stops clipping: no term held
    and the pulses read ``below_threshold`` (too faint) though the column hid an echo many times the threshold.
    The span now starts at the earliest of the strongest parts and is judged at the record's own samples."""
    model = _model(TURBID, 0.0)
    batch = PulseBatch.flat_target(model.instrument, np.full(40, 5.0), np.repeat([0.3, 0.9], 20))
    chans, ins = model.channels, model.instrument
    # The premise, from the records: the open-water column clips CH3 over the echo, and the echo alone (the record
    # less that of the same pulse with a dark plate) rises 5 times above CH3's threshold over its dark noise.
    rec, _ = simulate(model, batch, 5, mode="full", keep_noise_free=True, noise=False)
    dark, _ = simulate(model, _dark(batch), 5, mode="full", keep_noise_free=True, noise=False)
    base, _ = simulate(model, _open_water(batch), 5, mode="full", keep_noise_free=True, noise=False)
    times = base.sample_times_s(model)[0]
    start = model.echoes(batch).delay_s[0]
    over = (times >= start) & (times <= start + ins.pulse.duration_s)
    assert base.noise_free_lsb[0, 2, over].max() >= ins.digitizer.max_code
    echo_alone = (rec.noise_free_lsb[:, 2].astype(float) - dark.noise_free_lsb[:, 2]).max(axis=1)
    threshold = ins.processing.threshold_sigma * np.sqrt(chans.dark_std_lsb[3] ** 2 + 1.0 / 12.0)
    assert echo_alone.min() > 5.0 * threshold
    lost = _lost_to(model, batch, 5)
    assert list(lost) == ["masked_by_backscatter"] and lost["masked_by_backscatter"] >= 15


def test_dropout_seen_by_the_open_near_channel_is_not_outside_gate():
    """A plate 1.75 m down in turbid harbour water, the far channel's gate opening at 100 ns: the ungated CH1 sees
    the echo alone at 3.4 times its threshold, but on the column's flank the column the plate cuts lies 3.4 sigma
    below the open-water column the processor subtracts, so no peak shows. Every pulse is lost.

    Root cause: ``outside_gate`` was given wherever a shut channel could see the echo and no open one was judged
    hidden, and the hiding compared the echo with the column's noise only, not the record with the processor's
    baseline: the pulses read ``outside_gate``, blaming the far gate for an echo the open near channel had and the
    column hid. ``outside_gate`` now needs no open channel to see the echo alone."""
    model = _model(study_water("turbid_harbor"), 100e-9)
    batch = PulseBatch.flat_target(model.instrument, np.full(20, 1.75), 0.1)
    assert _lost_to(model, batch, 5) == {"masked_by_backscatter": 20}


def test_plate_darkening_the_column_is_masked_at_every_reflectance():
    """A plate 6.1 m down in turbid harbour water, the far channel open from the start: the column it cuts leaves
    the far channel's record below the open-water column the processor subtracts, so its echo, above the
    threshold over the column's noise at reflectance 0.03, clears under half of it over the baseline. Every pulse
    is lost to the column, at reflectance 0.03 as at 0.01 (at 0.1 the echo is ranged).

    Root cause: the cause compared the echo with the column's noise, not the record with the processor's baseline,
    so the brighter plate read ``below_threshold`` (too faint) while the darker one read ``masked_by_backscatter``."""
    model = _model(study_water("turbid_harbor"), 0.0)
    batch = PulseBatch.flat_target(model.instrument, np.full(40, 6.1), np.repeat([0.01, 0.03], 20))
    assert _lost_to(model, batch, 3) == {"masked_by_backscatter": 40}


def test_echo_span_is_every_sample_from_the_echo_start_to_the_end_of_its_pulse():
    """The span over which clipping is judged: the record's own samples (sample k at ``-pretrigger + k dt + phase``)
    from the echo's start to its start plus the pulse's duration, both ends included when a sample falls on them,
    counted here by walking the record's samples."""
    dig = mul2023().digitizer
    dt, pre = dig.sample_interval_s, dig.pretrigger_s
    phase = np.array([0.0, 0.3e-9, 0.0, 0.7e-9])
    start = np.array([20e-9, 20e-9, 20.5e-9, 20e-9])
    first, count = np.array([echo_span(s, 4e-9, pre, dt, ph) for s, ph in zip(start, phase)]).T
    by_hand = [[k for k in range(60) if s - 1e-15 <= -pre + k * dt + ph <= s + 4e-9 + 1e-15] for s, ph in zip(start, phase)]
    assert [len(h) for h in by_hand] == [5, 4, 4, 4]
    assert [list(range(f, f + c)) for f, c in zip(first, count)] == by_hand


def _dark_plate_scene(gate_delay_ns: float):
    """A dark plate (reflectance 0.02) 1.75 m below a static lidar in turbid harbour water, the far channel's
    gate opening at ``gate_delay_ns``; its first 60 pulses as a pass casts them."""
    from scanner_sim.config.scene_config import parse_scene

    config = parse_scene({
        "format_version": 1, "name": "dark_plate_turbid", "water": "turbid_harbor",
        "instrument": {"preset": "mul2023", "gate_delay_ns": gate_delay_ns, "gate_width_ns": 400},
        "objects": [{"type": "panel", "name": "plate", "center_m": [0, 0, -2.75], "size_m": [3, 3],
                     "reflectance": 0.02, "label": "panel"}],
        "platform": {"mode": "static", "position_m": [0, 0, -1.0]},
        "scanner": {"mode": "static", "aim_deg": 0},
        "survey": {"seed": 2, "fidelity": "balanced", "max_pulses": 60},
    })
    setup = PassSetup.build(config, PassOptions(max_pulses=60, progress=False))
    slots = next(setup.slot_chunks())
    return setup.physics.model, setup.cast_chunk(slots).batch, setup.seed


def test_dark_plate_in_turbid_water_behind_far_gate_is_masked_not_outside_gate():
    """A dark plate 1.75 m down in turbid harbour water with the far channel's gate opening at 25 ns: every pulse
    was ``outside_gate``, yet with the gate open from 0 ns every pulse is ``masked_by_backscatter``. Opening the gate
    ranges nothing: the column is what limits, and the cause must say so.

    Root cause: ``outside_gate`` was given wherever a channel shut at the echo's peak could see the echo alone and no
    open channel did, without asking whether that channel, opened, would range it: the column there hides the echo
    in the residual over the processor's baseline. A shut channel is now judged as if open at the peak; when the
    column would hide the echo there too, the cause is ``masked_by_backscatter``."""
    assert _lost_to(*_dark_plate_scene(0.0)) == {"masked_by_backscatter": 60}
    gated = _dark_plate_scene(25.0)
    assert _lost_to(*gated) == {"masked_by_backscatter": 60}
    assert assert_causes_match_definitions(*gated) == {"masked_by_backscatter": 60}


def test_pulses_too_faint_to_see_keep_the_causes_their_spans_give(monkeypatch):
    """Plates from 2 to 14 m down in turbid harbour water, dark to bright, the far channel open from 20 ns: some
    pulses are ranged, some lost to the column, and the farthest and darkest are too faint for any channel. Those are
    set aside as ``below_threshold`` from their echoes' total energy at the pulse's peak, without their span; with
    nothing set aside (every span computed), every pulse has the same cause."""
    import muls.ranging.returns as returns

    model = _model(study_water("turbid_harbor"), 20e-9)
    ranges = np.repeat(np.linspace(2.0, 14.0, 13), 6)
    batch = PulseBatch.flat_target(model.instrument, ranges, np.tile([0.01, 0.02, 0.05, 0.1, 0.3, 0.6], 13))
    set_aside = []
    faint_of = returns._too_faint_to_see

    def recorded(*args):
        faint = faint_of(*args)
        set_aside.append(int(faint.sum()))
        return faint

    monkeypatch.setattr(returns, "_too_faint_to_see", recorded)
    _, ranging = simulate(model, batch, seed=4)
    monkeypatch.setattr(returns, "_too_faint_to_see", lambda model, pulse_of, energy, todo, threshold: np.zeros(todo.size, bool))
    _, every_span = simulate(model, batch, seed=4)
    causes = ranging.dropout_cause
    assert 0 < sum(set_aside) < np.count_nonzero(causes >= 0)
    assert {"below_threshold", "masked_by_backscatter"} <= {DROPOUT_CAUSES[c] for c in causes[causes >= 0]}
    assert (causes == NO_DROPOUT).any()
    np.testing.assert_array_equal(causes, every_span.dropout_cause)
