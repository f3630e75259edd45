"""Instrument description: transmitter, receiver, detection channels, digitiser, processing.

Values come from the paper's Table 1 and section 3 unless marked ``# assumption:``; every assumption is
listed with its reason in docs/assumptions.md. Angles are full angles (docs/design.md#angles: Table 1's
2 mrad and 50 mrad are read as half-angles, so the full angles are 4 and 100 mrad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

from ..infra.errors import ParameterError, check_choice, check_fraction, check_non_negative, check_positive
from .overlap import TransceiverGeometry
from .pulse import PulseShape


@dataclass(frozen=True)
class Transmitter:
    """Pulsed laser. Energy [J], FWHM [s], rate [Hz], beam diameter [m], divergence full angle [rad]."""

    wavelength_m: float = 532e-9  # Table 1
    pulse_energy_j: float = 500e-6  # Table 1
    pulse_width_s: float = 10e-9  # Table 1 (read as FWHM)
    repetition_rate_hz: float = 5e3  # Table 1
    beam_divergence_full_rad: float = 4e-3  # Table 1's 2 mrad read as a half-angle (docs/design.md#angles)
    beam_diameter_m: float = 0.010  # Table 1
    efficiency: float = 0.9  # assumption: eta_t, not given in the paper

    def __post_init__(self):
        for key in ("wavelength_m", "pulse_energy_j", "pulse_width_s", "repetition_rate_hz", "beam_diameter_m"):
            check_positive(f"transmitter.{key}", getattr(self, key))
        check_non_negative("transmitter.beam_divergence_full_rad", self.beam_divergence_full_rad)
        check_fraction("transmitter.efficiency", self.efficiency, open_low=True)


@dataclass(frozen=True)
class Receiver:
    """Receiver optics. Area [m^2], offset from the beam axis [m], FOV full angle [rad], filter width [m]."""

    area_m2: float = 4.4e-3  # Table 1
    offset_m: float = 0.130  # Table 1
    fov_full_rad: float = 0.100  # Table 1's 50 mrad read as a half-angle (docs/design.md#angles)
    filter_bandwidth_m: float = 1e-9  # Table 1
    efficiency: float = 0.60  # Table 1, eta_o
    window_reflectance: float = 0.0039  # assumption: T_s, Fresnel glass (n 1.52) to water (n 1.34)
    window_distance_m: float = 0.05  # assumption: D of Eq. 3, window 5 cm in front of the receiver lens
    window_coupling: float = 0.0  # O of Eq. 3: 0 for non-coaxial optics (the window is outside the FOV)
    overlap_model: str = "finite_aperture"  # each aperture point sees its own field (instrument.overlap); "eq11": Eq. 11

    def __post_init__(self):
        for key in ("area_m2", "fov_full_rad", "filter_bandwidth_m", "window_distance_m"):
            check_positive(f"receiver.{key}", getattr(self, key))
        check_non_negative("receiver.offset_m", self.offset_m)
        check_fraction("receiver.efficiency", self.efficiency, open_low=True)
        check_fraction("receiver.window_reflectance", self.window_reflectance)
        check_fraction("receiver.window_coupling", self.window_coupling)

    @property
    def diameter_m(self) -> float:
        """Aperture diameter [m] of a circular receiver of ``area_m2`` (75 mm lens FL1 for the MUL)."""
        return 2.0 * math.sqrt(self.area_m2 / math.pi)


@dataclass(frozen=True)
class Channel:
    """One digitised detection channel (MULS Eq. 12 and 13).

    split_ratio: xi_i, share of the received light reaching this channel's detector; voltage_ratio: xi_v,
    share of that detector's output voltage on this channel; sensitivity_a_per_w: S_k; gain: M;
    load_ohm: R_L; excess_noise: F; gate_delay_s / gate_width_s: range gate after emission [s] or None;
    dark_mean_lsb / dark_std_lsb: dark noise of the digitised record [LSB]; range_offset_m: Delta R_i.
    """

    name: str
    detector: str
    split_ratio: float
    voltage_ratio: float
    gain: float
    sensitivity_a_per_w: float = 0.077  # Table 1, S_k
    load_ohm: float = 50.0  # section 2.2.2, R_L
    excess_noise: float = 1.2  # assumption: F, a typical excess noise factor of a PMT (not given in the paper)
    gate_delay_s: float | None = None
    gate_width_s: float | None = None
    dark_mean_lsb: float = 8.0  # assumption: offset that keeps the dark baseline off code 0
    dark_std_lsb: float = 1.0  # assumption: dark noise 1 LSB rms (measured in the paper, value not given)
    range_offset_m: float = 0.0  # Eq. 14 Delta R_i: 0, the simulated instrument needs no calibration

    def __post_init__(self):
        if not self.name:
            raise ParameterError("channel name must not be empty")
        key = f"channels.{self.name}"
        check_fraction(f"{key}.split_ratio", self.split_ratio, open_low=True)
        check_fraction(f"{key}.voltage_ratio", self.voltage_ratio, open_low=True)
        for name in ("gain", "sensitivity_a_per_w", "load_ohm"):
            check_positive(f"{key}.{name}", getattr(self, name))
        if self.excess_noise < 1.0:
            raise ParameterError(f"{key}.excess_noise = {self.excess_noise!r}: must be >= 1")
        check_non_negative(f"{key}.dark_mean_lsb", self.dark_mean_lsb)
        check_non_negative(f"{key}.dark_std_lsb", self.dark_std_lsb)
        if (self.gate_delay_s is None) != (self.gate_width_s is None):
            raise ParameterError(f"{key}: give both gate_delay_s and gate_width_s, or neither")
        if self.gated:
            check_non_negative(f"{key}.gate_delay_s", self.gate_delay_s)
            check_positive(f"{key}.gate_width_s", self.gate_width_s)

    @property
    def gated(self) -> bool:
        return self.gate_delay_s is not None

    @property
    def volts_per_watt(self) -> float:
        """V_i / P_T [V/W] of this channel."""
        return self.split_ratio * self.voltage_ratio * self.sensitivity_a_per_w * self.gain * self.load_ohm  # MULS Eq. 12


@dataclass(frozen=True)
class Reference:
    """CH0: the PIN photodiode that sees a pick-off of each emitted pulse (section 3)."""

    peak_lsb: float = 600.0  # assumption: the reference pulse fills ~60 % of the 10-bit range
    dark_mean_lsb: float = 8.0  # assumption, as the signal channels
    dark_std_lsb: float = 1.0  # assumption, as the signal channels


@dataclass(frozen=True)
class Digitiser:
    """ADC of MULS Eq. 13: bits, sample rate [Hz], reference voltage V_d [V], analog bandwidth [Hz]."""

    bits: int = 10  # Table 1
    sample_rate_hz: float = 1e9  # Table 1
    full_scale_v: float = 1.0  # assumption: V_d, not given in the paper; 1 V is a common digitiser input range
    bandwidth_hz: float = 200e6  # Table 1
    record_length_s: float = 1e-6  # assumption: 1 us record (150 m of water), longer than any echo used
    pretrigger_s: float = 16e-9  # assumption: samples kept before the laser fires (CH0 baseline)

    def __post_init__(self):
        if not isinstance(self.bits, int) or isinstance(self.bits, bool) or not (1 <= self.bits <= 16):
            raise ParameterError(f"digitizer.bits = {self.bits!r}: must be an integer from 1 to 16")
        for key in ("sample_rate_hz", "full_scale_v", "bandwidth_hz", "record_length_s"):
            check_positive(f"digitizer.{key}", getattr(self, key))
        check_non_negative("digitizer.pretrigger_s", self.pretrigger_s)

    @property
    def max_code(self) -> int:
        return 2**self.bits - 1

    @property
    def sample_interval_s(self) -> float:
        return 1.0 / self.sample_rate_hz

    @property
    def lsb_per_volt(self) -> float:
        return 2**self.bits / self.full_scale_v  # MULS Eq. 13

    @property
    def n_samples(self) -> int:
        return int(round((self.record_length_s + self.pretrigger_s) * self.sample_rate_hz))


PEAK_FITS = ("pulse", "gaussian", "parabolic", "sample_maximum")
SATURATION_POLICIES = ("drop", "keep")


@dataclass(frozen=True)
class Processing:
    """How the instrument turns records into ranges (docs/design.md#ranging)."""

    threshold_sigma: float = 5.0  # assumption: k of the k-sigma threshold (false alarms < 3e-7 per sample)
    # three-point fit to the known pulse shape (unbiased), gaussian / parabolic, or "sample_maximum": the
    # prototype's plain peak detection on the 1 GS/s record (the highest sample, no sub-sample refinement)
    peak_fit: str = "pulse"
    saturation_policy: str = "keep"  # clipped returns are kept, flagged; "drop" makes them dropouts
    merge_window_s: float = 4e-9  # peaks of different channels closer than this are one echo
    tail_tolerance: float = 0.05  # assumption: a later peak must also clear 5 % of the earlier echoes' model

    def __post_init__(self):
        check_positive("processing.threshold_sigma", self.threshold_sigma)
        check_choice("processing.peak_fit", self.peak_fit, PEAK_FITS)
        check_choice("processing.saturation_policy", self.saturation_policy, SATURATION_POLICIES)
        check_positive("processing.merge_window_s", self.merge_window_s)
        check_fraction("processing.tail_tolerance", self.tail_tolerance)


@dataclass(frozen=True)
class Instrument:
    """A complete lidar: what muls needs to turn returns into records and ranges."""

    name: str
    channels: tuple[Channel, ...]
    transmitter: Transmitter = field(default_factory=Transmitter)
    receiver: Receiver = field(default_factory=Receiver)
    digitizer: Digitiser = field(default_factory=Digitiser)
    reference: Reference = field(default_factory=Reference)
    processing: Processing = field(default_factory=Processing)

    def __post_init__(self):
        if not self.channels:
            raise ParameterError(f"instrument '{self.name}': channels must list at least one channel")
        names = [ch.name for ch in self.channels]
        if len(set(names)) != len(names) or "ch0" in names:
            raise ParameterError(f"instrument '{self.name}': channel names {names} must be unique and not 'ch0'")
        object.__setattr__(self, "channels", tuple(self.channels))

    @property
    def geometry(self) -> TransceiverGeometry:
        return TransceiverGeometry(
            beam_diameter_m=self.transmitter.beam_diameter_m,
            beam_divergence_full_rad=self.transmitter.beam_divergence_full_rad,
            receiver_diameter_m=self.receiver.diameter_m,
            fov_full_rad=self.receiver.fov_full_rad,
            offset_m=self.receiver.offset_m,
            overlap_model=self.receiver.overlap_model,
        )

    @cached_property
    def pulse(self) -> PulseShape:
        """The emitted pulse as the digitiser sees it (through the analog bandwidth); one object per instrument, so
        that its solved constants (peak delay, fall to half) are solved once, not in every chunk."""
        return PulseShape(self.transmitter.pulse_width_s, self.digitizer.bandwidth_hz)

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(ch.name for ch in self.channels)

    def channel(self, name: str) -> Channel:
        for ch in self.channels:
            if ch.name == name:
                return ch
        raise ParameterError(f"channel = {name!r}: instrument '{self.name}' has {', '.join(self.channel_names)}")

    def with_channel(self, name: str, **changes) -> Instrument:
        """Copy with one channel's fields changed (for example its gate)."""
        self.channel(name)
        return replace(self, channels=tuple(replace(ch, **changes) if ch.name == name else ch for ch in self.channels))
