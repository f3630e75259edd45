"""Ranging precision of the pass's instrument, measured from its own ranging: the table the uncertainty model reads.

At set-up the pass ranges flat Lambertian panels at normal incidence (:meth:`muls.optics.optical_model.PulseBatch.flat_target`,
the beam filling them) through its own physics (the same instrument, gate, water, echo spread, record mode and
processing as its pulses): :data:`SHOTS` shots at each of the ranges its survey gives (:data:`PANELS` spread over
its sampled echo delays, :func:`scanner_sim.survey.gate.echo_span`) and each of :data:`REFLECTANCES`, so that the echoes span
the signal-to-noise ratios and the clipping the pass meets. A panel's echo is timed as the pass times its own, by
half its path out from the laser and back to the receiver beside it (:func:`scanner_sim.rays.echoes.echo_range_m`),
and its error taken about the panel's true range: the receiver's offset lengthens a near echo's range by about
d^2 / (4 R), 2 mm at 2 m, where the ranging's spread is 5 mm. Each return the panel's echo explains is binned by the
channel the instrument chose, whether that channel clipped, whether it was the pulse's first return or a later one (a
later return inside one broad, multiply scattered echo lies far behind), the nearest panel range (the echo spread's
late shift grows with range) and its SNR. A bin holds the mean of its range errors about the truth (the ranging's
systematic part: the echo spread's late shift, a weak echo's early lean) and their standard deviation about that
mean (its random part). A bin with fewer than :data:`MIN_SHOTS` returns takes the nearest bin in SNR of its row that
has them, a row without any the nearest panel range's row, and a state (clipped, later) without any on a channel
the figures of that state pooled over channels and ranges, else of every return. A point looks the table up by
its measured range (:meth:`RangingPrecision.of`: between the two panels whose measured ranges bracket it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from muls.infra.runtime import kernel
from muls.optics.optical_model import PulseBatch
from scanner_sim.rays.echoes import echo_range_m

#: Panel reflectances ranged at each range: dark mud to a white panel, two decades of signal.
REFLECTANCES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)
#: Panels, evenly spaced from the pass's nearest sampled echo to its farthest. Evenly, not at quantiles of the
#: sampled beams: in turbid water the far echoes are mostly lost, so the points crowd where few beams end (the tops
#: of objects standing off the seabed), and the bias is interpolated between panels, which needs them close wherever
#: it bends. To the extremes, not the 2 and 98 % quantiles: the nearest echoes are where it can change fastest (an
#: echo at a gate's opening has part of its rise shut out and peaks late), and a point beyond the end panels takes
#: their figures unchanged.
PANELS = 9
#: Shots per (range, reflectance).
SHOTS = 256
#: Bins of log10(SNR) per decade, from SNR 1 to 10^6.
BINS_PER_DECADE = 4
SNR_DECADES = (0.0, 6.0)
#: Fewest returns a bin needs to stand on its own.
MIN_SHOTS = 12
#: Pulse ids of the panel shots start here, far from any pass's slot numbers (their noise draws are keyed by id).
FIRST_SHOT_ID = 1 << 40


@dataclass(frozen=True)
class RangingPrecision:
    """Range error [m] per (channel 1..k, clipped 0/1, later return 0/1, panel range, SNR bin): ``bias_m`` its mean
    and ``std_m`` its standard deviation, each (k + 1, 2, 2, ranges, bins) (channel 0 unused); ``count`` the returns
    measured in each bin; ``snr_edges`` (bins + 1,) the bins' SNR edges; ``ranges_m`` the panel ranges [m]."""

    bias_m: np.ndarray
    std_m: np.ndarray
    count: np.ndarray
    snr_edges: np.ndarray
    ranges_m: tuple[float, ...]

    def of(self, channel, snr, saturated, later, range_m) -> tuple[np.ndarray, np.ndarray]:
        """(bias, standard deviation) [m], each (n,), of the range of returns on ``channel`` (n,) 1-based at ``snr``
        (n,), clipped ``saturated`` (n,) bool, ``later`` (n,) bool not their pulse's first return, *measured* at
        ``range_m`` (n,) [m]; SNR outside the table takes the end bins.

        A point knows its measured range, not its true one, and the two differ by the very bias looked up (tens of
        centimetres in turbid water, as much as the panels' spacing). So the panels are placed by their measured
        range, panel i's true range plus its bias in the point's cell, and the figures are interpolated linearly
        between the two panels whose measured ranges bracket the point's (the end panels' beyond them): near the
        gate's opening, where part of an echo's rise is shut out, the bias grows by a few centimetres over a
        decimetre of range, more than a nearest panel's step allows."""
        n = len(range_m)
        bias, std = np.empty(n), np.empty(n)
        _look_up(*self.flat_tables(), np.asarray(channel, np.int64), np.asarray(snr, float),
                 np.asarray(saturated, np.int64), np.asarray(later, np.int64), np.asarray(range_m, float), bias, std)
        return bias, std

    def flat_tables(self) -> tuple:
        """The table as the look-up kernels take it (:func:`look_up_one`): the flattened (C-ordered) ``bias_m`` and
        ``std_m``, the channels, the SNR bins, the panel ranges [m] (panels,) and the SNR edges."""
        return (self.bias_m.reshape(-1), self.std_m.reshape(-1), self.bias_m.shape[0], self.bias_m.shape[-1],
                np.asarray(self.ranges_m, float), self.snr_edges)

    def as_dict(self) -> dict:
        """The table as JSON-ready lists (the summary's ``uncertainty.ranging``): per channel, state and panel range,
        the bias, standard deviation and count per SNR bin (bins without returns of their own show the figures they
        take)."""
        states = {"first": (0, 0), "first_clipped": (1, 0), "later": (0, 1), "later_clipped": (1, 1)}

        def rows(table, digits):
            return {f"ch{c}": {name: [[round(float(v), digits) for v in table[c, a, b, i]]
                                      for i in range(len(self.ranges_m))] for name, (a, b) in states.items()}
                    for c in range(1, table.shape[0])}

        return {"snr_edges": [round(float(e), 4) for e in self.snr_edges], "ranges_m": [round(r, 3) for r in self.ranges_m],
                "reflectances": list(REFLECTANCES), "shots_per_panel": SHOTS,
                "bias_m": rows(self.bias_m, 4), "std_m": rows(self.std_m, 4), "count": rows(self.count, 0)}


@kernel(nogil=True)
def _look_up(bias_m, std_m, channels, bins, ranges_m, edges, channel, snr, saturated, later, range_m, bias, std):
    """:meth:`RangingPrecision.of` point by point into ``bias`` and ``std`` (n,) (:func:`look_up_one` of each), from
    the flattened (C-ordered) tables ``bias_m`` and ``std_m`` of ``channels`` channels, ``ranges_m`` (panels,) and
    ``bins`` SNR bins of ``edges``."""
    measured = np.empty(ranges_m.shape[0])
    for i in range(range_m.shape[0]):
        bias[i], std[i] = look_up_one(bias_m, std_m, channels, bins, ranges_m, edges, channel[i], snr[i], saturated[i],
                                      later[i], range_m[i], measured)


@kernel(inline="always")
def look_up_one(bias_m, std_m, channels, bins, ranges_m, edges, channel, snr, saturated, later, rho, measured):
    """(bias, standard deviation) [m] of one return (:meth:`RangingPrecision.of`'s arguments, one value each: ``channel``
    and the flags as integers, ``snr`` and the measured range ``rho`` [m] as float64) from the flattened tables (as
    :func:`_look_up`); ``measured`` (panels,) scratch. The return's cell at panel 0 is an index into the flat tables
    (panel i lies i * bins on)."""
    panels = ranges_m.shape[0]
    first = ((min(max(channel, 0), channels - 1) * 2 + saturated) * 2 + later) * (panels * bins) + _snr_bin(edges, snr)
    if panels == 1:
        return bias_m[first], std_m[first]
    below = 0
    for k in range(panels):  # ascending: a farther panel's echo comes later
        measured[k] = ranges_m[k] + bias_m[first + k * bins]
        below += measured[k] <= rho
    lo = min(max(below - 1, 0), panels - 2)
    gap = measured[lo + 1] - measured[lo]
    w = (rho - measured[lo]) / (gap if gap > 0 else np.inf)
    if w == w:  # clipped to [0, 1] as numpy clips: a NaN stays NaN, -0 becomes 0
        w = w if w > 0.0 else 0.0
        w = w if w < 1.0 else 1.0
    a, b = first + lo * bins, first + (lo + 1) * bins
    return (1 - w) * bias_m[a] + w * bias_m[b], (1 - w) * std_m[a] + w * std_m[b]


@kernel(inline="always")
def _snr_bin(edges, snr):
    """:func:`snr_bin` of one ``snr``: the edges at or below it, less one, within the bins (a NaN lies above all)."""
    count = edges.shape[0]
    if snr == snr:
        count = 0
        while count < edges.shape[0] and edges[count] <= snr:
            count += 1
    return min(max(count - 1, 0), edges.shape[0] - 2)


def snr_edges() -> np.ndarray:
    """(bins + 1,) SNR edges of the table's bins: :data:`BINS_PER_DECADE` per decade over :data:`SNR_DECADES`."""
    lo, hi = SNR_DECADES
    return 10.0 ** np.linspace(lo, hi, int((hi - lo) * BINS_PER_DECADE) + 1)


def snr_bin(edges: np.ndarray, snr) -> np.ndarray:
    """(n,) int64 bin of each ``snr`` (n,) among ``edges``, the end bins taking what lies beyond."""
    return np.clip(np.searchsorted(edges, snr, side="right") - 1, 0, edges.size - 2)


def nearest_index(values, x) -> np.ndarray:
    """(n,) int64 index of the nearest of ascending ``values`` (k,) to each ``x`` (n,)."""
    values = np.asarray(values, float)
    return np.searchsorted(0.5 * (values[1:] + values[:-1]), np.asarray(x, float)).astype(np.int64)


def panel_ranges_m(delays_s: np.ndarray, speed_m_s: float) -> tuple[float, ...]:
    """The ranges [m] the panels stand at: :data:`PANELS` evenly spaced from the nearest to the farthest one-way range
    of echo delays ``delays_s`` (k,) [s] at light speed ``speed_m_s`` [m/s], each once, ascending."""
    ranges = 0.5 * speed_m_s * np.asarray(delays_s)
    return tuple(float(r) for r in np.unique(np.round(np.linspace(ranges.min(), ranges.max(), PANELS), 3)))


def measure_ranging_precision(physics, instrument, ranges_m: tuple[float, ...]) -> RangingPrecision:
    """Range the panels (module doc) with ``physics`` (:class:`scanner_sim.survey.chunk.Physics`: a muls batch ->
    records and ranging, called with ``explain_dropouts=False``: the table reads the returns only) of ``instrument``
    and tabulate the precision."""
    ranges = np.asarray(ranges_m, float)
    grid_r, grid_rho = np.meshgrid(ranges, np.asarray(REFLECTANCES), indexing="ij")
    truth = np.repeat(grid_r.ravel(), SHOTS)
    rho = np.repeat(grid_rho.ravel(), SHOTS)
    # out to the panel, back to the receiver: the kernel's formula run by numpy on the arrays (called as a kernel it
    # compiled an array signature of its own for this one call, 0.2 to 0.3 s of a first run)
    timed = echo_range_m.py_func(truth, np.hypot(truth, instrument.receiver.offset_m))
    batch = PulseBatch.flat_target(instrument, timed, rho, pulse_id=FIRST_SHOT_ID + np.arange(truth.size))
    _, ranging = physics(batch, explain_dropouts=False)
    r = ranging.returns
    echo = r.echo_index >= 0
    later = ranging.return_number > 1
    return tabulate((r.range_m - truth[r.pulse])[echo], r.channel[echo], r.snr[echo], r.saturated[echo], later[echo],
                    nearest_index(ranges, truth[r.pulse][echo]), len(instrument.channels), tuple(ranges.tolist()))


def tabulate(error_m, channel, snr, saturated, later, range_index, channels: int, ranges_m: tuple[float, ...]
             ) -> RangingPrecision:
    """The table (module doc) of returns with range errors ``error_m`` (n,) [m] on ``channel`` (n,) 1-based at
    ``snr`` (n,), clipped ``saturated`` (n,), ``later`` (n,) returns, from the panel at ``ranges_m[range_index]``
    (n,), for an instrument of ``channels`` signal channels."""
    edges = snr_edges()
    bins, n_ranges = edges.size - 1, len(ranges_m)
    shape = (channels + 1, 2, 2, n_ranges, bins)
    error = np.asarray(error_m, float)
    index = (np.asarray(channel, np.int64), np.asarray(saturated, np.int64), np.asarray(later, np.int64),
             np.asarray(range_index, np.int64), snr_bin(edges, snr))
    cell = np.ravel_multi_index(index, shape)
    size = int(np.prod(shape))
    count = np.bincount(cell, minlength=size).reshape(shape)
    total = np.bincount(cell, weights=error, minlength=size).reshape(shape)
    square = np.bincount(cell, weights=error**2, minlength=size).reshape(shape)
    bias, std = np.full(shape, np.nan), np.full(shape, np.nan)
    every = _mean_std(error)
    for clipped in (0, 1):
        for behind in (0, 1):
            mine = (index[1] == clipped) & (index[2] == behind)
            pooled = _mean_std(error[mine]) if mine.sum() >= MIN_SHOTS else every
            for c in range(channels + 1):
                filled = [i for i in range(n_ranges) if (count[c, clipped, behind, i] >= MIN_SHOTS).any()]
                for i in range(n_ranges):
                    if not filled:
                        bias[c, clipped, behind, i], std[c, clipped, behind, i] = pooled
                        continue
                    row = (c, clipped, behind, min(filled, key=lambda j: abs(j - i)))
                    good = np.nonzero(count[row] >= MIN_SHOTS)[0]
                    near = good[np.abs(np.arange(bins)[:, None] - good[None, :]).argmin(axis=1)]
                    n, mean = count[row][near], total[row][near] / count[row][near]
                    bias[c, clipped, behind, i] = mean
                    std[c, clipped, behind, i] = np.sqrt(np.maximum(square[row][near] / n - mean**2, 0.0))
    return RangingPrecision(bias, std, count, edges, ranges_m)


def _mean_std(error: np.ndarray) -> tuple[float, float]:
    return (float(error.mean()), float(error.std())) if error.size else (np.nan, np.nan)
