"""Ranging precision of the pass's instrument, measured from its own ranging: the table the uncertainty model reads.

At set-up the pass ranges flat Lambertian panels at normal incidence (:meth:`muls.waveform.PulseBatch.flat_target`,
the beam filling them) through its own physics (the same instrument, gate, water, echo spread, record mode and
processing as its pulses): :data:`SHOTS` shots at each of the ranges its survey gives (quantiles of its sampled
echo delays, :func:`scanner_sim.survey.gate.echo_span`) and each of :data:`REFLECTANCES`, so that the echoes span
the signal-to-noise ratios and the clipping the pass meets. Each return the panel's echo explains is binned by the
channel the instrument chose, whether that channel clipped, and its SNR; a bin holds the mean of its range errors
about the truth (the ranging's systematic part: the echo spread's late shift, a weak echo's early lean) and their
standard deviation about that mean (its random part). A bin with fewer than :data:`MIN_SHOTS` returns takes the
nearest bin of its row (channel and clipping) that has them; a row without any takes the pooled figures of all
returns of its clipping state, and of all returns when none clipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from muls.waveform import PulseBatch

#: Panel reflectances ranged at each range: dark mud to a white panel, two decades of signal.
REFLECTANCES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)
#: Quantiles of the pass's echo ranges at which the panels stand.
RANGE_QUANTILES = (0.02, 0.25, 0.5, 0.75, 0.98)
#: Shots per (range, reflectance).
SHOTS = 64
#: Bins of log10(SNR) per decade, from SNR 1 to 10^6.
BINS_PER_DECADE = 4
SNR_DECADES = (0.0, 6.0)
#: Fewest returns a bin needs to stand on its own.
MIN_SHOTS = 12
#: Pulse ids of the panel shots start here, far from any pass's slot numbers (their noise draws are keyed by id).
FIRST_SHOT_ID = 1 << 40


@dataclass(frozen=True)
class RangingPrecision:
    """Range error [m] per (channel 1..k, clipped 0/1, SNR bin): ``bias_m`` its mean and ``sigma_m`` its standard
    deviation, each (k + 1, 2, bins) (row 0 unused); ``snr_edges`` (bins + 1,) the bins' SNR edges, ``count``
    (k + 1, 2, bins) the returns measured in each bin, and the ranges [m] and reflectances the panels stood at."""

    bias_m: np.ndarray
    std_m: np.ndarray
    snr_edges: np.ndarray
    count: np.ndarray
    ranges_m: tuple[float, ...]
    reflectances: tuple[float, ...] = REFLECTANCES

    def of(self, channel: np.ndarray, snr: np.ndarray, saturated: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(bias, standard deviation) [m], each (n,), of the range of returns on ``channel`` (n,) 1-based at ``snr``
        (n,), clipped ``saturated`` (n,) bool; SNR outside the table takes its end bins."""
        k = np.clip(np.searchsorted(self.snr_edges, snr, side="right") - 1, 0, self.snr_edges.size - 2)
        cell = (np.clip(channel.astype(np.int64), 0, self.bias_m.shape[0] - 1), saturated.astype(np.int64), k)
        return self.bias_m[cell], self.std_m[cell]

    def as_dict(self) -> dict:
        """The table as JSON-ready lists (the summary's ``uncertainty.ranging``)."""
        return {"snr_edges": [round(float(e), 4) for e in self.snr_edges],
                **{name: {f"ch{c}": {state: [round(float(v), 5) for v in table[c, i]]
                                               for i, state in enumerate(("unclipped", "clipped"))}
                          for c in range(1, table.shape[0])} for name, table in (("bias_m", self.bias_m),
                                                                                  ("std_m", self.std_m))},
                "count": {f"ch{c}": {"unclipped": self.count[c, 0].tolist(), "clipped": self.count[c, 1].tolist()}
                          for c in range(1, self.count.shape[0])},
                "ranges_m": [round(r, 3) for r in self.ranges_m], "reflectances": list(self.reflectances),
                "shots_per_panel": SHOTS}


def panel_ranges_m(delays_s: np.ndarray, speed_m_s: float) -> tuple[float, ...]:
    """The ranges [m] the panels stand at: :data:`RANGE_QUANTILES` of the one-way ranges of echo delays
    ``delays_s`` (k,) [s] at light speed ``speed_m_s`` [m/s]."""
    return tuple(float(r) for r in np.quantile(0.5 * speed_m_s * np.asarray(delays_s), RANGE_QUANTILES))


def measure_ranging_precision(physics, instrument, ranges_m: tuple[float, ...]) -> RangingPrecision:
    """Range the panels (module doc) with ``physics`` (:class:`scanner_sim.survey.setup.Physics`: a muls batch ->
    records and ranging) of ``instrument`` and tabulate the precision."""
    ranges = np.asarray(ranges_m, float)
    grid_r, grid_rho = np.meshgrid(ranges, np.asarray(REFLECTANCES), indexing="ij")
    truth = np.repeat(grid_r.ravel(), SHOTS)
    rho = np.repeat(grid_rho.ravel(), SHOTS)
    batch = PulseBatch.flat_target(instrument, truth, rho, pulse_id=FIRST_SHOT_ID + np.arange(truth.size))
    _, ranging = physics(batch)
    r = ranging.returns
    echo = r.echo_index >= 0
    error = (r.range_m - truth[r.pulse])[echo]
    return tabulate(error, r.channel[echo], r.snr[echo], r.saturated[echo], len(instrument.channels),
                    tuple(ranges.tolist()))


def tabulate(error_m, channel, snr, saturated, channels: int, ranges_m: tuple[float, ...]) -> RangingPrecision:
    """The table (module doc) of returns with range errors ``error_m`` (n,) [m] on ``channel`` (n,) 1-based at
    ``snr`` (n,), clipped ``saturated`` (n,), for an instrument of ``channels`` signal channels."""
    lo, hi = SNR_DECADES
    edges = 10.0 ** np.linspace(lo, hi, int((hi - lo) * BINS_PER_DECADE) + 1)
    bins = edges.size - 1
    k = np.clip(np.searchsorted(edges, snr, side="right") - 1, 0, bins - 1)
    cell = (channel.astype(np.int64) * 2 + saturated.astype(np.int64)) * bins + k
    size = (channels + 1) * 2 * bins
    error = np.asarray(error_m, float)
    count = np.bincount(cell, minlength=size).reshape(channels + 1, 2, bins)
    total = np.bincount(cell, weights=error, minlength=size).reshape(count.shape)
    square = np.bincount(cell, weights=error**2, minlength=size).reshape(count.shape)
    bias, std = np.full(count.shape, np.nan), np.full(count.shape, np.nan)
    clipped = saturated.astype(bool)
    for state in (0, 1):
        pooled = error[clipped == bool(state)]
        if pooled.size < MIN_SHOTS:
            pooled = error
        for c in range(channels + 1):
            good = np.nonzero(count[c, state] >= MIN_SHOTS)[0]
            if good.size == 0:
                bias[c, state], std[c, state] = pooled.mean(), pooled.std()
                continue
            nearest = good[np.abs(np.arange(bins)[:, None] - good[None, :]).argmin(axis=1)]
            n, mean = count[c, state, nearest], total[c, state, nearest] / count[c, state, nearest]
            bias[c, state] = mean
            std[c, state] = np.sqrt(np.maximum(square[c, state, nearest] / n - mean**2, 0.0))
    return RangingPrecision(bias, std, edges, count, ranges_m)
