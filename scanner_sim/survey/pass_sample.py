"""A sample of a pass for a study that runs only some of its pulses: stretches of consecutive pulses spread evenly
over the whole pass, not its first pulses, whose ground may be unlike the rest of the survey (``real_site``'s first
line runs along its raster's no-data edge: 62 % of its first 30,000 pulses meet nothing, 12 % of the whole pass's).
"""

from __future__ import annotations


def spread_stretches(n_pulses: int, pulses: int, count: int) -> list[tuple[int, int]]:
    """(first pulse, pulses) of ``count`` stretches that together hold ``pulses`` of a pass's ``n_pulses`` pulses (in
    the order they fire), in pass order, without overlap: stretch i as near the middle of the pass's i-th of
    ``count`` equal shares as the stretches before it and the pulses after it allow. Sizes differ by one at most.
    The whole pass as one stretch when ``pulses`` >= ``n_pulses``."""
    if pulses >= n_pulses:
        return [(0, n_pulses)] if n_pulses else []
    count = max(1, min(count, pulses))
    sizes = [pulses // count + (i < pulses % count) for i in range(count)]
    out, end, left = [], 0, pulses
    for i, size in enumerate(sizes):
        centred = (2 * i + 1) * n_pulses // (2 * count) - size // 2
        left -= size
        first = min(max(centred, end), n_pulses - left - size)
        out.append((first, size))
        end = first + size
    return out
