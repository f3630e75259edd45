"""The optical model's echoes (muls/optics/optical_model.py)."""

import numpy as np


def test_echoes_are_sorted_by_delay_within_each_pulse_as_a_stable_sort_leaves_them():
    """Pulses of 0 to 91 echoes (the reference level's footprint), with ties and with every delay equal: in place,
    the order numpy's stable lexsort gives, energy and source moved along (both the insertion sort of a few echoes
    and the delay buckets that come first for more)."""
    from muls.optics.optical_model import INSERTION_SORT_MAX, _sort_by_delay_within

    rng = np.random.default_rng(3)
    counts = np.array([0, 1, 7, INSERTION_SORT_MAX, INSERTION_SORT_MAX + 1, 40, 91, 91, 91])
    pulse = np.repeat(np.arange(counts.size), counts)
    delay = rng.integers(0, 30, pulse.size) * 1e-9 + 40e-9  # many ties
    delay[pulse == 7] = 55e-9  # one pulse whose echoes all arrive together
    delay[pulse == 8] = rng.normal(60e-9, 3e-9, 91)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    energy, source = rng.random(pulse.size), np.arange(pulse.size, dtype=np.int64)
    expected = np.lexsort((delay, pulse))
    d, e, s = delay.copy(), energy.copy(), source.copy()
    _sort_by_delay_within(offsets, d, e, s)
    np.testing.assert_array_equal(s, source[expected])
    np.testing.assert_array_equal(d, delay[expected])
    np.testing.assert_array_equal(e, energy[expected])


def test_the_stepped_pulse_is_the_pulse_evaluated_at_each_sample_until_its_extent():
    """add_pulse_steps steps the pulse basis's exponentials by constant factors: each sample it adds is, to
    rounding, the scaled pulse evaluated directly there (pulse_value), from ``first`` on and only while the pulse
    lasts; with the samples' own times (``exact_u``) it reads u from them instead of summing steps."""
    from muls.optics.sample_kernels import add_pulse_steps, pulse_value
    from muls.presets import mul2023

    pulse = mul2023().pulse
    basis = np.array(pulse.basis())
    dt, first, u0, scale, extent = 1e-9, 3, 0.4e-9, 2.5, pulse.duration_s
    out = np.zeros(80)
    add_pulse_steps(out, first, u0, dt, scale, extent, basis, out[:0])
    u = u0 + (np.arange(out.size) - first) * dt
    expected = np.where((np.arange(out.size) >= first) & (u < extent),
                        [scale * pulse_value(x, basis) for x in u], 0.0)
    assert np.count_nonzero(out) > 10 and out[:first].tolist() == [0.0] * first
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    times = 1e-9 * np.arange(-5, 75) + 0.3e-9
    exact = np.zeros(times.size)
    add_pulse_steps(exact, 5, 0.0, dt, 1.0, extent, basis, times)
    direct = np.where((times >= 0.0) & (times < extent), [pulse_value(x, basis) for x in times], 0.0)
    np.testing.assert_allclose(exact, direct, rtol=1e-12, atol=1e-12 * np.abs(direct).max())
