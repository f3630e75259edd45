"""MULS: the multi-channel underwater lidar waveform model (physics only, usable alone).

The public names below load on first use (a module ``__getattr__``), so that ``import muls`` and the command
line's ``--help`` do not import the kernels behind them."""

from __future__ import annotations

from .infra.lazy_names import lazy_names

#: public name -> the module of this package that defines it.
_WHERE = {
    "ParameterError": ".infra.errors",
    **dict.fromkeys(("Channel", "Digitiser", "Instrument", "Processing", "Receiver", "Reference", "Transmitter"),
                    ".instrument.description"),
    "TransceiverGeometry": ".instrument.overlap",
    "PulseShape": ".instrument.pulse",
    **dict.fromkeys(("WATER_PRESETS", "coaxial", "instrument_preset", "mul2023", "single_channel", "water_preset"),
                    ".presets"),
    "Water": ".water.properties",
}

__all__, __getattr__, __dir__ = lazy_names(__name__, _WHERE)
