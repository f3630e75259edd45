"""MULS: the multi-channel underwater lidar waveform model (physics only, usable alone).

The public names below load on first use (a module ``__getattr__``), so that ``import muls`` and the command
line's ``--help`` do not import the kernels behind them."""

from __future__ import annotations

import importlib

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

__all__ = sorted(_WHERE, key=str.lower)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_WHERE[name], __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
