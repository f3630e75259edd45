"""From optical power to digitised records: beam splitter and gains (Eq. 12), range gate, dark and shot
noise, sampling with a random phase, quantisation and clipping (Eq. 13); CH0 the reference photodiode.

Two record modes share this code: ``full`` synthesises every sample of the record, ``windowed`` only
windows around the emission (for CH0) and around each echo (one window for a pulse's echoes that chain).
Noise is keyed by (seed, pulse id, channel, sample index), so both modes and any batching see identical
samples where they overlap.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..infra.blocks import in_blocks
from ..infra.borrowed import borrowed
from ..infra.noise import (
    NORMAL_BOUND,
    PHASE_STREAM,
    REFERENCE_STREAM,
    dark_noise_stream,
    fill_hashes,
    fill_normal_pairs,
    seed_key,
    shot_noise_stream,
    stream_base,
    uniform_at,
)
from ..infra.runtime import kernel
from ..optics.optical_model import Echoes, OpticalModel, PulseBatch
from ..optics.sample_kernels import add_pulse_steps
from .channel_codes import channel_codes, quantise, ranging_codes
from .record_windows import plan_windows
from .window_signal import pulse_steps, sample_times, window_scratch, window_signal

#: Windowed mode: samples of the CH0 reference record (the emitted pulse peaks ~21 samples in).
REFERENCE_SAMPLES = 40


@dataclass(frozen=True)
class Waveforms:
    """Digitised records of a batch (struct of arrays).

    reference: (n_pulses, n_ref) uint16 CH0 record from sample 0 (the whole record in ``full`` mode; under
    :func:`digitise`'s ``ranging_only`` only the samples around its peak, the others 0; under its ``deciding_only``
    all 0 for a pulse without a window, which has no return for it to time).
    codes: (n_windows, n_channels, n_samples) uint16 signal-channel windows, channel j is
    ``instrument.channels[j]`` (``full`` mode under ``ranging_only``: only the samples the peak search may read, the
    others 0). window_pulse: (n_windows,) batch index of each window's pulse;
    window_start: (n_windows,) index of the window's first sample in the full record. Sample k of the full
    record is taken at ``-pretrigger_s + k / sample_rate_hz + phase_s[pulse]``. noise_free_lsb and
    reference_noise_free_lsb: same shapes (float32, before noise, rounding and clipping) when asked for.
    synthesised: (n_windows, n_channels) bool, the channels synthesised in each window (the others' codes are 0),
    or None when every one was (:func:`digitise`'s ``deciding_only``). baseline_w: (n_windows, n_samples), the
    processor's calibrated baseline [W] at each window's samples, which the digitiser found to decide the channels
    and hands to the peak search (:func:`digitise`'s ``deciding_only`` and ``ranging_only`` of windows), or None.
    """

    reference: np.ndarray
    codes: np.ndarray
    window_pulse: np.ndarray
    window_start: np.ndarray
    phase_s: np.ndarray
    mode: str
    noise_free_lsb: np.ndarray | None = None
    reference_noise_free_lsb: np.ndarray | None = None
    synthesised: np.ndarray | None = None
    baseline_w: np.ndarray | None = None

    @property
    def n_pulses(self) -> int:
        return int(self.phase_s.shape[0])

    def sample_times_s(self, model: OpticalModel) -> np.ndarray:
        """(n_windows, n_samples) sample times [s] after emission."""
        dig = model.instrument.digitizer
        k = self.window_start[:, None] + np.arange(self.codes.shape[2])[None, :]
        return -dig.pretrigger_s + k * dig.sample_interval_s + self.phase_s[self.window_pulse][:, None]

    def reference_times_s(self, model: OpticalModel) -> np.ndarray:
        """(n_pulses, n_ref) sample times [s] of the CH0 record."""
        dig = model.instrument.digitizer
        k = np.arange(self.reference.shape[1])[None, :]
        return -dig.pretrigger_s + k * dig.sample_interval_s + self.phase_s[:, None]


def sampling_phase_s(key: np.uint64, pulse_id: np.ndarray, sample_interval_s: float) -> np.ndarray:
    """Random sampling phase of each pulse in [0, sample interval) [s] (the ADC clock is free-running)."""
    return _phases(key, np.asarray(pulse_id, np.int64)) * sample_interval_s


@kernel(nogil=True)
def _phases(key, pulse_id):
    out = np.empty(pulse_id.shape[0])
    for i in range(pulse_id.shape[0]):
        out[i] = uniform_at(stream_base(key, pulse_id[i], PHASE_STREAM), 0)
    return out


class Sampling(NamedTuple):
    """How the digitiser samples a batch: sample k of pulse p is taken at ``t0_s + k dt_s + phase_s[p]`` [s
    after emission]; its noise is keyed by (``key``, ``pulse_id[p]``, stream, k)."""

    t0_s: float
    dt_s: float
    phase_s: np.ndarray
    pulse_id: np.ndarray
    key: np.uint64


def digitise(model: OpticalModel, batch: PulseBatch, seed, mode: str = "windowed",
             keep_noise_free: bool = False, noise: bool = True, echoes: Echoes | None = None,
             deciding_only: bool = False, ranging_only: bool = False) -> Waveforms:
    """Digitised records of every channel for a batch of pulses (MULS Eqs. 1, 12, 13).

    ``noise=False`` leaves only quantisation and clipping (closed-form checks); the sampling phase stays.
    ``echoes``: ``model.echoes(batch)`` if already computed. ``deciding_only``: in each window, synthesise only the
    channels that can decide a return (:mod:`muls.receiver.deciding_channels`); the others' codes are 0 and
    ``Waveforms.synthesised`` says which; and the CH0 reference only of the pulses with a window (it times their
    returns; a pulse without one has none). ``ranging_only``: only the samples the ranging may read get their codes,
    the others 0: of each CH0 record the samples around its peak (:func:`_reference`), and of ``full`` records the
    samples where a run of the peak search may start or go on or a code may clip, and those beside them
    (:func:`muls.receiver.channel_codes.ranging_codes`; windows are mostly echo, and draw faster whole). The same
    peaks and ranges, the records not whole; with ``deciding_only``, windows also hand the peak search the baseline
    the channels were decided on (``Waveforms.baseline_w``, the numbers it would compute). A large batch is
    digitised in blocks on numba's thread count (:mod:`muls.infra.blocks`), the same bytes as in one.
    """
    ins = model.instrument
    dig = ins.digitizer
    key = seed_key(seed)
    echoes = echoes if echoes is not None else model.echoes(batch)
    window_pulse, window_start, n_samples = plan_windows(model, batch, echoes, mode)
    phase = sampling_phase_s(key, batch.pulse_id, dig.sample_interval_s)
    sampling = Sampling(-dig.pretrigger_s, dig.sample_interval_s, phase, batch.pulse_id.astype(np.int64), key)
    chans = model.channels
    n_ref = dig.n_samples if mode == "full" else REFERENCE_SAMPLES
    shape, ref_shape = (window_pulse.shape[0], len(ins.channels), n_samples), (batch.n_pulses, n_ref)
    codes, reference = np.empty(shape, np.uint16), np.empty(ref_shape, np.uint16)
    clean = np.empty(shape if keep_noise_free else (0, 0, 0), np.float32)
    ref_clean = np.empty(ref_shape if keep_noise_free else (0, 0), np.float32)
    pulse = ins.pulse
    synthesised = np.empty(shape[:2], np.bool_)
    settings = DigitiserSettings(float(dig.max_code), 1.0 if noise else 0.0, deciding_only,
                                 ins.processing.threshold_sigma, ranging_only and noise and mode == "full")
    # The peak search reads the baseline the channels were decided on instead of computing it again (the same
    # numbers): 3.3 of its 14.8 ms on 10,000 cable_survey windows at ``fast``.
    handed = ranging_only and deciding_only and mode == "windowed"
    baselines = np.empty((shape[0], shape[2]) if handed else (0, 0))
    cuts, signal = model.cuts(batch), chans.signal()
    lsb_per_density = ins.reference.peak_lsb / pulse.peak_per_s

    digitise_windows, noise_scratch = ((_digitise_read_samples, _read_samples_scratch) if settings.read_samples_only
                                       else (_digitise, _noise_scratch))

    def windows(a, b):  # windows a:b; their pulses index the whole batch
        deciding = np.empty((3, shape[1]), np.bool_) if deciding_only else None  # the deciding test's scratch
        shot_needed, scratch = window_scratch(shape, cuts, signal)
        digitise_windows(codes[a:b], clean[a:b], synthesised[a:b], baselines[a:b], window_pulse[a:b], window_start[a:b],
                         sampling, model.column, cuts, echoes, signal, settings, deciding, shot_needed, scratch,
                         noise_scratch(shape, shot_needed))

    needed = np.ones(batch.n_pulses, np.bool_)
    if deciding_only:
        needed[:] = False
        needed[window_pulse] = True

    def references(a, b):  # the CH0 records of pulses a:b
        _reference(reference[a:b], ref_clean[a:b], sampling._replace(phase_s=phase[a:b], pulse_id=sampling.pulse_id[a:b]),
                   model.basis, pulse.duration_s, lsb_per_density, chans.dark_mean_lsb[0], chans.dark_std_lsb[0],
                   settings.max_code, settings.noise_scale, ranging_only, needed[a:b],
                   (np.empty(n_ref), np.empty(0), np.empty(2 * n_ref, np.int64), np.empty(n_ref), np.empty(n_ref)))

    in_blocks(windows, shape[0])
    in_blocks(references, batch.n_pulses)
    return Waveforms(reference, codes, window_pulse, window_start, phase, mode,
                   clean if keep_noise_free else None, ref_clean if keep_noise_free else None,
                   synthesised if deciding_only else None, baselines if handed else None)


@kernel(nogil=True)
def _reference(reference, clean, sampling, basis, extent, lsb_per_density, dark_mean, dark_std, max_code,
               noise_scale, peak_only, needed, scratch):
    """The CH0 records (n_pulses, n_ref) from sample 0 (MULS Eqs. 2, 13 through the photodiode). ``peak_only``:
    only the samples that can hold the record's highest code or flank it (what :func:`muls.ranging.peaks._reference_peaks`
    reads) get their noise and code, the others code 0: a sample whose noise-free level lies more than two noise
    bounds (:data:`muls.infra.noise.NORMAL_BOUND` sigma and a rounding each) under the highest level is below the highest
    code whatever the draws, and so is 0. ``needed`` (n_pulses,) bool: the pulses whose codes are drawn, the others' all 0.
    ``scratch``: the normals' (n_ref,), an empty low half, the tails' (2 n_ref,) int64, the levels' and the sample
    times' (n_ref,). Its arguments borrowed (:mod:`muls.infra.borrowed`)."""
    reference, clean, sampling, basis, needed, scratch = borrowed((reference, clean, sampling, basis, needed, scratch))
    n_pulses, n_ref = reference.shape
    keep = clean.shape[0] > 0
    bound = noise_scale * dark_std * NORMAL_BOUND + 0.5
    normal, no_low, tails, levels, times = scratch
    for p in range(n_pulses):
        if not (needed[p] or keep):
            reference[p, :] = 0
            continue
        # the filtered pulse (MULS Eq. 2) from emission, at each sample's own time
        sample_times(times, 0, n_ref, sampling.t0_s, sampling.dt_s, 0, sampling.phase_s[p])
        levels[:] = 0.0
        start = 0
        while start < n_ref and times[start] < 0.0:
            start += 1
        if start < n_ref:
            add_pulse_steps(levels, start, 0.0, sampling.dt_s, lsb_per_density, extent, basis, times)
        if keep:
            for k in range(n_ref):
                clean[p, k] = levels[k] + dark_mean
        if not needed[p]:
            reference[p, :] = 0
            continue
        first, last = 0, n_ref - 1
        if peak_only:
            first, last = _reference_span(levels, dark_mean, bound, max_code)
            reference[p, :first] = 0
            reference[p, last + 1:] = 0
        fill_normal_pairs(stream_base(sampling.key, sampling.pulse_id[p], REFERENCE_STREAM), first,
                          normal[: last + 1 - first], no_low, tails)
        for k in range(first, last + 1):
            reference[p, k] = quantise(levels[k] + dark_mean + noise_scale * dark_std * normal[k - first],
                                        max_code)


@kernel(inline="always")
def _reference_span(levels, dark_mean, bound, max_code):
    """(first, last) samples of a CH0 record that can hold its highest code among samples 1 to n - 2 (where the peak
    search looks) or flank it, from the noise-free ``levels`` (n,) [LSB over the dark mean] and the most a code can lie
    from its noise-free value, ``bound`` [LSB]: every sample above the highest level less two bounds, or able to reach
    the top code, and one more on each side."""
    n = levels.shape[0]
    top = -np.inf
    for k in range(1, n - 1):
        top = max(top, levels[k])
    first, last = n, -1
    for k in range(n):
        if levels[k] + 2.0 * bound >= top or levels[k] + dark_mean + bound >= max_code:
            first, last = min(first, k), max(last, k)
    return max(0, first - 1), min(n - 1, last + 1)


class DigitiserSettings(NamedTuple):
    """Scalars of the digitiser kernel: the top code [LSB], the noise's scale (1, or 0 for no noise), whether only
    the channels that can decide a return are synthesised (:mod:`muls.receiver.deciding_channels`), the threshold [sigma]
    that decides it and that the peak search uses, and whether only the samples the peak search may read get their
    codes (:func:`muls.receiver.channel_codes.ranging_codes`)."""

    max_code: float
    noise_scale: float
    deciding_only: bool
    k_sigma: float
    read_samples_only: bool = False


def _noise_scratch(shape: tuple, shot_needed: np.ndarray) -> tuple:
    """The dark and shot normals' (2 pairs, n) scratch of windows of ``shape`` (n_windows, n_channels, n) whose
    detectors ``shot_needed`` lists, the tails' (2 n,) int64 scratch and an empty low half."""
    n = shape[2]
    return (np.empty((2 * ((shape[1] + 1) // 2), n)), np.empty((2 * ((shot_needed.shape[0] + 1) // 2), n)),
            np.empty(2 * n, np.int64), np.empty(0))


def _read_samples_scratch(shape: tuple, shot_needed: np.ndarray) -> tuple:
    """:func:`_digitise_read_samples`'s scratch of windows of ``shape``: the hashes' (dark pairs + shot pairs, n)
    uint64, the samples read (n,) bool, the tails' (2 n,) int64 and the listed samples' (n,) int64 scratch, and the
    two normals' (n,) each."""
    n = shape[2]
    pairs = (shape[1] + 1) // 2 + (shot_needed.shape[0] + 1) // 2
    return (np.empty((pairs, n), np.uint64), np.empty(n, np.bool_), np.empty(2 * n, np.int64), np.empty(n, np.int64),
            np.empty(n), np.empty(n))


@kernel(nogil=True)
def _digitise(codes, clean, synthesised, baselines, window_pulse, window_start, sampling, col, cuts, echoes, chans,
              settings, deciding, shot_needed, scratch, noise):
    """The signal windows' codes (MULS Eqs. 1, 12, 13) into ``codes``, every sample drawn, with ``clean``,
    ``synthesised`` and, where ``baselines`` is not empty ((n_windows, n_samples)), each window's calibrated baseline
    [W] (:func:`digitise`); ``deciding``: None, or the deciding test's scratch where only the channels that can decide
    a return are synthesised (:func:`~muls.receiver.window_signal.window_signal`); ``shot_needed``, ``scratch``:
    :func:`~muls.receiver.window_signal.window_scratch`'s, ``noise``: :func:`_noise_scratch`'s. Its arguments but
    ``deciding`` borrowed (:mod:`muls.infra.borrowed`; ``deciding`` is the switch that leaves the test out)."""
    (codes, clean, synthesised, baselines, window_pulse, window_start, sampling, col, cuts, echoes, chans, shot_needed,
     scratch, noise) = borrowed((codes, clean, synthesised, baselines, window_pulse, window_start, sampling, col, cuts,
                                 echoes, chans, shot_needed, scratch, noise))
    dark_normal, shot_normal, tails, no_low = noise
    n_windows, n_chan = codes.shape[0], codes.shape[1]
    steps = pulse_steps(col, sampling.dt_s)
    times, power = scratch[0], scratch[1]
    for w in range(n_windows):
        p = window_signal(w, codes, clean, synthesised, baselines, window_pulse, window_start, sampling, col, cuts, echoes,
                    chans, settings, shot_needed, scratch, steps, deciding)
        # Every sample: drawn a window at once for the pairs a synthesised channel needs.
        first_index = window_start[w]
        _draw_pairs(dark_normal, synthesised[w], sampling, p, dark_noise_stream(0)[0], first_index, no_low, tails)
        _draw_pairs(shot_normal, shot_needed, sampling, p, shot_noise_stream(0, n_chan)[0], first_index, no_low,
                    tails)
        for c in range(n_chan):
            if synthesised[w, c]:
                channel_codes(codes[w, c], power, times, dark_normal[c], shot_normal[chans.detector[c]], chans, c,
                              settings.max_code, settings.noise_scale)
            else:
                codes[w, c, :] = 0


@kernel(nogil=True)
def _digitise_read_samples(codes, clean, synthesised, baselines, window_pulse, window_start, sampling, col, cuts,
                           echoes, chans, settings, deciding, shot_needed, scratch, work):
    """:func:`_digitise` with only the samples the peak search may read coded, the others 0
    (:func:`muls.receiver.channel_codes.ranging_codes`; :func:`digitise`'s ``ranging_only`` of full records); ``work``:
    :func:`_read_samples_scratch`'s. A kernel of its own so that a run which never asks for it does not compile it
    and the draws by list it calls; the window up to its noise is :mod:`.window_signal`'s, as :func:`_digitise`'s."""
    (codes, clean, synthesised, baselines, window_pulse, window_start, sampling, col, cuts, echoes, chans, shot_needed,
     scratch, work) = borrowed((codes, clean, synthesised, baselines, window_pulse, window_start, sampling, col, cuts,
                                echoes, chans, shot_needed, scratch, work))
    hashes, read, tails, listed, dark_normal, shot_normal = work
    n_windows, n_chan = codes.shape[0], codes.shape[1]
    n_pairs = (n_chan + 1) // 2
    steps = pulse_steps(col, sampling.dt_s)
    times, power, baseline = scratch[0], scratch[1], scratch[2]
    for w in range(n_windows):
        p = window_signal(w, codes, clean, synthesised, baselines, window_pulse, window_start, sampling, col, cuts, echoes,
                    chans, settings, shot_needed, scratch, steps, deciding)
        first_index = window_start[w]
        _hash_pairs(hashes[:n_pairs], synthesised[w], sampling, p, dark_noise_stream(0)[0], first_index)
        _hash_pairs(hashes[n_pairs:], shot_needed, sampling, p, shot_noise_stream(0, n_chan)[0], first_index)
        for c in range(n_chan):
            if synthesised[w, c]:
                d = chans.detector[c]
                ranging_codes(codes[w, c], power, baseline, times, hashes[c // 2], c % 2, hashes[n_pairs + d // 2],
                              d % 2, chans, c, settings.max_code, settings.noise_scale, settings.k_sigma, read, listed,
                              dark_normal, shot_normal, tails)
            else:
                codes[w, c, :] = 0


@kernel(inline="always")
def _pair_needed(needed, j):
    """Whether row 2j or 2j + 1 of ``needed`` (k,) is set (the rows that share stream pair j)."""
    return needed[2 * j] or (2 * j + 1 < needed.shape[0] and needed[2 * j + 1])


@kernel(inline="always")
def _hash_pairs(hashes, needed, sampling, p, first_stream, first_index):
    """Row j of ``hashes`` (m, n): the positions ``first_index`` on of stream ``first_stream + j`` of pulse ``p``, for
    the pairs j a ``needed`` (k,) row (2j or 2j + 1) asks for (as :func:`_draw_pairs` draws them)."""
    for j in range(hashes.shape[0]):
        if _pair_needed(needed, j):
            fill_hashes(stream_base(sampling.key, sampling.pulse_id[p], first_stream + j), first_index, hashes[j])


@kernel(inline="always")
def _draw_pairs(normals, needed, sampling, p, first_stream, first_index, no_low, tails):
    """Rows 2j and 2j + 1 of ``normals`` (2 m, n) from the two halves of stream ``first_stream + j`` of pulse ``p``,
    positions ``first_index`` on, for the pairs with a ``needed`` (k,) row; a half no row needs is not drawn."""
    for j in range(normals.shape[0] // 2):
        low = 2 * j + 1 < needed.shape[0] and needed[2 * j + 1]
        if _pair_needed(needed, j):
            fill_normal_pairs(stream_base(sampling.key, sampling.pulse_id[p], first_stream + j), first_index,
                              normals[2 * j], normals[2 * j + 1] if low else no_low, tails)
