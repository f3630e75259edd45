"""Per-channel constants of the compiled kernels: gain in LSB per watt (Eqs. 12, 13), gates, dark and shot
noise. Built once per :class:`muls.optics.optical_model.OpticalModel` and passed to the kernels as one named tuple."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..infra.runtime import kernel
from .description import Channel, Instrument

ELECTRON_CHARGE_C = 1.602176634e-19

#: Equivalent noise bandwidth of the analog chain over its 3 dB bandwidth B: the chain is a first-order
#: low-pass (docs/assumptions.md), whose |H(f)|^2 = 1 / (1 + (f/B)^2) integrates to pi/2 B.
NOISE_BANDWIDTH_FACTOR = math.pi / 2.0


def noise_bandwidth_hz(bandwidth_hz: float) -> float:
    """Equivalent noise bandwidth [Hz] of the first-order analog chain of 3 dB bandwidth ``bandwidth_hz``."""
    return NOISE_BANDWIDTH_FACTOR * bandwidth_hz


def shot_noise_lsb2_per_w(channel: Channel, bandwidth_hz: float, lsb_per_volt: float) -> float:
    """Shot-noise variance per watt of received power [LSB^2/W]: 2 e B_n F M^2 S_k (xi_i P) (xi_v R_L)^2.

    ``bandwidth_hz`` is the chain's 3 dB bandwidth B; the noise bandwidth B_n = pi/2 B of its first-order
    low-pass sets the variance (the shot-noise current 2 e I B_n, Ehret et al. 2008, as the paper uses it).
    """
    ch = channel
    return (2.0 * ELECTRON_CHARGE_C * noise_bandwidth_hz(bandwidth_hz) * ch.excess_noise * ch.gain**2
            * ch.sensitivity_a_per_w * ch.split_ratio * (ch.voltage_ratio * ch.load_ohm) ** 2 * lsb_per_volt**2)


def detector_index(instrument: Instrument) -> np.ndarray:
    """(n_channels,) int64: the index of each signal channel's detector, in order of first appearance.

    Channels of one detector (CH1 and CH2 are the 9:1 outputs of PMT1) carry one shot-noise current, so
    their shot noise is one draw scaled by each channel's own shot sigma.
    """
    names: list[str] = []
    for ch in instrument.channels:
        if ch.detector not in names:
            names.append(ch.detector)
    return np.array([names.index(ch.detector) for ch in instrument.channels], np.int64)


class ChannelArrays(NamedTuple):
    """(n_channels + 1,) float64 each (``detector`` int64); index 0 is the CH0 reference, 1.. the signal channels in order.

    lsb_per_w [LSB/W]; gate_open_s / gate_close_s [s after emission] (-inf / inf when ungated);
    dark_mean_lsb, dark_std_lsb [LSB]; shot_lsb2_per_w [LSB^2/W] (0 for CH0); detector: index of the
    channel's detector (channels that share one share its shot-noise draw), -1 for CH0.
    """

    lsb_per_w: np.ndarray
    gate_open_s: np.ndarray
    gate_close_s: np.ndarray
    dark_mean_lsb: np.ndarray
    dark_std_lsb: np.ndarray
    shot_lsb2_per_w: np.ndarray
    detector: np.ndarray

    @classmethod
    def of(cls, instrument: Instrument) -> ChannelArrays:
        dig = instrument.digitizer
        chans = instrument.channels
        lsb = np.array([0.0] + [ch.volts_per_watt * dig.lsb_per_volt for ch in chans])  # MULS Eqs. 12, 13
        gate_open = np.array([-np.inf] + [ch.gate_delay_s if ch.gated else -np.inf for ch in chans])
        gate_close = np.array([np.inf] + [ch.gate_delay_s + ch.gate_width_s if ch.gated else np.inf for ch in chans])
        mean = np.array([instrument.reference.dark_mean_lsb] + [ch.dark_mean_lsb for ch in chans])
        std = np.array([instrument.reference.dark_std_lsb] + [ch.dark_std_lsb for ch in chans])
        shot = np.array([0.0] + [shot_noise_lsb2_per_w(ch, dig.bandwidth_hz, dig.lsb_per_volt) for ch in chans])
        detector = np.concatenate([[-1], detector_index(instrument)]).astype(np.int64)
        return cls(lsb, gate_open, gate_close, mean, std, shot, detector)

    def signal(self) -> ChannelArrays:
        """The signal channels only (CH0 dropped): what the digitiser and peak kernels index by channel."""
        return ChannelArrays(*(a[1:] for a in self))


@kernel(inline="always")
def processor_sigma_lsb(chans, c, baseline_w):
    """The noise [LSB] the peak search assumes on signal channel ``c`` of ``chans`` (:meth:`ChannelArrays.signal`)
    over a calibrated baseline of ``baseline_w`` [W]: dark noise, the baseline's shot noise and rounding."""
    return math.sqrt(chans.dark_std_lsb[c] ** 2 + chans.shot_lsb2_per_w[c] * baseline_w + 1.0 / 12.0)


@kernel(inline="always")
def gate_open_at(chans, c, t):
    """Signal channel ``c``'s gate is open at time ``t`` [s] (bitwise, so that a loop of these has no branch)."""
    return (chans.gate_open_s[c] <= t) & (t < chans.gate_close_s[c])


@kernel(inline="always")
def level_lsb(chans, c, power_w):
    """Signal channel ``c``'s noise-free level [LSB] at optical power ``power_w`` [W] (MULS Eq. 12 in LSB)."""
    return chans.dark_mean_lsb[c] + chans.lsb_per_w[c] * power_w
