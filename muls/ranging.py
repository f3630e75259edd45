"""Ranging as the instrument does it (MULS Eq. 14): the peaks of every channel (:mod:`muls.peaks`) grouped into
returns with one channel chosen per return, several returns per pulse, and a cause for every pulse left
without one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .detection import Records
from .peaks import Peaks, find_peaks
from .runtime import kernel
from .waveform import Echoes, OpticalModel, PulseBatch, optical_power

DROPOUT_CAUSES = ("no_hit", "blind_zone", "below_threshold", "saturated", "masked_by_backscatter", "outside_gate")
NO_DROPOUT = -1
#: Times over an echo, from its start to the end of its pulse, at which a channel's clipping by the column is judged.
ECHO_SPAN_POINTS = 9


@dataclass(frozen=True)
class Ranging:
    """Result of ranging a batch: chosen returns, all peaks, and each pulse's dropout cause.

    returns: one row per return (channel chosen), with ``return_number`` / ``number_of_returns`` (n,) uint8;
    dropout_cause: (n_pulses,) int8, index into DROPOUT_CAUSES, or NO_DROPOUT when the pulse has a return.
    reference_time_s: (n_pulses,) refined CH0 peak time.
    """

    returns: Peaks
    return_number: np.ndarray
    number_of_returns: np.ndarray
    peaks: Peaks
    dropout_cause: np.ndarray
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


def dropout_causes(model: OpticalModel, batch: PulseBatch, has_return, saturated_dropped, echoes: Echoes) -> np.ndarray:
    """Cause of each pulse without a return (index into DROPOUT_CAUSES), NO_DROPOUT otherwise.

    Judged on the noise-free signal of the strongest echo: ``blind_zone`` if no light reaches the receiver,
    ``saturated`` if clipped returns were dropped, ``masked_by_backscatter`` if in a channel open at its peak the
    echo alone would clear the threshold over dark noise but the column hides it (its shot noise at the peak, or
    its clipping anywhere over the echo, :data:`ECHO_SPAN_POINTS` times from its start to its end), ``outside_gate``
    if only a gated channel could see it and its gate is shut then, else ``below_threshold``.
    """
    ins = model.instrument
    dig = ins.digitizer
    offsets, delay, energy = echoes.offsets, echoes.delay_s, echoes.energy_j
    record_end = dig.record_length_s
    cause = np.full(batch.n_pulses, NO_DROPOUT, np.int8)
    missing = ~np.asarray(has_return, bool)
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
    if todo.size:
        strongest = np.full(batch.n_pulses, -1, np.int64)
        masked_energy = np.where(delay < record_end, energy, -1.0)
        order = np.lexsort((masked_energy, pulse_of))
        strongest[pulse_of[order]] = order  # last (largest energy) per pulse wins
        t_star = delay[strongest[todo]] + ins.pulse.peak_delay_s
        chans = model.channels
        total = _powers(t_star, todo, model.column, model.cuts(batch), echoes, ins.pulse.duration_s)
        base = batch.background_w[todo] + model.column_power_w(t_star)
        echo = np.maximum(total - model.column_power_w(t_star, batch.column_cut_m[todo].min(axis=1))
                          - batch.background_w[todo], 0.0)
        k = ins.processing.threshold_sigma
        # The column (and background) over the echo, from its start to its end: where it clips, no peak shows.
        span = delay[strongest[todo]][:, None] + ins.pulse.duration_s * np.linspace(0.0, 1.0, ECHO_SPAN_POINTS)
        span_base = batch.background_w[todo][:, None] + model.column_power_w(span.ravel()).reshape(span.shape)
        masked = np.zeros(todo.size, bool)
        gated_out = np.zeros(todo.size, bool)
        for c in range(1, len(ins.channels) + 1):
            in_gate = (chans.gate_open_s[c] <= t_star) & (t_star < chans.gate_close_s[c])
            amp = chans.lsb_per_w[c] * echo
            dark = math.sqrt(chans.dark_std_lsb[c] ** 2 + 1.0 / 12.0)
            noise = np.sqrt(dark**2 + chans.shot_lsb2_per_w[c] * base)
            open_over = (chans.gate_open_s[c] <= span) & (span < chans.gate_close_s[c])
            clipped = np.any(open_over & (chans.dark_mean_lsb[c] + chans.lsb_per_w[c] * span_base >= dig.max_code),
                             axis=1)
            visible_alone = amp > k * dark
            masked |= in_gate & visible_alone & ((amp <= k * noise) | clipped)
            gated_out |= ~in_gate & visible_alone
        cause[todo] = np.where(masked, DROPOUT_CAUSES.index("masked_by_backscatter"),
                               np.where(gated_out, DROPOUT_CAUSES.index("outside_gate"),
                                        DROPOUT_CAUSES.index("below_threshold")))
    return cause


@kernel(nogil=True)
def _powers(t, pulses, col, cuts, echoes, extent):
    out = np.empty(t.shape[0])
    for i in range(t.shape[0]):
        out[i] = optical_power(t[i], pulses[i], col, cuts, echoes, extent)
    return out


def range_batch(model: OpticalModel, batch: PulseBatch, records: Records, echoes: Echoes | None = None) -> Ranging:
    """Peaks, chosen returns and dropout causes of a digitised batch (``echoes``: ``model.echoes(batch)``)."""
    echoes = echoes if echoes is not None else model.echoes(batch)
    peaks, ref_time = find_peaks(model, batch, records, echoes)
    chosen, return_number, number_of_returns, dropped = choose_returns(model, peaks)
    has_return = np.zeros(batch.n_pulses, bool)
    has_return[chosen.pulse] = True
    cause = dropout_causes(model, batch, has_return, dropped, echoes)
    return Ranging(chosen, return_number, number_of_returns, peaks, cause, ref_time)
