"""A record window up to its noise: its sample times, its noise-free optical power (MULS Eq. 1: the echoes, the
water column as the pulse's targets cut it, the background), the processor's calibrated baseline and the channels
that can decide a return. The digitiser's two kernels (:mod:`muls.receiver.digitiser`) share it, inlined, and the peak
search reads its sample times.
"""

from __future__ import annotations

import math

import numpy as np

from ..infra.runtime import kernel
from ..instrument.channels import gate_open_at, level_lsb
from ..optics.sample_kernels import baseline_values, column_integrals_at
from .deciding_channels import deciding_channels


@kernel(inline="always")
def sample_times(out, first, end, t0_s, dt_s, first_index, phase_s):
    """out[k] = t0_s + (first_index + k) dt_s + phase_s [s] for first <= k < end: the times of samples of a window
    whose sample 0 is sample ``first_index`` of its record (:class:`Sampling`; :meth:`Waveforms.sample_times_s`)."""
    for k in range(first, end):
        out[k] = t0_s + (first_index + k) * dt_s + phase_s


def window_scratch(shape: tuple, cuts, chans) -> tuple:
    """For windows of ``shape`` (n_windows, n_channels, n): the (detectors,) bool of the detectors whose shot noise a
    window needs, and (times, power, baseline, uncut (n,) each, then the column cuts' times, shares and shares ahead),
    allocated by the digitiser's caller so that its kernels may borrow them (:mod:`muls.infra.borrowed`)."""
    n, k = shape[2], cuts.cut_tau_s.shape[1]
    n_detectors = int(chans.detector[:shape[1]].max()) + 1
    return np.empty(n_detectors, np.bool_), (np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(k),
                                             np.empty(k), np.empty(k + 1))


@kernel(inline="always")
def pulse_steps(col, dt_s):
    """The pulse basis's two exponentials' factors over a sample interval ``dt_s`` [s] (``col.basis``)."""
    return math.exp(-col.basis[0] * dt_s), math.exp(-col.basis[1] * dt_s)


@kernel(inline="always")
def window_signal(w, codes, clean, synthesised, baselines, window_pulse, window_start, sampling, col, cuts, echoes, chans,
            settings, shot_needed, scratch, steps, deciding):
    """Window w up to its noise: its sample times and noise-free power (MULS Eq. 1: echoes, the column as its targets
    cut it, background), the calibrated baseline where the channels are decided or the samples the search reads are
    chosen (into ``baselines`` too where it is not empty), the channels synthesised, their noise-free levels into
    ``clean`` (when kept) and the detectors whose shot noise is needed. Into ``scratch`` (:func:`window_scratch`);
    ``steps``: the pulse basis's two exponentials' factors over a sample interval; ``deciding``: None (every channel
    synthesised) or the deciding test's (3, channels) bool scratch. A None there prunes the test from the kernel
    numba compiles (its branch is dropped before typing): a run that decides no channels never compiles it (1.4 to
    2.9 s of a first run's CPU). Returns the window's pulse."""
    times, power, baseline, uncut, cut_t, cut_s, ahead = scratch
    n_chan, n_samples = codes.shape[1], codes.shape[2]
    basis, dt = col.basis, sampling.dt_s
    offsets, delay, energy = echoes.offsets, echoes.delay_s, echoes.energy_j
    cut_tau, cut_w = cuts.cut_tau_s, cuts.cut_weight
    ra, rb = steps
    p = window_pulse[w]
    # Echoes of pulse p (by delay) as three running sums over those started by time t:
    # sa = sum E exp(-a u), s1 = sum E u exp(-a u), sb = sum E exp(-b u), u = t - delay; then the echo
    # power is A s1 + B0 sa + C sb (the pulse basis), and a sample step only rescales the sums.
    sa, s1, sb = 0.0, 0.0, 0.0
    nxt = offsets[p]
    bg, b2, b3, b4 = cuts.background_w[p], basis[2], basis[3], basis[4]
    # The column's cuts by two-way time (insertion sort: a handful). Before a cut its share of the beam
    # sees the full column; from the cut on, its share is the module doc's tail of waveform.py, of the same
    # form as an echo, so it joins the three sums; ``ahead[i]``: the share of cuts i and later.
    n_cut = 0
    for c in range(cut_tau.shape[1]):
        if cut_w[p, c] != 0.0:
            i = n_cut
            while i > 0 and cut_t[i - 1] > cut_tau[p, c]:
                cut_t[i], cut_s[i] = cut_t[i - 1], cut_s[i - 1]
                i -= 1
            cut_t[i], cut_s[i] = cut_tau[p, c], cut_w[p, c]
            n_cut += 1
    ahead[n_cut] = 0.0
    for i in range(n_cut - 1, -1, -1):
        ahead[i] = ahead[i + 1] + cut_s[i]
    next_cut = 0
    sample_times(times, 0, n_samples, sampling.t0_s, dt, window_start[w], sampling.phase_s[p])
    # The uncut column, on SIMD lanes (uncut_column_value's numbers): where a cut is still ahead, and for the
    # baseline wherever that is needed.
    uncut_until = 0
    with_baseline = settings.deciding_only or settings.read_samples_only
    if with_baseline:
        uncut_until = n_samples
    elif n_cut > 0:
        while uncut_until < n_samples and times[uncut_until] < cut_t[n_cut - 1]:
            uncut_until += 1
    baseline_values(uncut[:uncut_until], times[:uncut_until], 0.0, col)
    for k in range(n_samples):
        t = times[k]
        if k > 0:
            s1 = (s1 + dt * sa) * ra
            sa *= ra
            sb *= rb
        while nxt < offsets[p + 1] and delay[nxt] <= t:
            u = t - delay[nxt]
            ea = energy[nxt] * math.exp(-basis[0] * u)
            sa += ea
            s1 += u * ea
            sb += energy[nxt] * math.exp(-basis[1] * u)
            nxt += 1
        while next_cut < n_cut and cut_t[next_cut] <= t:
            u = t - cut_t[next_cut]
            v0a, v1a, v0b = column_integrals_at(max(cut_t[next_cut], 0.0), col)
            ea = cut_s[next_cut] * math.exp(-basis[0] * u)
            sa += v0a * ea
            s1 += (u * v0a + v1a) * ea
            sb += cut_s[next_cut] * v0b * math.exp(-basis[1] * u)
            next_cut += 1
        power[k] = bg + b2 * s1 + b3 * sa + b4 * sb
        if next_cut < n_cut:
            power[k] += ahead[next_cut] * uncut[k]
    if with_baseline:
        background = cuts.background_w[p]
        for k in range(n_samples):  # the processor's calibrated baseline, as baseline_values gives it
            baseline[k] = background + uncut[k]
        if baselines.shape[0] > 0:
            for k in range(n_samples):  # (a loop: an array assignment compiles numba's shape-error formatting)
                baselines[w, k] = baseline[k]
    if deciding is not None:
        first_echo, last_echo = np.inf, -np.inf
        for j in range(offsets[p], offsets[p + 1]):
            if energy[j] > 0.0:
                first_echo, last_echo = min(first_echo, delay[j]), max(last_echo, delay[j])
        draws = (sampling.key, sampling.pulse_id[p], window_start[w], settings.noise_scale)
        deciding_channels(synthesised[w], power, baseline, times, chans, settings.max_code, settings.k_sigma,
                          last_echo - first_echo, draws, deciding)
    else:
        synthesised[w, :] = True
    if clean.shape[0] > 0:
        for c in range(n_chan):
            for k in range(n_samples):
                clean[w, c, k] = level_lsb(chans, c, power[k] if gate_open_at(chans, c, times[k]) else 0.0)
    # Dark noise: one normal per channel, half c % 2 of its pair's stream; shot noise: one normal per
    # detector (streams after those), shared by the channels of that detector (CH1 and CH2 split PMT1's
    # current).
    shot_needed[:] = False
    for c in range(n_chan):
        shot_needed[chans.detector[c]] |= synthesised[w, c]
    return p
