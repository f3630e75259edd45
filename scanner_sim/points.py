"""Georeferencing: the instrument's ranged returns to world points with their ground truth attached."""

from __future__ import annotations

import numba
import numpy as np

#: Intensity scale: log10 of the echo's peak optical power [W] from 1 nW (0) to 1 W (65535).
INTENSITY_LOG10_RANGE_W = (-9.0, 0.0)


def intensity_from_power(peak_power_w: np.ndarray) -> np.ndarray:
    """LAS intensity (uint16) of echoes of peak optical power ``peak_power_w`` (n,) [W], log-scaled so that
    one number spans the channels' 10^4 dynamic range (see docs/outputs.md)."""
    lo, hi = INTENSITY_LOG10_RANGE_W
    level = (np.log10(np.maximum(peak_power_w, 1e-30)) - lo) / (hi - lo)
    return np.round(np.clip(level, 0.0, 1.0) * 65535.0).astype(np.uint16)


@numba.njit(cache=True)
def match_returns_to_hits(return_pulse, return_range_m, hit_offsets, hit_range_m, hit_energy, window_m):
    """Index of the hit that made each return: the most energetic hit of its pulse within ``window_m`` of the
    measured range (a merged echo is attributed to its strongest part), else the nearest in range; -1 if the
    pulse has no hit. Returns (n_returns,) int64; hits of pulse p are ``hit_offsets[p]:hit_offsets[p + 1]``."""
    out = np.full(return_pulse.shape[0], -1, np.int64)
    for i in range(return_pulse.shape[0]):
        p = return_pulse[i]
        best, best_energy, nearest, nearest_gap = -1, -1.0, -1, np.inf
        for j in range(hit_offsets[p], hit_offsets[p + 1]):
            gap = abs(hit_range_m[j] - return_range_m[i])
            if gap < nearest_gap:
                nearest, nearest_gap = j, gap
            if gap <= window_m and hit_energy[j] > best_energy:
                best, best_energy = j, hit_energy[j]
        out[i] = best if best >= 0 else nearest
    return out
