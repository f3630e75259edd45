"""The optical waveform of a batch of pulses: water column (Eq. 4), target echoes (Eq. 7), window (Eq. 3)
and background (Eq. 8), summed as in MULS Eq. 1.

With multiple scattering (``multiple_scattering="table"``, the default under the ``monte_carlo`` attenuation
rule) the Monte Carlo reference's tables for the water and the receiver (:mod:`muls.montecarlo.scattering_tables`) replace the two
single-scattering parts: the column is the Monte Carlo's impulse response, rescaled to the water's beta_pi, and
each echo is spread in time as the Monte Carlo spreads it, as one echo on the straight path plus equal-energy
echoes at the quantile delays of its scattered part (one echo at the mean delay where they all lie within
:data:`~muls.optics.echo_spread.SPREAD_MERGE_S`).

The water column of a pulse is the pulse convolved with the Eq. 4 profile, cut where the beam meets a
surface. With the exponential pulse basis of :mod:`muls.instrument.pulse` the cut is exact and cheap: writing
tau = 2 z / c_w and h(tau) the column density per unit two-way time, the column power at time t of a beam
cut at tau_c is, with tau_e = min(t, tau_c) and u = t - tau_e,

    P_C(t) = E_t [ (A (u S0a + S1a) + B0 S0a) exp(-a u) + C S0b exp(-b u) ]

where S0a(tau) = int_0^tau h(s) exp(-a (tau - s)) ds, S1a(tau) = int_0^tau h(s) (tau - s) exp(-a (tau - s)) ds
and S0b likewise with b. The three running integrals are tabulated once per water and instrument.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

from ..infra.errors import ParameterError
from ..infra.filters import first_order_filter
from ..infra.runtime import kernel
from ..instrument.channels import ChannelArrays
from ..instrument.description import Instrument
from ..instrument.shape_tables import ClipTable, FitTable
from ..montecarlo.scattering_tables import ScatteringTables
from ..montecarlo.tables import find_or_build_tables
from ..water.properties import MULTIPLE_SCATTERING, Water
from .echo_spread import spread_echoes, spread_rows
from .radiometry import column_density_per_m, lambertian_weight, target_factor, two_way_transmission, window_factor
from .sample_kernels import _column_many

#: Step of the column tables in two-way time [s]: 1/160 of the 4 ns pulse decay time.
COLUMN_TABLE_STEP_S = 25e-12


@dataclass(frozen=True)
class ColumnTables:
    """Running integrals of the column profile on a grid of two-way time ``step_s * i`` [s]; include E_t [J]."""

    step_s: float
    s0a: np.ndarray
    s1a: np.ndarray
    s0b: np.ndarray

    @classmethod
    def build(cls, instrument: Instrument, water: Water, step_s: float = COLUMN_TABLE_STEP_S,
              scattering: ScatteringTables | None = None, tables: ScatteringTables | None = None) -> ColumnTables:
        """``scattering``: the Monte Carlo's tables whose column replaces Eq. 4's (None: Eq. 4); ``tables``: the
        tables of the water's attenuation rule if the caller holds them
        (:func:`muls.optics.radiometry.lidar_attenuation_per_m`)."""
        a, b, _, _, _ = instrument.pulse.basis()
        dig = instrument.digitizer
        n = int(math.ceil((dig.record_length_s + 4.0 * instrument.pulse.duration_s) / step_s)) + 2
        tau = np.arange(n) * step_s
        e_t = instrument.transmitter.pulse_energy_j
        if scattering is not None:
            # The Monte Carlo's column [1/s] with its phase function's b p(pi), rescaled to the water's beta_pi.
            rescale = (water.beta_pi_per_m_sr / (water.scattering_per_m * scattering.phase_value_at_pi_per_sr)
                       if water.scattering_per_m > 0.0 and scattering.phase_value_at_pi_per_sr > 0.0 else 0.0)
            h = e_t * two_way_transmission(instrument) * rescale * scattering.column_response(tau)
        else:
            # h(tau) = (c_w / 2) * Eq. 4 density at z = c_w tau / 2, times E_t.
            z = 0.5 * water.speed_m_s * tau
            h = e_t * 0.5 * water.speed_m_s * column_density_per_m(instrument, water, z, tables)
        hs = h * step_s  # times the trapezoid step
        tables = []
        for rate in (a, b):
            r = math.exp(-rate * step_s)
            s0 = first_order_filter(hs, r)
            s1 = first_order_filter(s0, r, 0.0, r * step_s)
            # Trapezoid rule: half weight on both ends of the integral.
            decay = r ** np.arange(n)
            s0 = s0 - 0.5 * hs - 0.5 * hs[0] * decay
            s1 = s1 - 0.5 * hs[0] * tau * decay
            tables.append((s0, s1))
        return cls(step_s, tables[0][0], tables[0][1], tables[1][0])


@dataclass(frozen=True)
class PulseBatch:
    """What each pulse of a batch meets (struct of arrays).

    pulse_id: (n,) int64 global pulse numbers; they key the noise, so a pulse has the same noise whatever
        batch it is simulated in.
    return_pulse: (m,) int64 index into the batch of each echo contribution, sorted ascending.
    return_range_m: (m,) one-way range of each contribution [m].
    return_weight_per_sr: (m,) sum of w_j (rho_j / pi) cos(theta_j) x receiver weight [1/sr].
    column_cut_m: (n, c) ranges where the beam's parts stop [m] (inf: never); column_cut_weight (n, c) their
        energy shares (rows sum to 1).
    background_w: (n,) background light power [W] (Eqs. 8-10).
    """

    pulse_id: np.ndarray
    return_pulse: np.ndarray
    return_range_m: np.ndarray
    return_weight_per_sr: np.ndarray
    column_cut_m: np.ndarray
    column_cut_weight: np.ndarray
    background_w: np.ndarray

    def __post_init__(self):
        n = self.pulse_id.shape[0]
        m = self.return_pulse.shape[0]
        if self.return_range_m.shape != (m,) or self.return_weight_per_sr.shape != (m,):
            raise ParameterError("return_range_m and return_weight_per_sr must have the shape of return_pulse")
        cuts = self.column_cut_m
        if cuts.ndim != 2 or cuts.shape[0] != n or self.column_cut_weight.shape != cuts.shape:
            raise ParameterError("column_cut_m and column_cut_weight must be (n_pulses, n_cuts)")
        if self.background_w.shape != (n,):
            raise ParameterError("background_w must be (n_pulses,)")
        if m and (np.any(np.diff(self.return_pulse) < 0) or self.return_pulse[0] < 0 or self.return_pulse[-1] >= n):
            raise ParameterError("return_pulse must be sorted and index the batch")
        if np.any(~np.isfinite(self.return_range_m)) or np.any(self.return_range_m <= 0.0):
            raise ParameterError("return_range_m must be finite and > 0")
        if np.any(self.return_weight_per_sr < 0.0):
            raise ParameterError("return_weight_per_sr must be >= 0")

    @property
    def n_pulses(self) -> int:
        return int(self.pulse_id.shape[0])

    @classmethod
    def flat_target(cls, instrument: Instrument, range_m, reflectance=0.1, incidence_rad=0.0,
                    pulse_id=None, background_w=None) -> PulseBatch:
        """One flat Lambertian target per pulse at ``range_m`` (n,) [m], the beam filling it (Eq. 7, 11).

        ``reflectance`` must lie in [0, 1]; a range of inf means the pulse meets nothing.
        """
        r = np.atleast_1d(np.asarray(range_m, dtype=float))
        rho = np.broadcast_to(np.asarray(reflectance, float), r.shape)
        if np.any(~np.isfinite(rho)) or np.any((rho < 0.0) | (rho > 1.0)):
            raise ParameterError(f"reflectance = {np.asarray(reflectance)!r}: must lie in [0, 1]")
        if np.any(np.isnan(r)) or np.any(r <= 0.0):
            raise ParameterError("range_m must be > 0 (inf for a pulse that meets nothing)")
        n = r.shape[0]
        hit = np.isfinite(r)
        idx = np.nonzero(hit)[0]
        weight = lambertian_weight(instrument, r[hit], rho[hit], np.broadcast_to(incidence_rad, r.shape)[hit])
        return cls(
            pulse_id=np.arange(n, dtype=np.int64) if pulse_id is None else np.asarray(pulse_id, np.int64),
            return_pulse=idx.astype(np.int64),
            return_range_m=r[hit],
            return_weight_per_sr=weight,
            column_cut_m=r[:, None].copy(),
            column_cut_weight=np.ones((n, 1)),
            background_w=np.zeros(n) if background_w is None else np.asarray(background_w, float),
        )


class ColumnKernel(NamedTuple):
    """What the kernels need to evaluate the column: the pulse basis (5,) (see :meth:`PulseShape.basis`) and
    the running integrals of :class:`ColumnTables` on their grid of ``step_s`` [s], packed (n, 3) as S0a, S1a,
    S0b per row, so that one lookup reads one cache line, not three (measured: peak finding 18 % faster); and
    ``uncut`` (n,) [W], the uncut column's power on the same grid (the integrals' combination at u = 0, which is
    linear in them, so interpolating it gives what combining interpolated integrals gives)."""

    basis: np.ndarray
    integrals: np.ndarray
    step_s: float
    uncut: np.ndarray


class Echoes(NamedTuple):
    """The echoes of a batch in CSR form, sorted by delay within each pulse.

    offsets (n_pulses + 1,) int64: echoes of pulse p are ``offsets[p]:offsets[p + 1]``; delay_s (m,) [s]:
    start of each echo's pulse after emission; energy_j (m,) [J] received; source (m,) int64: index of the
    :class:`PulseBatch` return that made it, -1 for the window return (Eq. 3).
    """

    offsets: np.ndarray
    delay_s: np.ndarray
    energy_j: np.ndarray
    source: np.ndarray


class ColumnCuts(NamedTuple):
    """Per pulse: where the column is cut, in two-way time, and the background (from a :class:`PulseBatch`).

    cut_tau_s (n, c) [s]; cut_weight (n, c) energy shares; background_w (n,) [W].
    """

    cut_tau_s: np.ndarray
    cut_weight: np.ndarray
    background_w: np.ndarray


@dataclass(frozen=True)
class OpticalModel:
    """One instrument in one water, with every table the kernels need, each built once and reused.

    attenuation: the Monte Carlo's tables of the ``monte_carlo`` attenuation rule (None under another rule);
    scattering: the same tables when the model applies multiple scattering, None for single scattering;
    multiple_scattering: what was asked for (:data:`MULTIPLE_SCATTERING`)."""

    instrument: Instrument
    water: Water
    tables: ColumnTables
    attenuation: ScatteringTables | None = None
    scattering: ScatteringTables | None = None
    multiple_scattering: str = "none"

    @classmethod
    def build(cls, instrument: Instrument, water: Water, multiple_scattering: str = "table",
              tables: ScatteringTables | None = None) -> OpticalModel:
        """``multiple_scattering``: one of :data:`MULTIPLE_SCATTERING`; ``table`` applies only under the
        ``monte_carlo`` attenuation rule (the other rules are single-scattering lidar equations); ``tables``: the
        Monte Carlo's tables of that rule if the caller holds them (e.g. a quicker run's), else found or built."""
        if multiple_scattering not in MULTIPLE_SCATTERING:
            raise ParameterError(f"multiple_scattering = {multiple_scattering!r}: must be one of "
                                 f"{', '.join(map(repr, MULTIPLE_SCATTERING))}")
        if water.attenuation_model != "monte_carlo":
            tables = None
        elif tables is None:
            tables = find_or_build_tables(instrument.geometry, water)
        scattering = tables if multiple_scattering == "table" else None
        return cls(instrument, water, ColumnTables.build(instrument, water, scattering=scattering, tables=tables),
                   tables, scattering, multiple_scattering)

    @cached_property
    def basis(self) -> np.ndarray:
        return np.array(self.instrument.pulse.basis())

    @cached_property
    def column(self) -> ColumnKernel:
        tb, b = self.tables, self.basis
        return ColumnKernel(b, np.ascontiguousarray(np.stack([tb.s0a, tb.s1a, tb.s0b], axis=1)), tb.step_s,
                            b[2] * tb.s1a + b[3] * tb.s0a + b[4] * tb.s0b)

    @cached_property
    def channels(self) -> ChannelArrays:
        """Per-channel constants, index 0 the CH0 reference."""
        return ChannelArrays.of(self.instrument)

    @cached_property
    def fit_table(self) -> FitTable:
        return FitTable.build(self.instrument.pulse, self.instrument.digitizer.sample_interval_s)

    @cached_property
    def clip_table(self) -> ClipTable:
        return ClipTable.build(self.instrument.pulse, self.instrument.digitizer.sample_interval_s)

    def cuts(self, batch: PulseBatch) -> ColumnCuts:
        return ColumnCuts(2.0 * batch.column_cut_m / self.water.speed_m_s, batch.column_cut_weight,
                          batch.background_w)

    def echoes(self, batch: PulseBatch) -> Echoes:
        """The echoes of ``batch``: per return (Eq. 7) one, or with multiple scattering its spread in time
        (:meth:`spread`), plus the window return (Eq. 3) when coupled."""
        e_t = self.instrument.transmitter.pulse_energy_j
        c_w = self.water.speed_m_s
        delay = 2.0 * batch.return_range_m / c_w
        energy = e_t * target_factor(self.instrument, self.water, batch.return_range_m, batch.return_weight_per_sr,
                                     self.attenuation)
        pulse = batch.return_pulse
        source = np.arange(pulse.shape[0], dtype=np.int64)
        if self.scattering is not None:
            pulse, delay, energy, source = self.spread(pulse, delay, energy, source, batch.return_range_m)
        window = window_factor(self.instrument)
        if window > 0.0:
            n = batch.n_pulses
            d = self.instrument.receiver.window_distance_m
            pulse = np.concatenate([np.arange(n), pulse])
            delay = np.concatenate([np.full(n, 2.0 * d / c_w), delay])
            energy = np.concatenate([np.full(n, e_t * window), energy])
            source = np.concatenate([np.full(n, -1, np.int64), source])
            order = np.argsort(pulse, kind="stable")
            pulse, delay, energy, source = pulse[order], delay[order], energy[order], source[order]
        offsets = np.searchsorted(pulse, np.arange(batch.n_pulses + 1)).astype(np.int64)
        delay, energy, source = delay.copy(), energy.copy(), source.copy()
        _sort_by_delay_within(offsets, delay, energy, source)  # the digitiser adds echoes as they start
        return Echoes(offsets, delay, energy, source)

    @cached_property
    def _spread_rows(self) -> tuple:
        """The seen table rows and their moments (:func:`muls.optics.echo_spread.spread_rows`), once per model."""
        return spread_rows(self.scattering)

    def spread(self, pulse, delay, energy, source, range_m):
        """Echoes (m,) spread in time by multiple scattering (:mod:`muls.montecarlo.scattering_tables`): each becomes
        its share on the straight path at ``delay`` and equal shares of the rest at quantile delays after it: one echo at their
        energy-weighted mean delay where their spread is under :data:`~muls.optics.echo_spread.SPREAD_MERGE_S`, the means
        of :data:`~muls.montecarlo.scattering_tables.SPREAD_NODES` / 2 pairs of neighbouring nodes where it is under
        :data:`~muls.optics.echo_spread.SPREAD_FINE_S`, every node beyond (:func:`muls.optics.echo_spread.spread_echoes`).
        Returns (pulse, delay, energy, source) of the echoes, pulse ascending."""
        index, out_delay, out_energy = spread_echoes(self._spread_rows, delay, energy, range_m)
        return pulse[index], out_delay, out_energy, source[index]

    def column_power_w(self, t_s, cut_m=np.inf):
        """Noise-free column power [W] at times ``t_s`` for a beam cut at ``cut_m`` (numpy, for studies)."""
        t = np.atleast_1d(np.asarray(t_s, float))
        cut_tau = 2.0 * np.asarray(cut_m, float) / self.water.speed_m_s
        return _column_many(t, np.broadcast_to(cut_tau, t.shape).astype(float), self.column)


#: Pulses with more echoes than this are first bucketed by delay (a counting sort), then finished by insertion.
INSERTION_SORT_MAX = 12


@kernel(nogil=True)
def _sort_by_delay_within(offsets, delay, energy, source):
    """Sort each pulse's echoes by delay in place, stably, as an insertion sort alone would.

    An insertion sort costs as the square of a footprint's 91 sub-rays in the worst case. A pulse with more than
    :data:`INSERTION_SORT_MAX` echoes is first put in order of delay bucket (as many buckets as echoes over the
    delays' span, a stable counting sort; the bucket grows with the delay, so only echoes sharing a bucket stay out
    of order), and the insertion sort then has little left to move."""
    most = 0
    for p in range(offsets.shape[0] - 1):
        most = max(most, offsets[p + 1] - offsets[p])
    bucket, starts = np.empty(most, np.int64), np.empty(most + 1, np.int64)
    moved_d, moved_e, moved_s = np.empty(most), np.empty(most), np.empty(most, np.int64)
    for p in range(offsets.shape[0] - 1):
        lo, hi = offsets[p], offsets[p + 1]
        n = hi - lo
        if n > INSERTION_SORT_MAX:
            first, last, finite = delay[lo], delay[lo], True
            for i in range(lo, hi):
                first, last = min(first, delay[i]), max(last, delay[i])
                finite &= math.isfinite(delay[i])
            if finite and last > first:  # else the insertion sort alone
                per_s = (n - 1) / (last - first)
                starts[: n + 1] = 0
                for i in range(n):
                    bucket[i] = min(n - 1, int((delay[lo + i] - first) * per_s))
                    starts[bucket[i] + 1] += 1
                for b in range(n):
                    starts[b + 1] += starts[b]
                for i in range(n):
                    at = starts[bucket[i]]
                    starts[bucket[i]] += 1
                    moved_d[at], moved_e[at], moved_s[at] = delay[lo + i], energy[lo + i], source[lo + i]
                for i in range(n):
                    delay[lo + i], energy[lo + i], source[lo + i] = moved_d[i], moved_e[i], moved_s[i]
        for i in range(lo + 1, hi):
            d, e, s = delay[i], energy[i], source[i]
            j = i - 1
            while j >= lo and delay[j] > d:
                delay[j + 1], energy[j + 1], source[j + 1] = delay[j], energy[j], source[j]
                j -= 1
            delay[j + 1], energy[j + 1], source[j + 1] = d, e, s
