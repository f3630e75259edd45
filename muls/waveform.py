"""The optical waveform of a batch of pulses: water column (Eq. 4), target echoes (Eq. 7), window (Eq. 3)
and background (Eq. 8), summed as in MULS Eq. 1.

The water column of a pulse is the pulse convolved with the Eq. 4 profile, cut where the beam meets a
surface. With the exponential pulse basis of :mod:`muls.pulse` the cut is exact and cheap: writing
tau = 2 z / c_w and h(tau) the column density per unit two-way time, the column power at time t of a beam
cut at tau_c is, with tau_e = min(t, tau_c) and u = t - tau_e,

    P_C(t) = E_t [ (A (u S0a + S1a) + B0 S0a) exp(-a u) + C S0b exp(-b u) ]

where S0a(tau) = int_0^tau h(s) exp(-a (tau - s)) ds, S1a(tau) = int_0^tau h(s) (tau - s) exp(-a (tau - s)) ds
and S0b likewise with b. The three running integrals are tabulated once per water and instrument.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numba
import numpy as np
from scipy.signal import lfilter

from .errors import ParameterError
from .instrument import SINGLE_CHANNEL_MAX_GAIN, Channel, Instrument, mul2023
from .radiometry import column_density_per_m, lambertian_weight, target_factor, window_factor
from .water import Water

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
    def build(cls, instrument: Instrument, water: Water, step_s: float = COLUMN_TABLE_STEP_S) -> "ColumnTables":
        a, b, _, _, _ = instrument.pulse.basis()
        dig = instrument.digitizer
        n = int(math.ceil((dig.record_length_s + 4.0 * instrument.pulse.duration_s) / step_s)) + 2
        tau = np.arange(n) * step_s
        z = 0.5 * water.speed_m_s * tau
        # h(tau) = (c_w / 2) * Eq. 4 density at z = c_w tau / 2, times E_t, times the trapezoid step.
        h = instrument.transmitter.pulse_energy_j * 0.5 * water.speed_m_s * column_density_per_m(instrument, water, z)
        hs = h * step_s
        tables = []
        for rate in (a, b):
            r = math.exp(-rate * step_s)
            s0 = lfilter([1.0], [1.0, -r], hs)
            s1 = lfilter([0.0, r * step_s], [1.0, -r], s0)
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
        if self.column_cut_m.ndim != 2 or self.column_cut_m.shape[0] != n or self.column_cut_weight.shape != self.column_cut_m.shape:
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
                    pulse_id=None, background_w=None) -> "PulseBatch":
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


@dataclass(frozen=True)
class OpticalModel:
    """Everything the compiled kernels need about one instrument in one water (built once, reused)."""

    instrument: Instrument
    water: Water
    tables: ColumnTables

    @classmethod
    def build(cls, instrument: Instrument, water: Water) -> "OpticalModel":
        return cls(instrument, water, ColumnTables.build(instrument, water))

    @property
    def basis(self) -> np.ndarray:
        return np.array(self.instrument.pulse.basis())

    def echoes(self, batch: PulseBatch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CSR echoes per pulse, by delay within a pulse: (offsets (n+1,), delay_s (m',), energy_j (m',)).

        The window return (Eq. 3), when coupled, is one more echo per pulse.
        """
        e_t = self.instrument.transmitter.pulse_energy_j
        c_w = self.water.speed_m_s
        delay = 2.0 * batch.return_range_m / c_w
        energy = e_t * target_factor(self.instrument, self.water, batch.return_range_m, batch.return_weight_per_sr)
        pulse = batch.return_pulse
        window = window_factor(self.instrument)
        if window > 0.0:
            n = batch.n_pulses
            d = self.instrument.receiver.window_distance_m
            pulse = np.concatenate([np.arange(n), pulse])
            delay = np.concatenate([np.full(n, 2.0 * d / c_w), delay])
            energy = np.concatenate([np.full(n, e_t * window), energy])
        if window > 0.0:
            order = np.argsort(pulse, kind="stable")
            pulse, delay, energy = pulse[order], delay[order], energy[order]
        offsets = np.searchsorted(pulse, np.arange(batch.n_pulses + 1)).astype(np.int64)
        delay, energy = delay.copy(), energy.copy()
        _sort_by_delay_within(offsets, delay, energy)  # the digitiser adds echoes as they start
        return offsets, delay, energy

    def column_power_w(self, t_s, cut_m=np.inf):
        """Noise-free column power [W] at times ``t_s`` for a beam cut at ``cut_m`` (numpy, for studies)."""
        t = np.atleast_1d(np.asarray(t_s, float))
        cut_tau = 2.0 * np.asarray(cut_m, float) / self.water.speed_m_s
        tb = self.tables
        return _column_many(t, np.broadcast_to(cut_tau, t.shape).astype(float), self.basis,
                            tb.s0a, tb.s1a, tb.s0b, tb.step_s)


@numba.njit(cache=True)
def _sort_by_delay_within(offsets, delay, energy):
    """Sort each pulse's echoes by delay in place (insertion sort: a pulse has a few tens at most)."""
    for p in range(offsets.shape[0] - 1):
        for i in range(offsets[p] + 1, offsets[p + 1]):
            d, e = delay[i], energy[i]
            j = i - 1
            while j >= offsets[p] and delay[j] > d:
                delay[j + 1], energy[j + 1] = delay[j], energy[j]
                j -= 1
            delay[j + 1], energy[j + 1] = d, e


@numba.njit(cache=True, inline="always")
def pulse_value(u, basis):
    """Filtered unit-area pulse at u seconds after its start [1/s] (MULS Eq. 2 through the bandwidth)."""
    if u < 0.0:
        return 0.0
    return (basis[2] * u + basis[3]) * math.exp(-basis[0] * u) + basis[4] * math.exp(-basis[1] * u)


@numba.njit(cache=True, inline="always")
def column_value(t, cut_tau, basis, s0a, s1a, s0b, step):
    """Column power [W] at time t [s] of a beam cut at two-way time cut_tau [s] (exact cut, see module doc)."""
    if t <= 0.0:
        return 0.0
    tau = t if t < cut_tau else cut_tau
    x = tau / step
    i = int(x)
    if i >= s0a.shape[0] - 1:
        return 0.0
    f = x - i
    v0a = s0a[i] + f * (s0a[i + 1] - s0a[i])
    v1a = s1a[i] + f * (s1a[i + 1] - s1a[i])
    v0b = s0b[i] + f * (s0b[i + 1] - s0b[i])
    if t < cut_tau:  # before the cut's echo: the full column, u = 0
        return basis[2] * v1a + basis[3] * v0a + basis[4] * v0b
    u = t - tau
    ea = math.exp(-basis[0] * u)
    return (basis[2] * (u * v0a + v1a) + basis[3] * v0a) * ea + basis[4] * v0b * math.exp(-basis[1] * u)


@numba.njit(cache=True)
def _column_many(t, cut_tau, basis, s0a, s1a, s0b, step):
    out = np.empty(t.shape[0])
    for i in range(t.shape[0]):
        out[i] = column_value(t[i], cut_tau[i], basis, s0a, s1a, s0b, step)
    return out


@numba.njit(cache=True, inline="always")
def optical_power(t, p, basis, s0a, s1a, s0b, step, cut_tau, cut_w, offsets, delay, energy, background, extent):
    """Total received power [W] of batch pulse p at time t [s] (MULS Eq. 1)."""
    power = background[p]
    for c in range(cut_tau.shape[1]):
        if cut_w[p, c] != 0.0:
            power += cut_w[p, c] * column_value(t, cut_tau[p, c], basis, s0a, s1a, s0b, step)
    for j in range(offsets[p], offsets[p + 1]):
        u = t - delay[j]
        if 0.0 <= u < extent:
            power += energy[j] * pulse_value(u, basis)
    return power


def single_channel(water: Water, base: Instrument | None = None) -> Instrument:
    """One non-gated detector receiving all the light, its gain set for ``water`` as a user would.

    The gain is the highest (up to ``SINGLE_CHANNEL_MAX_GAIN``) at which the noise-free water-column
    backscatter plus the dark level and five standard deviations of noise stays below the top code.
    """
    base = base or mul2023()
    template = Channel("ch1", "single", split_ratio=1.0, voltage_ratio=1.0, gain=1.0)
    unit = replace(base, name="single_channel", channels=(template,))
    model = OpticalModel.build(unit, water)
    t = np.arange(0.0, unit.digitizer.record_length_s, 0.25e-9)
    peak_w = float(np.max(model.column_power_w(t)))
    dig = unit.digitizer
    e = 1.602176634e-19

    def headroom(gain: float) -> float:
        ch = replace(template, gain=gain)
        level = ch.volts_per_watt * peak_w * dig.lsb_per_volt
        shot_var = shot_noise_lsb2_per_w(ch, dig.bandwidth_hz, dig.lsb_per_volt, e) * peak_w
        return dig.max_code - (ch.dark_mean_lsb + level + 5.0 * math.sqrt(ch.dark_std_lsb**2 + shot_var))

    if headroom(SINGLE_CHANNEL_MAX_GAIN) >= 0.0:
        gain = SINGLE_CHANNEL_MAX_GAIN
    else:
        lo, hi = 0.0, math.log(SINGLE_CHANNEL_MAX_GAIN)
        if headroom(1.0) < 0.0:
            raise ParameterError(f"water '{water.name}': the column backscatter clips the digitiser even at gain 1")
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if headroom(math.exp(mid)) >= 0.0 else (lo, mid)
        gain = math.exp(lo)
    return replace(unit, channels=(replace(template, gain=gain),))


def shot_noise_lsb2_per_w(channel: Channel, bandwidth_hz: float, lsb_per_volt: float,
                          electron_charge_c: float = 1.602176634e-19) -> float:
    """Shot-noise variance per watt of received power [LSB^2/W]: 2 e B F M^2 S_k (xi_i P) (xi_v R_L)^2."""
    ch = channel
    return (2.0 * electron_charge_c * bandwidth_hz * ch.excess_noise * ch.gain**2 * ch.sensitivity_a_per_w
            * ch.split_ratio * (ch.voltage_ratio * ch.load_ohm) ** 2 * lsb_per_volt**2)
