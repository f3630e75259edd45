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
