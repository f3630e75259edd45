"""The option checks and options the ``muls`` subcommands share: a water preset's name, a positive number, a count,
an attenuation rule, a table cell, and the ``--json``/``--out``/``--no-plot`` options. A check raises ValueError
naming the option, the value and what is allowed (the one-line error of :mod:`muls.infra.command`)."""

from __future__ import annotations

import math

from ..infra.command import output_file
from ..presets import WATER_PRESETS


def _one_of(option: str, name: str, allowed) -> str:
    """``name`` if it is in ``allowed``, else ValueError naming ``option``, the value and the names allowed."""
    if name not in allowed:
        raise ValueError(f"{option} {name!r}: must be one of {', '.join(allowed)}")
    return name


def _water_name(name: str) -> str:
    return _one_of("--water", name, sorted(WATER_PRESETS))


def _positive(option: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{option} {value!r}: must be a number > 0")
    return value


def _count(option: str, value: int) -> int:
    if value < 1:
        raise ValueError(f"{option} {value!r}: must be an integer >= 1")
    return value


def _attenuation(name: str) -> str:
    from ..water.properties import ATTENUATION_MODELS

    return _one_of("--attenuation", name, ATTENUATION_MODELS)


def _fmt(v, digits: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


def _waters() -> str:
    return ", ".join(sorted(WATER_PRESETS))


def _common(p, plot=True, out_type=output_file):
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    if plot:
        p.add_argument("--out", default=None, type=out_type(),
                       help="picture file (PNG); default %(prog)s's own name")
        p.add_argument("--no-plot", action="store_true", help="do not write the picture")
