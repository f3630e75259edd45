"""Where a batch's signal-channel records are synthesised: in ``full`` mode every sample of the record, in
``windowed`` mode a window around each cluster of a pulse's echoes (:func:`plan_windows`); the digitiser
(:mod:`muls.receiver.digitiser`) fills them."""

from __future__ import annotations

import math

import numpy as np

from ..infra.errors import check_choice
from ..infra.runtime import kernel
from ..optics.optical_model import Echoes, OpticalModel, PulseBatch

RECORD_MODES = ("windowed", "full")

#: Windowed mode: samples per echo window (at least; longer when a pulse's echoes chain, see _plan), and
#: how many of them precede an echo's start.
WINDOW_SAMPLES = 64
WINDOW_LEAD_S = 8e-9
#: Samples after an echo's start that its window must hold (a strongly clipped echo's run is ~50 ns long);
#: a pulse's echoes closer than this to the previous window's end share its window.
WINDOW_NEED_S = 56e-9


def plan_windows(model: OpticalModel, batch: PulseBatch, echoes: Echoes, mode: str):
    """(window_pulse, window_start, n_samples) of the signal-channel records to synthesise."""
    check_choice("record_mode", mode, RECORD_MODES)
    dig = model.instrument.digitizer
    n = batch.n_pulses
    if mode == "full":
        return np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64), dig.n_samples
    first = np.floor((echoes.delay_s + dig.pretrigger_s - WINDOW_LEAD_S) * dig.sample_rate_hz).astype(np.int64)
    usable = (echoes.energy_j > 0.0) & (first < dig.n_samples - WINDOW_SAMPLES)
    # each echo's window holds the lead and the samples a strongly clipped echo's run may take after it
    reach = max(WINDOW_SAMPLES, int(math.ceil((WINDOW_LEAD_S + WINDOW_NEED_S) * dig.sample_rate_hz)))
    pulses, starts, spans = _plan(echoes.offsets, np.maximum(first, 0), usable, reach)
    width = max(WINDOW_SAMPLES, int(spans.max())) if spans.size else WINDOW_SAMPLES
    width = min(width, dig.n_samples)
    return pulses, np.minimum(starts, dig.n_samples - width), width


@kernel(nogil=True)
def _plan(offsets, first, usable, reach):
    """Windows per pulse, one per cluster of echoes: an echo whose window would start before the cluster's
    earlier windows end (``reach`` samples after each window start) joins the cluster, whose window then
    runs to its last echo's reach. A run of samples that chains several echoes so lies whole in one window
    (the ranging drops a run cut by a window's edge, unless it is clipped and its plateau ends inside the
    window). ``first`` must ascend within a pulse (it does, from :class:`Echoes`' delays). Returns (pulse, first
    sample, samples the cluster spans) per window."""
    n = offsets.shape[0] - 1
    out_p = np.empty(first.shape[0], np.int64)
    out_s = np.empty(first.shape[0], np.int64)
    out_n = np.empty(first.shape[0], np.int64)
    m = 0
    for p in range(n):
        end = -(1 << 40)
        for j in range(offsets[p], offsets[p + 1]):  # ascending: Echoes are sorted by delay within a pulse
            if not usable[j]:
                continue
            s = first[j]
            if s < end:  # within the cluster: it only extends it
                end = max(end, s + reach)
                out_n[m - 1] = end - out_s[m - 1]
                continue
            end = s + reach
            out_p[m] = p
            out_s[m] = s
            out_n[m] = reach
            m += 1
    return out_p[:m], out_s[:m], out_n[:m]
