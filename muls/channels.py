"""Per-channel constants of the compiled kernels: gain in LSB per watt (Eqs. 12, 13), gates, dark and shot
noise. Built once per :class:`muls.waveform.OpticalModel` and passed to the kernels as one named tuple."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .instrument import Channel, Instrument

ELECTRON_CHARGE_C = 1.602176634e-19


def shot_noise_lsb2_per_w(channel: Channel, bandwidth_hz: float, lsb_per_volt: float) -> float:
    """Shot-noise variance per watt of received power [LSB^2/W]: 2 e B F M^2 S_k (xi_i P) (xi_v R_L)^2."""
    ch = channel
    return (2.0 * ELECTRON_CHARGE_C * bandwidth_hz * ch.excess_noise * ch.gain**2 * ch.sensitivity_a_per_w
            * ch.split_ratio * (ch.voltage_ratio * ch.load_ohm) ** 2 * lsb_per_volt**2)


class ChannelArrays(NamedTuple):
    """(n_channels + 1,) float64 each; index 0 is the CH0 reference, 1.. the signal channels in order.

    lsb_per_w [LSB/W]; gate_open_s / gate_close_s [s after emission] (-inf / inf when ungated);
    dark_mean_lsb, dark_std_lsb [LSB]; shot_lsb2_per_w [LSB^2/W] (0 for CH0).
    """

    lsb_per_w: np.ndarray
    gate_open_s: np.ndarray
    gate_close_s: np.ndarray
    dark_mean_lsb: np.ndarray
    dark_std_lsb: np.ndarray
    shot_lsb2_per_w: np.ndarray

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
        return cls(lsb, gate_open, gate_close, mean, std, shot)

    def signal(self) -> ChannelArrays:
        """The signal channels only (CH0 dropped): what the digitiser and peak kernels index by channel."""
        return ChannelArrays(*(a[1:] for a in self))
