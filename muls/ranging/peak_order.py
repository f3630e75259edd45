"""The peaks of a batch in ranging's order: by pulse, then time, then channel and sample index, each run found
twice by overlapping windows kept once (what :func:`muls.ranging.peaks.find_peaks` hands to the returns)."""

from __future__ import annotations

import numpy as np

from ..infra.runtime import kernel


@kernel(nogil=True)
def peak_order(pulse, channel, index, time_s):
    """(m,) int64: the peaks to keep, in ranging's order: by pulse, then time, then channel and sample index, where
    overlapping windows found one run twice (the same pulse, channel and index) the earlier one only.

    ``pulse`` (n,) must not decrease (the kernel's slots are by window, and windows by pulse), so each pulse's few
    peaks are sorted where they lie, and ``time_s`` is a function of pulse and index, so a run found twice has one
    time. The result equals a stable lexsort by (pulse, channel, index), the duplicates dropped, then a stable
    lexsort of that by (pulse, time)."""
    n = pulse.shape[0]
    order = np.arange(n)
    kept = np.empty(n, np.int64)
    m = 0
    start = 0
    while start < n:
        end = start + 1
        while end < n and pulse[end] == pulse[start]:
            end += 1
        for i in range(start + 1, end):  # insertion sort by (time, channel, index, slot)
            j, o = i - 1, order[i]
            while j >= start and _after(order[j], o, time_s, channel, index):
                order[j + 1] = order[j]
                j -= 1
            order[j + 1] = o
        for i in range(start, end):
            o = order[i]
            if i > start and channel[o] == channel[order[i - 1]] and index[o] == index[order[i - 1]]:
                continue
            kept[m] = o
            m += 1
        start = end
    return kept[:m]


@kernel(inline="always")
def _after(a, b, time_s, channel, index):
    """Peak ``a`` comes after peak ``b`` of the same pulse: by time, then channel, sample index and slot."""
    if time_s[a] != time_s[b]:
        return time_s[a] > time_s[b]
    if channel[a] != channel[b]:
        return channel[a] > channel[b]
    if index[a] != index[b]:
        return index[a] > index[b]
    return a > b
