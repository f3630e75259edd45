"""A channel's codes in one record window, from its noise-free power and its noise (MULS Eq. 13): every sample
(:func:`channel_codes`, from normals drawn a window at once), or only the samples the peak search may read
(:func:`ranging_codes`, which bounds each sample's largest code from its hashes before drawing anything)."""

from __future__ import annotations

import math

import numpy as np

from ..infra.noise import fill_normals_of, half_bits, normal_upper_bound
from ..infra.runtime import kernel
from ..instrument.channels import gate_open_at, level_lsb


@kernel(inline="always")
def quantise(u, max_code):
    """MULS Eq. 13: rounding, then clipping to [0, 2^bits - 1], as an int32 (a float-to-int conversion that
    vectorises; the code then fits any integer record type)."""
    return np.int32(min(max(math.floor(u + 0.5), 0.0), max_code))


@kernel(nogil=True, error_model="numpy")
def channel_codes(out, power, times, dark_normal, shot_normal, chans, c, max_code, noise_scale):
    """One channel's codes (n,) of a window from the power [W] at its sample times [s] and its two normals: no
    branch but selects, so the loop runs on SIMD lanes. The channel's constants in locals, as in
    :func:`ranging_codes` (the expressions are gate_open_at and level_lsb): 5 to 8 % of ``fast``'s digitiser."""
    dark_std, shot = chans.dark_std_lsb[c], chans.shot_lsb2_per_w[c]
    gate_open, gate_close = chans.gate_open_s[c], chans.gate_close_s[c]
    dark_mean, lsb_per_w = chans.dark_mean_lsb[c], chans.lsb_per_w[c]
    for k in range(out.shape[0]):
        gated = power[k] if (gate_open <= times[k]) & (times[k] < gate_close) else 0.0
        level = dark_mean + lsb_per_w * gated
        noise = dark_std * dark_normal[k] + math.sqrt(shot * gated) * shot_normal[k]
        out[k] = quantise(level + noise_scale * noise, max_code)  # MULS Eq. 13


#: How far [LSB] :func:`ranging_codes` keeps its bound on a code above the code's noise-free reach: far more than the
#: rounding of the sums it adds up, so the bound holds in floating point too.
READ_MARGIN_LSB = 1e-3


@kernel(nogil=True, error_model="numpy")
def ranging_codes(out, power, baseline, times, dark_hashes, dark_half, shot_hashes, shot_half, chans, c, max_code,
                  noise_scale, k_sigma, read, at, dark_normal, shot_normal, tails):
    """One channel's codes (n,) of a window where the peak search (:func:`muls.ranging.peaks._peaks`) may read them, 0
    elsewhere: the same codes as :func:`channel_codes` there, with the normals computed only there.

    The search reads a code where a run may start or go on (its residual over the baseline above half the threshold,
    ``k_sigma`` / 2 of the processor's sigma), where it may be clipped (the top code), and the samples next to those
    (a run's ends, the three-point fit, a plateau's edges). A code cannot be either where even its largest possible
    noise cannot take it there: each normal at most :func:`muls.infra.noise.normal_upper_bound` of its bits (read from the
    hash, not drawn), and a code is an integer, so one over the run level must reach the least integer over it. The
    echo model the search takes off a residual is never negative, and a code of 0 lies under every run's level and the
    top code, so the search finds the same runs. ``dark_hashes``, ``shot_hashes`` (n,): the
    positions of the channel's dark stream and its detector's shot stream, whose halves ``dark_half`` and
    ``shot_half`` are this channel's; ``read`` (n,) bool, ``tails`` (2 n,) int64, ``at`` (n,) int64, ``dark_normal``,
    ``shot_normal`` (n,) scratch."""
    # The channel's constants in locals (numba tells LLVM nothing of aliasing: read from ``chans`` in the loop, they
    # are read again after every store); the expressions are gate_open_at, level_lsb and processor_sigma_lsb.
    gate_open, gate_close = chans.gate_open_s[c], chans.gate_close_s[c]
    dark_mean, lsb_per_w = chans.dark_mean_lsb[c], chans.lsb_per_w[c]
    dark_std, shot = chans.dark_std_lsb[c], chans.shot_lsb2_per_w[c]
    n = out.shape[0]
    for k in range(n):
        is_open = (gate_open <= times[k]) & (times[k] < gate_close)
        gated = power[k] if is_open else 0.0
        base = baseline[k] if is_open else 0.0
        noise_most = (dark_std * normal_upper_bound(half_bits(dark_hashes[k], dark_half))
                      + math.sqrt(shot * gated) * normal_upper_bound(half_bits(shot_hashes[k], shot_half)))
        reach = dark_mean + lsb_per_w * gated + noise_scale * noise_most + 0.5 + READ_MARGIN_LSB  # MULS Eq. 13
        # A run holds codes over the baseline's level by more than half the threshold: integers from the least such
        # one up (the floor taken a hair low, so that rounding in the sum cannot raise it).
        level = dark_mean + lsb_per_w * base + 0.5 * k_sigma * math.sqrt(dark_std**2 + shot * base + 1.0 / 12.0)
        read[k] = (reach >= math.floor(level - READ_MARGIN_LSB) + 1.0) | (reach >= max_code)
        out[k] = 0
    m = 0
    for k in range(n):  # the samples to read and their neighbours, listed without a branch
        at[m] = k
        m += read[k] | read[max(k - 1, 0)] | read[min(k + 1, n - 1)]
    listed = at[:m]
    fill_normals_of(dark_hashes, dark_half, listed, dark_normal, tails)
    fill_normals_of(shot_hashes, shot_half, listed, shot_normal, tails)
    for i in range(m):
        k = at[i]
        gated = power[k] if gate_open_at(chans, c, times[k]) else 0.0
        noise = dark_std * dark_normal[i] + math.sqrt(shot * gated) * shot_normal[i]
        out[k] = quantise(level_lsb(chans, c, gated) + noise_scale * noise, max_code)  # MULS Eq. 13
