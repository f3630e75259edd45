"""Which signal channels of a record window can decide a return, judged on the noise-free signal before any noise
is drawn: the digitiser's ``deciding_only`` mode synthesises only those (the ``auto`` and ``fast`` levels).

Ranging keeps, for each echo, the unsaturated peak with the best SNR (:func:`muls.ranging.returns.choose_returns`), and
every normal the noise streams give is smaller than :data:`muls.infra.noise.NORMAL_BOUND` in magnitude, so some outcomes
are certain before the noise is drawn:

- a channel with no open sample that both escapes the column's clipping (the processor's calibrated baseline below
  the top code) and carries echo over that baseline finds no echo in the window: not needed;
- nor does a channel that the column blinds from the window's start, where the samples it then sees begin surely
  clipped and stay surely over half the threshold until they lie surely under it, with no later run of two samples
  (:func:`_lost_in_the_column`): its one run starts on a plateau that reaches back into the blind samples, which the
  peak search takes for the column and drops, echo and all. Where the noise's reach leaves a sample open, the bounds
  of the sample's own two normals, read from their hashes without drawing them, decide (the far-field channel of
  cable_survey, blind through its echo in six windows in ten);
- where the pulse's echoes lie within a sample of each other and their signal over the baseline is one hump, the
  channel (gate open and baseline unclipped throughout) that surely stays unclipped and surely clears the threshold
  at the hump, with the best least SNR, is kept; a channel surely clipped at the hump, or clipped from samples the
  column blinds through the hump, gives a saturated peak or none and cannot win; a channel whose best SNR, times
  :data:`SNR_MARGIN`, stays below the kept channel's least cannot win either, and is left out where its least SNR
  exceeds :data:`TIMED_SNR` (a weaker peak, timed by its noise, may be ranged as a duplicate return). Where every
  channel that sees the echo is clipped, the lowest-gain one is kept (its saturated peak is the return).

Anything else is kept: two humps (echoes apart), a gate edge or a blind stretch for the SNR comparison, a channel
that may or may not clip. What the pruning gives up, a pruned channel's false alarms and its duplicate returns of
an echo another channel ranges, docs/fidelity.md states.
"""

from __future__ import annotations

import math

import numpy as np

from ..infra.borrowed import borrowed
from ..infra.noise import (
    NORMAL_BOUND,
    dark_noise_stream,
    half_bits,
    hash_at,
    normal_bounds,
    shot_noise_stream,
    stream_base,
)
from ..infra.runtime import kernel
from ..instrument.channels import gate_open_at, level_lsb, processor_sigma_lsb
from .channel_codes import quantise

#: The kept channel's worst SNR must exceed a lower-gain channel's best by this factor for that one to be dropped:
#: room for the peak fit's amplitude ratio (the centre sample over the fitted peak, within a few per cent).
SNR_MARGIN = 1.25
#: [s] Most spread of a pulse's echo delays for its echo to count as one: a sample interval, so the echo is the
#: pulse's shape to a few per cent and the peak search finds it once. A footprint stretched over range (grazing
#: incidence) makes a long hump in which the search finds several peaks per channel, and which of them become
#: returns depends on how the other channels' peaks chain them (muls.ranging.returns's merge window).
ECHO_SPAN_S = 1e-9
#: A peak surely this far over its noise is timed within a fraction of a nanosecond (a 10 ns pulse's edge over
#: the SNR), far inside the 4 ns within which ranging merges the peaks of different channels into one return; a
#: weaker one, timed by its noise, can fall outside it and be ranged as a return of its own (a duplicate).
TIMED_SNR = 20.0


@kernel(nogil=True)
def deciding_channels(out, power, baseline, times, chans, max_code, k_sigma, echo_span_s, draws, scratch):
    """Fill ``out`` (n_channels,) bool with the channels of one window that can decide a return (module doc);
    ``scratch``: (3, n_channels) bool work space.

    power: (n,) noise-free optical power at the window's samples [W]; baseline: (n,) the processor's calibrated
    baseline there [W] (background plus the uncut column, as :mod:`muls.ranging.peaks` uses it); times: (n,) the sample
    times [s]; chans: the signal channels' :class:`muls.instrument.channels.ChannelArrays`; max_code: the top code [LSB];
    k_sigma: the detection threshold [sigma]; echo_span_s: the spread of the pulse's echo delays [s]; draws: the
    window's noise streams, (key, pulse id, index of its first sample, noise scale), whose bounds settle what the
    noise's reach leaves open (:func:`_lost_in_the_column`). Its arguments borrowed (:mod:`muls.infra.borrowed`).
    """
    out, power, baseline, times, chans, scratch = borrowed((out, power, baseline, times, chans, scratch))
    n_chan, n = out.shape[0], power.shape[0]
    whole, plain, clipped = scratch[0], scratch[1], scratch[2]
    tolerance = np.inf  # [W] one dark sigma of the most sensitive channel that sees the echo
    highest, most = power[0], power[0] - baseline[0]  # the largest power, and echo signal over the baseline
    for k in range(1, n):
        highest = max(highest, power[k])
        most = max(most, power[k] - baseline[k])
    top = 0  # the hump: the first sample of the largest echo signal (found after the maximum, which vectorises)
    while most == most and power[top] - baseline[top] != most and top < n - 1:
        top += 1
    for c in range(n_chan):
        # whole: gate open over the whole window; plain: no sample where the baseline alone clips it (a blind
        # sample's residual is 0); out: an open sample where the baseline alone leaves it below the top code, with
        # echo on it. Counted with bitwise tests, not short-circuit ones, so that the loop has no branch, the
        # channel's constants in locals (gate_open_at's and level_lsb's terms): 15 % faster than flags and calls.
        gate_open, gate_close = chans.gate_open_s[c], chans.gate_close_s[c]
        dark_mean, lsb_per_w = chans.dark_mean_lsb[c], chans.lsb_per_w[c]
        n_open, n_blind, n_echo = 0, 0, 0
        for k in range(n):
            is_open = (gate_open <= times[k]) & (times[k] < gate_close)
            blind = is_open & (dark_mean + lsb_per_w * baseline[k] >= max_code)
            n_open += is_open
            n_blind += blind
            n_echo += is_open & (not blind) & (power[k] > baseline[k])
        whole[c], plain[c], out[c] = n_open == n, n_blind == 0, n_echo > 0
        if out[c] and n_blind > 0 and n_open == n and _lost_in_the_column(c, power, baseline, chans, max_code, k_sigma,
                                                                          draws):
            out[c] = False
        if out[c]:
            tolerance = min(tolerance, processor_sigma_lsb(chans, c, 0.0) / chans.lsb_per_w[c])
    if echo_span_s > ECHO_SPAN_S or not _one_hump(power, baseline, top, tolerance):
        return
    best, best_snr = -1, -np.inf  # the surely unclipped, surely detected channel with the best least SNR
    for c in range(n_chan):
        least = _snr_bounds(c, power, baseline, top, chans)[0]
        candidate = out[c] and whole[c] and plain[c] and least > k_sigma and least > best_snr
        if candidate and _surely_unclipped(c, highest, chans, max_code):
            best, best_snr = c, least
    # a channel open at the hump and surely clipped there gives a saturated peak there, or none (clipped)
    clipped[:] = False
    lowest = -1  # the lowest-gain channel that gives a saturated peak at the hump
    for c in range(n_chan):
        if out[c] and gate_open_at(chans, c, times[top]):
            if plain[c]:
                clipped[c] = _surely_clipped(c, power[top], chans, max_code)
                if clipped[c] and (lowest < 0 or chans.lsb_per_w[c] < chans.lsb_per_w[lowest]):
                    lowest = c
            else:
                clipped[c] = _clipped_from_blindness(c, power, baseline, times, top, chans, max_code)
    if best < 0:
        # every channel that sees is clipped: the return is the lowest-gain saturated peak (muls.ranging.returns)
        every_clipped = lowest >= 0
        for c in range(n_chan):
            every_clipped = every_clipped and (clipped[c] or not out[c])
        if every_clipped:
            for c in range(n_chan):
                out[c] = c == lowest
        return
    for c in range(n_chan):
        if out[c] and c != best:
            least, most = _snr_bounds(c, power, baseline, top, chans)
            # its peak cannot win, and is timed too well to be ranged as a return of its own
            loses = whole[c] and plain[c] and SNR_MARGIN * most < best_snr and least > TIMED_SNR
            out[c] = not (clipped[c] or loses)


@kernel(nogil=True)
def _lost_in_the_column(c, power, baseline, chans, max_code, k_sigma, draws):
    """Channel c, its gate open over the whole window, surely finds no peak in it. The baseline alone clips its first
    samples and none after (a blind stretch, residual 0); its first run surely begins on a surely clipped sample next to
    that stretch, so the plateau reaches back into it and the peak search takes the run for the column and drops it
    (muls.ranging.peaks), echo and all. Any later run can only begin after a sample that may lie at or under the run
    level (half the threshold), and is then one sample long and surely unclipped: it has no rising edge and is dropped
    too. Each code is bounded by :func:`_noise_reach`, and where that leaves a test open, by the draws' own bounds
    (:func:`_drawn_code_range`; ``draws``: the window's (key, pulse id, first sample index, noise scale))."""
    n = power.shape[0]
    b = 0  # the first sample the channel sees
    while b < n and level_lsb(chans, c, baseline[b]) >= max_code:
        b += 1
    if b + 2 > n:
        return False
    key, pulse_id, first_index, noise_scale = draws
    dark_stream, dark_half = dark_noise_stream(c)
    shot_stream, shot_half = shot_noise_stream(chans.detector[c], chans.detector.shape[0])
    bounds = (noise_scale, first_index, stream_base(key, pulse_id, dark_stream), dark_half,
              stream_base(key, pulse_id, shot_stream), shot_half)
    if not _clipped_whatever_drawn(c, b, power[b], chans, max_code, bounds):
        return False
    # the first run: at b (its residual, max_code less the baseline, over the run level), else at b + 1, surely clipped
    if max_code - level_lsb(chans, c, baseline[b]) <= 0.5 * k_sigma * processor_sigma_lsb(chans, c, baseline[b]) \
            and not _clipped_whatever_drawn(c, b + 1, power[b + 1], chans, max_code, bounds):
        return False
    low_before = False  # the sample before may lie at or under the run level (so a later run may begin after it)
    may_begin = False  # this sample may begin a later run
    for k in range(b + 1, n):
        expected = level_lsb(chans, c, baseline[k])  # the baseline's code
        if expected >= max_code:
            return False  # blind again after samples it sees
        run_level = 0.5 * k_sigma * processor_sigma_lsb(chans, c, baseline[k])
        level, reach = level_lsb(chans, c, power[k]), _noise_reach(chans, c, power[k])
        lowest, highest = min(level - reach, max_code), min(level + reach, max_code)
        if (lowest - expected <= run_level < highest - expected) or lowest < max_code <= highest:
            lowest, highest = _drawn_code_range(c, k, power[k], chans, max_code, bounds)
        may_be_over = highest - expected > run_level
        if may_begin and may_be_over:
            return False  # a later run of two samples or more
        may_begin = low_before and k > b + 1 and may_be_over
        if may_begin and highest >= max_code:
            return False  # a later run that may clip
        low_before = lowest - expected <= run_level
    return True


@kernel(inline="always")
def _clipped_whatever_drawn(c, k, power, chans, max_code, bounds):
    """Channel c's code at sample k, at optical power ``power`` [W], is the top code whatever the noise: within the
    noise's reach, or else within its draws' bounds (:func:`_drawn_code_range`)."""
    return _surely_clipped(c, power, chans, max_code) or _drawn_code_range(c, k, power, chans, max_code,
                                                                           bounds)[0] >= max_code


@kernel(nogil=True)
def _drawn_code_range(c, k, power, chans, max_code, bounds):
    """(lowest, highest) code [LSB] channel c (gate open) can give at sample k of its window, at optical power
    ``power`` [W]: :func:`muls.receiver.channel_codes.channel_codes`'s expression with each of its two normals at the
    bound of its bits (:func:`muls.infra.noise.normal_bounds`, read from the hash, not drawn). Rounding is monotone, so
    the code lies between them. ``bounds``: (noise scale, the window's first sample index, then the base and half of
    the channel's dark-noise stream and of its detector's shot-noise stream)."""
    noise_scale, first_index, dark_base, dark_half, shot_base, shot_half = bounds
    dark_lo, dark_hi = normal_bounds(half_bits(hash_at(dark_base, first_index + k), dark_half))
    shot_lo, shot_hi = normal_bounds(half_bits(hash_at(shot_base, first_index + k), shot_half))
    level = level_lsb(chans, c, power)
    dark_std, shot_std = chans.dark_std_lsb[c], math.sqrt(chans.shot_lsb2_per_w[c] * power)
    return (float(quantise(level + noise_scale * (dark_std * dark_lo + shot_std * shot_lo), max_code)),
            float(quantise(level + noise_scale * (dark_std * dark_hi + shot_std * shot_hi), max_code)))


@kernel(inline="always")
def _noise_reach(chans, c, power):
    """Most that channel c's noise and rounding can move a code at optical power ``power`` [W] [LSB]."""
    return NORMAL_BOUND * (chans.dark_std_lsb[c] + math.sqrt(chans.shot_lsb2_per_w[c] * power)) + 0.5


@kernel(inline="always")
def _surely_unclipped(c, highest_power, chans, max_code):
    """No sample of channel c, whose gate is open throughout, can reach the top code whatever the noise: its level
    and the noise's reach both grow with the power, so the window's highest power [W] decides."""
    return level_lsb(chans, c, highest_power) + _noise_reach(chans, c, highest_power) < max_code


@kernel(inline="always")
def _surely_clipped(c, power, chans, max_code):
    """Channel c's sample at optical power ``power`` [W] reaches the top code, whatever the noise."""
    return level_lsb(chans, c, power) - _noise_reach(chans, c, power) >= max_code


@kernel(inline="always")
def _clipped_from_blindness(c, power, baseline, times, top, chans, max_code):
    """Channel c, which the baseline alone clips at some samples, surely stays clipped from its last such sample
    through the hump, which lies after all of them, with its gate open all along: the plateau at the hump then runs
    back into samples the backscatter clips, and the peak search takes it for the column, not an echo."""
    last = -1
    for k in range(power.shape[0]):
        if gate_open_at(chans, c, times[k]) and level_lsb(chans, c, baseline[k]) >= max_code:
            if k >= top:
                return False
            last = k
    if last < 0:
        return False
    for k in range(last, top + 1):
        if not (gate_open_at(chans, c, times[k]) and _surely_clipped(c, power[k], chans, max_code)):
            return False
    return True


@kernel(inline="always")
def _snr_bounds(c, power, baseline, top, chans):
    """(least, most) SNR of channel c's peak at the hump: its amplitude over the baseline, less or plus the noise's
    reach, over the processor's noise there (dark, rounding and the baseline's shot noise, as muls.ranging.peaks has it)."""
    amplitude = chans.lsb_per_w[c] * (power[top] - baseline[top])
    reach = _noise_reach(chans, c, power[top])
    sigma = processor_sigma_lsb(chans, c, baseline[top])
    return (amplitude - reach) / sigma, (amplitude + reach) / sigma


@kernel(inline="always")
def _one_hump(power, baseline, top, tolerance):
    """The echo signal r = power - baseline has one hump, at ``top``: going out from it either way, r never rises
    by more than ``tolerance`` [W] over both its lowest value since the hump and zero (a rise below the baseline,
    the column's deficit behind a cut shrinking, cannot start a run over it)."""
    lowest = np.inf
    for k in range(top, -1, -1):
        lowest = min(lowest, power[k] - baseline[k])
        if power[k] - baseline[k] > max(lowest, 0.0) + tolerance:
            return False
    lowest = np.inf
    for k in range(top, power.shape[0]):
        lowest = min(lowest, power[k] - baseline[k])
        if power[k] - baseline[k] > max(lowest, 0.0) + tolerance:
            return False
    return True
