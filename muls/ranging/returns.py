"""Ranging as the instrument does it (MULS Eq. 14): the peaks of every channel (:mod:`muls.ranging.peaks`) grouped into
returns with one channel chosen per return, several returns per pulse, and a cause for every pulse left
without one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..infra.runtime import kernel
from ..optics.optical_model import Echoes, OpticalModel, PulseBatch
from ..optics.sample_kernels import add_pulse_steps, cut_column_power, uncut_column_value
from ..receiver.digitiser import Waveforms
from .causes import DROPOUT_CAUSES, NO_DROPOUT
from .peaks import Peaks, find_peaks


@dataclass(frozen=True)
class Ranging:
    """Result of ranging a batch: chosen returns, all peaks, and each pulse's dropout cause.

    returns: one row per return (channel chosen), with ``return_number`` / ``number_of_returns`` (n,) uint8;
    dropout_cause: (n_pulses,) int8, index into DROPOUT_CAUSES, or NO_DROPOUT when the pulse has a return; None
    when the caller did not ask why pulses were lost (:func:`range_batch`'s ``explain_dropouts``).
    reference_time_s: (n_pulses,) refined CH0 peak time.
    """

    returns: Peaks
    return_number: np.ndarray
    number_of_returns: np.ndarray
    peaks: Peaks
    dropout_cause: np.ndarray | None
    reference_time_s: np.ndarray


def choose_returns(model: OpticalModel, peaks: Peaks):
    """Group peaks of different channels into returns and keep one channel per return.

    The unsaturated peak with the best SNR wins (CH3 inside its gate, by its gain); a return whose every
    peak is clipped keeps the lowest-gain channel under ``saturation_policy = "keep"`` and is dropped under
    ``"drop"``. Returns (chosen Peaks, return_number, number_of_returns, pulses with a dropped return).
    """
    proc = model.instrument.processing
    n = peaks.pulse.shape[0]
    if n == 0:
        empty = np.zeros(0, np.uint8)
        return peaks, empty, empty, np.zeros(0, np.int64)
    new = np.ones(n, bool)
    new[1:] = (peaks.pulse[1:] != peaks.pulse[:-1]) | (np.diff(peaks.time_s) > proc.merge_window_s)
    gain = np.array([0.0] + [ch.volts_per_watt for ch in model.instrument.channels])
    score = np.where(peaks.saturated, -gain[peaks.channel], peaks.snr)
    best = best_of_clusters(new, peaks.saturated, score)
    all_clipped = peaks.saturated[best]
    dropped = peaks.pulse[best[all_clipped]] if proc.saturation_policy == "drop" else np.zeros(0, np.int64)
    if proc.saturation_policy == "drop":
        best = best[~all_clipped]
    chosen = peaks.select(best)  # ascending: clusters are runs of peaks in order
    pulse = chosen.pulse
    first = np.ones(pulse.shape[0], bool)
    first[1:] = pulse[1:] != pulse[:-1]
    group_start = np.maximum.accumulate(np.where(first, np.arange(pulse.shape[0]), 0))
    return_number = (np.arange(pulse.shape[0]) - group_start + 1).astype(np.uint8)
    counts = np.bincount(pulse, minlength=int(pulse.max()) + 1 if pulse.size else 0)
    number_of_returns = counts[pulse].astype(np.uint8)
    return chosen, return_number, number_of_returns, dropped


@kernel(nogil=True)
def best_of_clusters(new, saturated, score):
    """(k,) int64, ascending: the peak each cluster keeps, where a cluster is a run of peaks that ``new`` (n,) bool
    starts: the unsaturated one with the highest ``score`` before any saturated one, a tie going to the later peak,
    and NaN above every number, as the last of a stable lexsort by (cluster, unsaturated, score) would be."""
    n = new.shape[0]
    out = np.empty(n, np.int64)
    m = 0
    start = 0
    while start < n:
        end = start + 1
        while end < n and not new[end]:
            end += 1
        b = start
        for k in range(start + 1, end):
            if saturated[k] != saturated[b]:
                if not saturated[k]:
                    b = k
            elif not (score[k] < score[b]) and not (math.isnan(score[b]) and not math.isnan(score[k])):
                b = k
        out[m] = b
        m += 1
        start = end
    return out[:m]


def dropout_causes(model: OpticalModel, batch: PulseBatch, has_return, saturated_dropped, echoes: Echoes,
                   phase_s) -> np.ndarray:
    """Cause of each pulse without a return (index into DROPOUT_CAUSES), NO_DROPOUT otherwise; ``phase_s`` (n,) the
    pulses' sampling phases [s] (:attr:`Waveforms.phase_s`).

    One rule per cause, the first that holds (docs/outputs.md tables them): ``no_hit`` no echo begins within the
    record; ``blind_zone`` none that does carries light; ``saturated`` a clipped return was dropped; then, over the
    samples of the strongest echo (from its start to the end of its pulse, :func:`echo_span`) and at the
    sample where the echoes alone are highest (the echo's peak): ``masked_by_backscatter`` if in a channel open at
    the peak the echo alone clears the threshold over dark noise (k sigma) and the column hides it there: the
    residual over the processor's baseline (the open-water column and background) is at most k times the noise
    with the baseline's shot noise, or the column alone or the column with the echo clips the channel at an open
    sample of the span; ``outside_gate`` if no open channel would see the echo alone but a channel shut at its peak
    would see it and, were its gate open there, range it (the column neither hiding the echo in the residual nor
    clipping the channel at the peak); ``masked_by_backscatter`` also if the shut channels that would see the echo
    alone would all have it hidden by the column; ``below_threshold`` otherwise.
    """
    ins = model.instrument
    dig = ins.digitizer
    offsets, delay, energy = echoes.offsets, echoes.delay_s, echoes.energy_j
    record_end = dig.record_length_s
    cause = np.full(batch.n_pulses, NO_DROPOUT, np.int8)
    missing = ~np.asarray(has_return, bool)
    if not missing.any():
        return cause
    in_record = np.zeros(batch.n_pulses, bool)
    lit = np.zeros(batch.n_pulses, bool)
    pulse_of = np.repeat(np.arange(batch.n_pulses), np.diff(offsets))
    in_record[pulse_of[delay < record_end]] = True
    lit[pulse_of[(energy > 0.0) & (delay < record_end)]] = True
    cause[missing & ~in_record] = DROPOUT_CAUSES.index("no_hit")
    cause[missing & in_record & ~lit] = DROPOUT_CAUSES.index("blind_zone")
    sat = np.zeros(batch.n_pulses, bool)
    sat[np.asarray(saturated_dropped, np.int64)] = True
    cause[missing & lit & sat] = DROPOUT_CAUSES.index("saturated")
    todo = np.nonzero(missing & lit & ~sat)[0]
    chans = model.channels
    signal = slice(1, len(ins.channels) + 1)
    k = ins.processing.threshold_sigma
    dark = np.sqrt(chans.dark_std_lsb[signal] ** 2 + 1.0 / 12.0)  # each signal channel's dark noise and rounding [LSB]
    faint = _too_faint_to_see(model, pulse_of, energy, todo, k * dark)
    cause[todo[faint]] = DROPOUT_CAUSES.index("below_threshold")
    todo = todo[~faint]
    if todo.size == 0:
        return cause
    top_w = (dig.max_code - chans.dark_mean_lsb[signal]) / chans.lsb_per_w[signal]  # the power that clips each channel
    sampling = (-dig.pretrigger_s, dig.sample_interval_s)
    t_peak, echo_peak, column_peak, base_peak, clipped = _span_terms(
        todo, phase_s[todo], sampling, record_end, model.column, model.cuts(batch), echoes, ins.pulse.duration_s,
        chans.gate_open_s[signal], chans.gate_close_s[signal], top_w)
    # The residual the peak search measures: the record (column cut by the targets, echo, background) over the
    # processor's baseline (the open-water column and background).
    resid_peak = echo_peak + column_peak - base_peak
    masked = np.zeros(todo.size, bool)
    seen_open = np.zeros(todo.size, bool)
    ranged_if_open = np.zeros(todo.size, bool)
    hidden_if_open = np.zeros(todo.size, bool)
    for c in range(1, len(ins.channels) + 1):
        open_at_peak = (chans.gate_open_s[c] <= t_peak) & (t_peak < chans.gate_close_s[c])
        sigma = np.sqrt(dark[c - 1] ** 2 + chans.shot_lsb2_per_w[c] * base_peak)
        visible_alone = chans.lsb_per_w[c] * echo_peak > k * dark[c - 1]  # MULS Eqs. 12-13 in LSB
        under_column = chans.lsb_per_w[c] * resid_peak <= k * sigma
        masked |= open_at_peak & visible_alone & (under_column | clipped[:, c - 1])
        seen_open |= open_at_peak & visible_alone
        # A shut channel judged as if its gate were open at the peak: the column would hide the echo there too
        # when the residual stays under the threshold or the column (with the echo) clips the channel.
        clips_at_peak = np.maximum(base_peak, column_peak + echo_peak) >= top_w[c - 1]
        hidden = under_column | clips_at_peak
        ranged_if_open |= ~open_at_peak & visible_alone & ~hidden
        hidden_if_open |= ~open_at_peak & visible_alone & hidden
    cause[todo] = np.select(
        [masked, ranged_if_open & ~seen_open, hidden_if_open & ~seen_open],
        [DROPOUT_CAUSES.index("masked_by_backscatter"), DROPOUT_CAUSES.index("outside_gate"),
         DROPOUT_CAUSES.index("masked_by_backscatter")], DROPOUT_CAUSES.index("below_threshold"))
    return cause


#: Relative margin over the echoes' bound in :func:`_too_faint_to_see`: far above the rounding of the echoes' sum
#: (about 1e-14 of it), so that a pulse set aside could not have had a channel see its echo.
FAINT_MARGIN = 0.01


def _too_faint_to_see(model: OpticalModel, pulse_of, energy_j, todo, threshold_lsb) -> np.ndarray:
    """(len(todo),) bool: the pulses ``todo`` whose echoes (``energy_j`` [J] of batch pulse ``pulse_of``, each (m,))
    could not clear any signal channel's ``threshold_lsb`` (channels,) (k sigma of its dark noise and rounding) even
    all at their pulse's peak. No echo
    sum exceeds its energies' total times the unit-area pulse's maximum, so no channel sees their echo alone (MULS
    Eqs. 12-13 in LSB): they are ``below_threshold`` whatever the column does, without their span."""
    lsb_per_w = model.channels.signal().lsb_per_w
    total_j = np.bincount(pulse_of, weights=np.maximum(energy_j, 0.0))[todo]  # a lit pulse has echoes
    most_w = total_j * model.instrument.pulse.peak_per_s * (1.0 + FAINT_MARGIN)
    return ~np.any(lsb_per_w * most_w[:, None] > threshold_lsb, axis=1)


@kernel(inline="always")
def echo_span(start_s, duration_s, pretrigger_s, dt_s, phase_s):
    """(first, count): the samples of a record from ``start_s`` to ``start_s + duration_s`` [s], both included
    (sample k at ``-pretrigger_s + k dt_s + phase_s`` [s])."""
    first = math.ceil((start_s + pretrigger_s - phase_s) / dt_s)
    last = math.floor((start_s + duration_s + pretrigger_s - phase_s) / dt_s)
    return first, max(last - first + 1, 0)


@kernel(nogil=True)
def _span_terms(pulses, phase, sampling, record_end, col, cuts, echoes, extent, gate_open, gate_close, top_w):
    """The terms of pulse ``pulses[i]`` (sampling phase ``phase[i]`` [s]) over its span: the samples of its record
    (sample k at ``sampling[0] + k sampling[1] + phase[i]`` [s]) from the start of its strongest echo within the record
    (``delay_s < record_end``; the earliest of equals; energies finite) to that start plus ``extent`` [s]
    (:func:`echo_span`). Returns the peak's time [s] (the first sample where the echoes alone are highest), there the
    echoes alone, the column as the targets cut it plus background, and the processor's baseline (the uncut column
    plus background) [W], each (n,); and whether each signal channel (n, channels), at a sample where its gate
    (``gate_open``, ``gate_close`` [s]) is open, is clipped (power at or over ``top_w`` [W]) by the baseline alone or
    by the record (column and echo).

    Each echo's pulse is stepped from sample to sample by constant factors; the cut column is evaluated only where
    it decides a clip (the baseline under a channel's top and the baseline with the echo at or over it: the cut
    column never exceeds the baseline)."""
    n = pulses.shape[0]
    n_chan = top_w.shape[0]
    t0, dt = sampling
    t_peak, echo_peak = np.full(n, np.nan), np.zeros(n)
    column_peak, base_peak = np.zeros(n), np.zeros(n)
    clipped = np.zeros((n, n_chan), np.bool_)
    basis = col.basis
    first, count = np.empty(n, np.int64), np.empty(n, np.int64)
    for i in range(n):
        p = pulses[i]
        strongest, strongest_j = -1, 0.0
        for e in range(echoes.offsets[p], echoes.offsets[p + 1]):
            energy = echoes.energy_j[e] if echoes.delay_s[e] < record_end else -1.0
            if strongest < 0 or energy > strongest_j:
                strongest, strongest_j = e, energy
        first[i], count[i] = echo_span(echoes.delay_s[strongest], extent, -t0, dt, phase[i])
    most = 0  # a loop, not count.max(): numpy's max costs a second of compiling
    for i in range(n):
        most = max(most, count[i])
    times, echo = np.empty(most), np.empty(most)
    for i in range(n):
        p = pulses[i]
        last = count[i]
        if last == 0:
            continue
        for j in range(last):
            times[j] = t0 + (first[i] + j) * dt + phase[i]
        echo[:last] = 0.0
        for e in range(echoes.offsets[p], echoes.offsets[p + 1]):
            j = 0
            while j < last and times[j] < echoes.delay_s[e]:
                j += 1
            if j == last:
                continue
            add_pulse_steps(echo[:last], j, times[j] - echoes.delay_s[e], dt, echoes.energy_j[e], extent, basis,
                            echo[:0])
        peak = 0
        for j in range(last):
            t = times[j]
            if echo[j] > echo[peak]:
                peak = j
            base = cuts.background_w[p] + uncut_column_value(t, col)
            decides = False
            for c in range(n_chan):
                is_open = (gate_open[c] <= t) & (t < gate_close[c])
                if is_open and base >= top_w[c]:
                    clipped[i, c] = True
                decides = decides or (is_open and not clipped[i, c] and base + echo[j] >= top_w[c])
            if decides:
                record = cut_column_power(t, p, col, cuts) + echo[j]
                for c in range(n_chan):
                    if (gate_open[c] <= t) & (t < gate_close[c]) and record >= top_w[c]:
                        clipped[i, c] = True
        t_peak[i] = times[peak]
        echo_peak[i] = echo[peak]
        column_peak[i] = cut_column_power(times[peak], p, col, cuts)
        base_peak[i] = cuts.background_w[p] + uncut_column_value(times[peak], col)
    return t_peak, echo_peak, column_peak, base_peak, clipped


def range_batch(model: OpticalModel, batch: PulseBatch, records: Waveforms, echoes: Echoes | None = None,
                explain_dropouts: bool = True) -> Ranging:
    """Peaks, chosen returns and dropout causes of a digitised batch.

    Parameters
    ----------
    model : OpticalModel
        The model that made the records.
    batch : PulseBatch
        The batch's n_pulses pulses.
    records : Waveforms
        Their digitised records (:func:`muls.receiver.digitiser.digitise`).
    echoes : Echoes, optional
        ``model.echoes(batch)``, if the caller has it.
    explain_dropouts : bool
        Give each pulse without a return its cause (:func:`dropout_causes`); False leaves ``dropout_cause`` None,
        for a caller that reads only the returns.

    Returns
    -------
    Ranging
        The returns, every peak, each pulse's dropout cause (n_pulses,) int8 and its CH0 reference time
        (n_pulses,) [s].
    """
    echoes = echoes if echoes is not None else model.echoes(batch)
    peaks, ref_time = find_peaks(model, batch, records, echoes)
    chosen, return_number, number_of_returns, dropped = choose_returns(model, peaks)
    has_return = np.zeros(batch.n_pulses, bool)
    has_return[chosen.pulse] = True
    cause = dropout_causes(model, batch, has_return, dropped, echoes, records.phase_s) if explain_dropouts else None
    return Ranging(chosen, return_number, number_of_returns, peaks, cause, ref_time)
