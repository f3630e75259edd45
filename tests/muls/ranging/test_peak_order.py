"""muls/ranging/peak_order.py: the peaks in ranging's order."""

import numpy as np

from muls.ranging.peak_order import peak_order


def test_peak_order_is_the_two_stable_lexsorts_with_duplicates_dropped():
    """``peak_order`` (one pass over each pulse's few peaks) against numpy: a stable lexsort by (pulse, channel, index),
    repeats of (pulse, channel, index) dropped but the first, then a stable lexsort by (pulse, time); with runs found
    twice by overlapping windows, equal times on different channels, and pulses without peaks between."""
    rng = np.random.default_rng(11)
    pulse = np.sort(rng.choice(np.arange(0, 3000, 3), 4000))
    channel = rng.integers(1, 4, pulse.size)
    index = rng.integers(20, 30, pulse.size) + rng.choice([0.0, 0.25, 0.5], pulse.size)
    time_s = np.floor(index) * 1e-9 + 1e-12 * (pulse % 7)  # a function of (pulse, index), with ties across both
    order = np.lexsort((index, channel, pulse))
    keep = np.ones(order.size, bool)
    keep[1:] = ((pulse[order][1:] != pulse[order][:-1]) | (channel[order][1:] != channel[order][:-1])
                | (index[order][1:] != index[order][:-1]))
    order = order[keep]
    expected = order[np.lexsort((time_s[order], pulse[order]))]
    assert expected.size < pulse.size  # duplicates were there to drop
    np.testing.assert_array_equal(peak_order(pulse, channel, index, time_s), expected)
