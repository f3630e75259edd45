"""Peaks in the digitised records, as the instrument finds them: runs over the local baseline, sub-sample
refinement on the known pulse shape, ranges from the CH0 reference peak (MULS Eq. 14), and the echo behind
each peak (:mod:`.peak_echoes`), put in ranging's order (:mod:`.peak_order`).

The baseline of each channel is the calibrated no-target record of the water (column backscatter plus
background, as measured in open water), and its noise the dark noise plus the shot noise of that baseline:
the processor knows its own noise model. A peak is the maximum of a run of samples whose residual over the
baseline exceeds half the threshold, kept when the maximum exceeds the threshold (hysteresis stops noise
on a peak's shoulder from splitting one echo in two). Echoes closer than a pulse merge into one run, and
its range is biased, as in a real instrument. Behind each peak, clipped or not, the search goes on once the
echo's modelled pulse is taken off; behind a clipped plateau, whose fitted pulse is known only to the plateau's
width, a run must clear the threshold over a share of that pulse too (:data:`CLIPPED_TAIL_TOLERANCE`), and an echo
that began before the plateau ended (its peak less than the pulse's rise behind the plateau) rose inside it, where
the channel cannot time it: it is left to a channel that does not clip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..infra.blocks import in_blocks
from ..infra.borrowed import borrowed
from ..infra.lookup import bracket, interp_at, on_geometric_grid, on_log_grid, steps_per_log
from ..infra.runtime import kernel
from ..instrument.channels import processor_sigma_lsb
from ..optics.optical_model import Echoes, OpticalModel, PulseBatch
from ..optics.sample_kernels import add_pulse_steps, baseline_values, pulse_value
from ..receiver.digitiser import Waveforms
from ..receiver.window_signal import sample_times
from .peak_echoes import dominant_echo
from .peak_order import peak_order

#: Most peaks kept per window and channel (more means noise, not echoes).
MAX_PEAKS_PER_WINDOW = 8
#: What the pulse fitted to a clipped plateau may be off by behind it, as a share of its value [-]: a run there must
#: clear the threshold over that too. A plateau is known only to its width, and one plateau may hold two echoes (CH1
#: over a plate and the sand 2 m behind), whose single fitted pulse leaves 9-13 % of its value behind the plateau
#: (docs/assumptions.md).
CLIPPED_TAIL_TOLERANCE = 0.25  # assumption: about twice the 9-13 % a plateau of two echoes leaves


@dataclass(frozen=True)
class Peaks:
    """Every peak of every signal channel (struct of arrays, shape (n,) each).

    pulse: batch index; channel: 1-based index into ``instrument.channels``; time_s: after emission;
    range_m: Eq. 14 range from the CH0 peak; amplitude_lsb: residual over the baseline at the peak;
    snr: amplitude over the local noise; saturated: the run touched the top code; peak_power_w: the
    amplitude as optical power at the receiver [W] (Eqs. 12-13 inverted for the channel).
    echo_index: the :class:`PulseBatch` return whose echo explains the peak (the way trimesh returns
    ``index_ray``): the most noise-free power at the peak among the echoes that can make a peak there (see
    :func:`dominant_echo`), or -1 where no echo explains the peak (noise, the water column, the window): the
    echoes together must reach half the detection threshold there, the level at which a run starts.
    """

    pulse: np.ndarray
    channel: np.ndarray
    time_s: np.ndarray
    range_m: np.ndarray
    amplitude_lsb: np.ndarray
    snr: np.ndarray
    saturated: np.ndarray
    peak_power_w: np.ndarray
    echo_index: np.ndarray

    def select(self, mask) -> Peaks:
        return Peaks(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))


FIT_CODES = {"pulse": 0, "gaussian": 1, "parabolic": 2, "sample_maximum": 3}
#: The fit code of plain peak detection: the highest sample (the first of a clipped plateau), no refinement.
SAMPLE_MAXIMUM = FIT_CODES["sample_maximum"]


class PeakSettings(NamedTuple):
    """Scalars of the peak kernel: threshold k [sigma], tail tolerance [-], top code, fit code (FIT_CODES),
    the pulse's peak delay after its start [s] and its unit-area value there [1/s]."""

    k_sigma: float
    tail_tolerance: float
    max_code: float
    fit: int
    peak_delay_s: float
    peak_density: float


class PeakSlots(NamedTuple):
    """Output slots of the peak kernel: ``MAX_PEAKS_PER_WINDOW`` per (window, channel), ``counts`` filled."""

    channel: np.ndarray
    index: np.ndarray
    amplitude: np.ndarray
    snr: np.ndarray
    saturated: np.ndarray
    counts: np.ndarray

    @classmethod
    def empty(cls, n_slots: int) -> PeakSlots:
        cap = n_slots * MAX_PEAKS_PER_WINDOW
        return cls(np.empty(cap, np.int64), np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap, np.bool_),
                   np.zeros(n_slots, np.int64))

    def blocks(self, first: int, end: int, n_chan: int) -> PeakSlots:
        """The slots of windows ``first:end`` of ``n_chan`` channels each (views)."""
        a, b = first * n_chan, end * n_chan
        return PeakSlots(*(f[a * MAX_PEAKS_PER_WINDOW:b * MAX_PEAKS_PER_WINDOW] for f in self[:-1]), self.counts[a:b])


def find_peaks(model: OpticalModel, batch: PulseBatch, records: Waveforms, echoes: Echoes) -> tuple[Peaks, np.ndarray]:
    """All peaks of all signal channels, with Eq. 14 ranges and the echo behind each, and the CH0 reference
    times (n_pulses,) [s]."""
    ins = model.instrument
    dig = ins.digitizer
    proc = ins.processing
    chans = model.channels
    n_windows, n_chan, _ = records.codes.shape
    out = PeakSlots.empty(n_windows * n_chan)
    fit = FIT_CODES[proc.peak_fit]
    settings = PeakSettings(proc.threshold_sigma, proc.tail_tolerance, float(dig.max_code), fit,
                            ins.pulse.peak_delay_s, ins.pulse.peak_per_s)
    synthesised = records.synthesised if records.synthesised is not None else np.ones((n_windows, n_chan), np.bool_)
    handed = records.baseline_w is not None
    baselines = records.baseline_w if handed else np.empty((0, 0))
    signal = chans.signal()

    def windows(a, b):  # windows a:b into their slots; their pulses index the whole batch
        _peaks(records.codes[a:b], synthesised[a:b], records.window_pulse[a:b], records.window_start[a:b],
               records.phase_s, -dig.pretrigger_s, dig.sample_interval_s, model.column, batch.background_w, signal,
               settings, model.fit_table, model.clip_table, out.blocks(a, b, n_chan), records.mode == "full",
               baselines[a:b] if handed else baselines, _search_scratch(records.codes.shape[2]))

    in_blocks(windows, n_windows)
    ref_index = np.concatenate(in_blocks(
        lambda a, b: _reference_peaks(records.reference[a:b], chans.dark_mean_lsb[0], fit, model.fit_table),
        batch.n_pulses))
    # Gather the filled slots: slot s holds counts[s] peaks from position s * MAX_PEAKS_PER_WINDOW.
    counts = out.counts
    first = np.repeat(np.arange(counts.size) * MAX_PEAKS_PER_WINDOW - (np.cumsum(counts) - counts), counts)
    slot = first + np.arange(first.size)
    w, c, idx = slot // (MAX_PEAKS_PER_WINDOW * n_chan), out.channel[slot] + 1, out.index[slot]
    pulse = records.window_pulse[w]
    phase = records.phase_s
    time_s = -dig.pretrigger_s + idx * dig.sample_interval_s + phase[pulse]
    ref_time = -dig.pretrigger_s + ref_index * dig.sample_interval_s + phase
    offsets = np.array([0.0] + [ch.range_offset_m for ch in ins.channels])
    range_m = 0.5 * model.water.speed_m_s * (time_s - ref_time[pulse]) + offsets[c]  # MULS Eq. 14
    order = peak_order(pulse, c, idx, time_s)
    pulse, c, time_s = pulse[order], c[order], time_s[order]
    amp, snr = out.amplitude[slot][order], out.snr[slot][order]
    power_w = amp / chans.lsb_per_w[c]  # MULS Eqs. 12-13 inverted
    # The echoes behind a peak must reach half the threshold (k sigma, sigma = amp / snr) there together.
    need_w = 0.5 * proc.threshold_sigma * (amp / snr) / chans.lsb_per_w[c]
    echo = dominant_echo(pulse, time_s, need_w, echoes, model.basis, ins.pulse)
    peaks = Peaks(pulse, c, time_s, range_m[order], amp, snr, out.saturated[slot][order], power_w, echo)
    return peaks, ref_time


# _refine, _add_echo and _clipped_peak run once a peak, not once a sample: called, not inlined into the numba IR of
# the peak kernels, they cut the first run's compile by about 1.2 s of CPU (_peaks 4.4 -> 2.6 s) for the same ranging
# time (balanced, three pairs alternated) and the same bits.
@kernel
def _refine(y0, y1, y2, fit, table):
    """(offset of the peak from the middle sample [samples], middle sample over peak) from three samples."""
    if fit == SAMPLE_MAXIMUM:
        return 0.0, 1.0
    den = y0 - 2.0 * y1 + y2
    if den >= 0.0:
        return 0.0, 1.0
    if fit == 1 and y0 > 0.0 and y1 > 0.0 and y2 > 0.0:
        l0, l1, l2 = math.log(y0), math.log(y1), math.log(y2)
        d = 0.5 * (l0 - l2) / (l0 - 2.0 * l1 + l2)
        return min(0.5, max(-0.5, d)), 1.0
    d = 0.5 * (y0 - y2) / den
    if fit != 0:
        return min(0.5, max(-0.5, d)), 1.0
    j = bracket(d, table.feature)
    return interp_at(d, j, table.feature, table.offset), interp_at(d, j, table.feature, table.centre)


@kernel(nogil=True)
def _reference_peaks(reference, dark_mean, fit, table):
    """Sub-sample index of the CH0 peak of each pulse."""
    n_pulses, n_ref = reference.shape
    out = np.empty(n_pulses)
    for p in range(n_pulses):
        best = 1
        for k in range(1, n_ref - 1):
            if reference[p, k] > reference[p, best]:
                best = k
        d, _ = _refine(reference[p, best - 1] - dark_mean, reference[p, best] - dark_mean,
                       reference[p, best + 1] - dark_mean, fit, table)
        out[p] = best + d
    return out


def _search_scratch(n_samples: int) -> tuple:
    """The peak search's scratch for windows of ``n_samples``: the sample times, baseline, residuals, sigmas and echo
    model (n,) float each, the open and blind samples (n,) bool each, and the stretches' first and end samples
    (n // 2 + 1,) int64 each (allocated by the caller, whose arrays the kernel may borrow)."""
    return (*(np.empty(n_samples) for _ in range(5)), np.empty(n_samples, np.bool_), np.empty(n_samples, np.bool_),
            np.empty(n_samples // 2 + 1, np.int64), np.empty(n_samples // 2 + 1, np.int64))


@kernel(nogil=True)
def _peaks(codes, synthesised, window_pulse, window_start, phase, t0, dt, col, background, chans, settings, fit_table,
           clip_table, out, sparse, baselines, scratch):
    """The peak search over every window and channel (module doc), into ``out``. ``sparse``: records mostly 0 (full
    records coded where the search reads, :func:`muls.receiver.channel_codes.ranging_codes`): a channel's residuals are
    computed, and its runs looked for, only within a sample of its nonzero codes (:func:`_code_segments`).
    ``baselines``: each window's calibrated baseline [W] ((n_windows, n_samples), the digitiser's, the numbers
    ``baseline_values`` gives), or empty: computed here. ``scratch``: :func:`_search_scratch`'s. Its arguments
    borrowed (:mod:`muls.infra.borrowed`)."""
    (codes, synthesised, window_pulse, window_start, phase, col, background, chans, fit_table, clip_table, out,
     baselines, scratch) = borrowed((codes, synthesised, window_pulse, window_start, phase, col, background, chans,
                                     fit_table, clip_table, out, baselines, scratch))
    n_windows, n_chan, n_samples = codes.shape
    cap = out.index.shape[0] // max(1, n_windows * n_chan)
    basis = col.basis
    k_sigma, tail_tolerance, max_code = settings.k_sigma, settings.tail_tolerance, settings.max_code
    out_c, out_idx, out_amp, out_snr, out_sat, counts = out
    # echoes: the model of the echoes found so far (known pulse shape)
    times, base_w, resid, sigma, echoes, open_, blind, seg_first, seg_end = scratch
    for w in range(n_windows):
        p = window_pulse[w]
        first = 0  # the first channel where a run may start; none: noise only (a dropout), no baseline needed
        while first < n_chan and not _may_run(codes, synthesised, w, first, chans, k_sigma):
            first += 1
        if first == n_chan:
            continue
        window_base = base_w
        if not sparse:
            sample_times(times, 0, n_samples, t0, dt, window_start[w], phase[p])
            if baselines.shape[0] > 0:
                window_base = baselines[w]
            else:
                baseline_values(base_w, times, background[p], col)
        for c in range(first, n_chan):
            slot = w * n_chan + c
            if c > first and not _may_run(codes, synthesised, w, c, chans, k_sigma):
                continue
            # The stretches of samples where a run may lie or the search may read: the whole window, or within a
            # sample of a nonzero code (a code of 0 lies under every run's level, so no run holds one).
            n_seg, seen = 1, 0
            if not sparse:
                seg_first[0], seg_end[0] = 0, n_samples
                seen = _residuals(codes[w, c], times, window_base, chans, c, max_code, open_, blind, sigma, resid,
                                  echoes)
            else:
                n_seg = _code_segments(codes[w, c], seg_first, seg_end)
                for g in range(n_seg):  # the same numbers as the whole window's, sample by sample
                    a, b = seg_first[g], seg_end[g]
                    sample_times(times, a, b, t0, dt, window_start[w], phase[p])
                    baseline_values(base_w[a:b], times[a:b], background[p], col)
                    seen += _residuals(codes[w, c, a:b], times[a:b], base_w[a:b], chans, c, max_code, open_[a:b],
                                       blind[a:b], sigma[a:b], resid[a:b], echoes[a:b])
            if seen == 0:
                continue  # blind wherever a run may lie: every residual there is zero
            for g in range(n_seg):
                k, end = seg_first[g], seg_end[g]
                clip_start, clip_scale = 0.0, 0.0  # the last plateau's fitted pulse here: start [s], area [LSB s]
                clip_end = -1.0  # the last plateau's end here, where its fitted pulse falls through the clip [samples]
                while k < end:
                    if resid[k] - echoes[k] <= 0.5 * k_sigma * sigma[k]:
                        k += 1
                        continue
                    start = k
                    top = k
                    clipped_first = -1
                    clipped_last = -1
                    while k < n_samples and resid[k] - echoes[k] > 0.5 * k_sigma * sigma[k]:
                        # The run's first plateau: its clipped samples, across a single unclipped one (noise at the
                        # top code); a later plateau is a later echo, found once this one's model is taken off.
                        if codes[w, c, k] >= max_code and (clipped_last < 0 or k - clipped_last <= 2):
                            if clipped_first < 0:
                                clipped_first = k
                            clipped_last = k
                        if resid[k] - echoes[k] > resid[top] - echoes[top] and (clipped_first < 0 or k <= clipped_last):
                            top = k
                        k += 1
                    # Keep a run that lies inside the window, rises to its maximum inside the gate, and clears the
                    # threshold there, over what the echoes already found leave if their shape is a little off.
                    # A clipped run may run on past the window's end once its plateau has ended inside it: the
                    # plateau and its two clip levels alone time it, whatever the tail does after.
                    if start == 0 or (k >= n_samples and not (clipped_first >= 0 and clipped_last < n_samples - 1)):
                        continue
                    if clipped_first < 0 and (top == start or not open_[top - 1]):
                        continue  # no rising edge inside the gate: a gate opening on a tail, not an echo
                    if clipped_first >= 0:
                        # The plateau may have begun before the run did (clipped samples with a small residual on a
                        # high baseline): it must rise from a sample the channel sees, or its width is unknown.
                        # A plateau that runs through samples the backscatter alone clips began in the column.
                        through_blind = False
                        while clipped_first > 0 and codes[w, c, clipped_first - 1] >= max_code:
                            clipped_first -= 1
                            through_blind = through_blind or blind[clipped_first]
                        if through_blind or clipped_first == 0 or not open_[clipped_first - 1] or blind[clipped_first - 1]:
                            continue
                        # A plateau that runs on into samples the backscatter alone clips ends there only in the
                        # residual: its width, so its amplitude and time, are unknown (the blind-zone edge).
                        if blind[clipped_last + 1] and codes[w, c, clipped_last + 1] >= max_code:
                            continue
                    if blind[top - 1]:
                        continue
                    height = resid[top] - echoes[top]
                    if clipped_first < 0 and height <= k_sigma * sigma[top] + tail_tolerance * echoes[top]:
                        continue
                    # Behind a plateau, over what its fitted pulse may be off by there too (CLIPPED_TAIL_TOLERANCE).
                    if clipped_first < 0 and height <= k_sigma * sigma[top] + CLIPPED_TAIL_TOLERANCE * clip_scale \
                            * pulse_value(times[top] - clip_start, basis):
                        continue
                    if counts[slot] >= cap:
                        continue
                    if clipped_first >= 0:
                        # Clipped: the plateau and the clip levels at its ends (over a baseline that may slope) give
                        # amplitude and peak time through the known pulse shape. A clip level that the echoes found
                        # before already explain leaves the plateau's edge, so its width, unknown.
                        level_first = resid[clipped_first] - echoes[clipped_first]
                        level_last = resid[clipped_last] - echoes[clipped_last]
                        if not (level_first > 0.0 and level_last > 0.0):
                            continue
                        idx, amp = _clipped_peak(clipped_first, clipped_last, level_first, level_last, clip_table)
                        idx += window_start[w]
                        # Plain peak detection reports the first sample at the top code; the plateau's model
                        # still places the echo that is taken off before the search goes on.
                        found = float(window_start[w] + clipped_first) if settings.fit == SAMPLE_MAXIMUM else idx
                        k = clipped_last + 1  # look again behind the plateau once the echo's model is taken off
                        clip_end = clipped_last + 0.5
                        clip_start = t0 + idx * dt + phase[p] - settings.peak_delay_s
                        clip_scale = amp / settings.peak_density
                    else:
                        d, ratio = _refine(resid[top - 1] - echoes[top - 1], height, resid[top + 1] - echoes[top + 1],
                                           settings.fit, fit_table)
                        idx = float(window_start[w] + top) + d
                        # An echo that began before the last plateau ended rose inside it: its light is in the
                        # plateau the single pulse was fitted to, so the fit and what it leaves are both off, and
                        # this channel cannot time it (a lower-gain channel that does not clip can).
                        if idx - window_start[w] - settings.peak_delay_s / dt < clip_end:
                            continue
                        found = idx
                        amp = height / ratio
                        k = top + 1  # look again behind this echo once its modelled shape is taken off
                    u = times[top + 1] - (t0 + idx * dt + phase[p]) + settings.peak_delay_s
                    _add_echo(echoes, top + 1, u, dt, amp / settings.peak_density, basis)
                    j = slot * cap + counts[slot]
                    out_c[j] = c
                    out_idx[j] = found
                    out_amp[j] = amp
                    out_snr[j] = amp / sigma[top]
                    out_sat[j] = clipped_first >= 0
                    counts[slot] += 1


@kernel(nogil=True)
def _residuals(codes, times, base_w, chans, c, max_code, open_, blind, sigma, resid, echoes):
    """Channel ``c``'s residuals over its baseline (codes (n,) at ``times`` (n,) [s], the uncut baseline ``base_w``
    (n,) [W] before the gate), in one loop without branches (it runs on SIMD lanes): ``open_``, ``blind`` (the
    backscatter alone clips the channel: nothing can be seen there, residual 0), ``sigma`` [LSB], ``resid`` [LSB],
    ``echoes`` zeroed. Returns how many samples the channel sees."""
    # The channel's constants in locals: numba tells LLVM nothing of aliasing, so a constant read from ``chans`` in the
    # loop is read again after every store (8 % of the peak kernel on 1,016-sample records). The expressions are
    # gate_open_at, level_lsb and processor_sigma_lsb, term for term.
    gate_open, gate_close = chans.gate_open_s[c], chans.gate_close_s[c]
    dark_mean, lsb_per_w = chans.dark_mean_lsb[c], chans.lsb_per_w[c]
    dark_var, shot = chans.dark_std_lsb[c] ** 2, chans.shot_lsb2_per_w[c]
    seen = 0
    for k in range(codes.shape[0]):
        is_open = (gate_open <= times[k]) & (times[k] < gate_close)
        base = base_w[k] if is_open else 0.0
        expected = dark_mean + lsb_per_w * base
        is_blind = expected >= max_code
        open_[k], blind[k] = is_open, is_blind
        seen += 0 if is_blind else 1
        sigma[k] = math.sqrt(dark_var + shot * base + 1.0 / 12.0)
        resid[k] = 0.0 if is_blind else codes[k] - expected
        echoes[k] = 0.0
    return seen


@kernel(inline="always")
def _may_run(codes, synthesised, w, c, chans, k_sigma):
    """Whether channel ``c`` of window ``w`` was synthesised and has a sample over half the threshold above its dark
    level, where a run may start (the baseline and its noise only raise the bar)."""
    if not synthesised[w, c]:
        return False
    highest = 0
    for k in range(codes.shape[2]):
        highest = max(highest, codes[w, c, k])
    return highest - chans.dark_mean_lsb[c] > 0.5 * k_sigma * processor_sigma_lsb(chans, c, 0.0)


@kernel(inline="always")
def _code_segments(row, seg_first, seg_end):
    """The stretches of ``row`` (n,) codes within a sample of a nonzero code, merged where they touch: their first
    samples and ends (exclusive) into ``seg_first``, ``seg_end``; returns how many. A run of the peak search lies
    inside one (its samples' codes are nonzero), and so does every sample the search reads around a run."""
    n, m, k = row.shape[0], 0, 0
    while k < n:
        if row[k] == 0:
            k += 1
            continue
        a = max(k - 1, 0)
        while k < n and row[k] != 0:
            k += 1
        b = min(k + 1, n)
        if m > 0 and a <= seg_end[m - 1]:
            seg_end[m - 1] = b
        else:
            seg_first[m], seg_end[m] = a, b
            m += 1
    return m


@kernel
def _add_echo(echoes, first, u, dt, scale, basis):
    """echoes[first:] += scale * w(u + i dt) (:func:`~muls.optics.sample_kernels.add_pulse_steps`), from the first
    sample at or after the echo's start."""
    if u < 0.0:  # the echo starts after this sample: first sample at or after its start
        skip = int(math.ceil(-u / dt))
        first += skip
        u += skip * dt
    if first < echoes.shape[0]:
        add_pulse_steps(echoes, first, u, dt, scale, math.inf, basis, echoes[:0])


@kernel
def _clipped_peak(first, last, level_first, level_last, table):
    """(peak index [samples], amplitude) of an echo clipped from sample ``first`` to ``last``, where the clip
    level above the baseline was ``level_first`` and ``level_last`` (both > 0): the amplitude A whose pulse exceeds
    those levels for exactly the plateau's width (rising and falling crossings half a sample outside it)."""
    ratio, rise, fall = table.ratio, table.rise, table.fall
    log_first, steps = math.log(ratio[0]), steps_per_log(ratio)
    log_level_first, log_level_last = math.log(level_first), math.log(level_last)
    width = last - first + 1.0
    lo = math.log(max(level_first, level_last, 1e-9))
    hi = lo - log_first
    for _ in range(32):  # bisection on log A: 2^-32 of the bracket; the grid is read at log(level / A)
        mid = 0.5 * (lo + hi)
        span = (on_log_grid(log_level_first - mid, log_first, steps, rise)
                + on_log_grid(log_level_last - mid, log_first, steps, fall))
        if span < width:
            lo = mid
        else:
            hi = mid
    a = math.exp(0.5 * (lo + hi))
    return first - 0.5 + on_geometric_grid(level_first / a, ratio, rise), a
