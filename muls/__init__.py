"""MULS: the multi-channel underwater lidar waveform model (physics only, usable alone)."""

from .infra.errors import ParameterError
from .instrument.description import Channel, Digitiser, Instrument, Processing, Receiver, Reference, Transmitter
from .instrument.overlap import TransceiverGeometry
from .instrument.pulse import PulseShape
from .presets import WATER_PRESETS, coaxial, instrument_preset, mul2023, single_channel, water_preset
from .water.properties import Water

__all__ = [
    "Channel", "Digitiser", "Instrument", "ParameterError", "Processing", "PulseShape", "Receiver",
    "Reference", "TransceiverGeometry", "Transmitter", "WATER_PRESETS", "Water", "coaxial", "instrument_preset",
    "mul2023", "single_channel", "water_preset",
]
