"""MULS: the multi-channel underwater lidar waveform model (physics only, usable alone)."""

from .errors import ParameterError
from .instrument import Channel, Digitizer, Instrument, Processing, Receiver, Reference, Transmitter
from .overlap import TransceiverGeometry
from .presets import WATER_PRESETS, coaxial, instrument_preset, mul2023, single_channel, water_preset
from .pulse import PulseShape
from .water import Water

__all__ = [
    "Channel", "Digitizer", "Instrument", "ParameterError", "Processing", "PulseShape", "Receiver",
    "Reference", "TransceiverGeometry", "Transmitter", "WATER_PRESETS", "Water", "coaxial", "instrument_preset",
    "mul2023", "single_channel", "water_preset",
]
