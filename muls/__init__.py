"""MULS: the multi-channel underwater lidar waveform model (physics only, usable alone)."""

from .errors import ParameterError
from .instrument import (Channel, Digitizer, Instrument, Processing, Receiver, Reference, Transmitter,
                         instrument_preset, mul2023)
from .overlap import TransceiverGeometry
from .pulse import PulseShape
from .water import WATER_PRESETS, Water, water_preset

__all__ = [
    "Channel", "Digitizer", "Instrument", "ParameterError", "Processing", "PulseShape", "Receiver",
    "Reference", "TransceiverGeometry", "Transmitter", "WATER_PRESETS", "Water", "instrument_preset",
    "mul2023", "water_preset",
]
