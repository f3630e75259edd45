"""The option checks and options the ``muls`` subcommands share: a water preset's name, a positive number, a count,
an attenuation rule, a table cell, and the ``--json``/``--out``/``--no-plot`` options. A check raises ValueError
naming the option, the value and what is allowed (the one-line error of :mod:`muls.infra.command`)."""

from __future__ import annotations

import math

from ..infra.command import nonempty, output_file
from ..presets import WATER_PRESETS


def one_of(option: str, name: str, allowed) -> str:
    """``name`` if it is in ``allowed``, else ValueError naming ``option``, the value and the names allowed."""
    if name not in allowed:
        raise ValueError(f"{option} {name!r}: must be one of {', '.join(allowed)}")
    return name


def water_name(name: str) -> str:
    """``--water``: a water preset's name."""
    return one_of("--water", name, sorted(WATER_PRESETS))


def positive_number(option: str, value: float) -> float:
    """``value`` if it is a finite number above 0, else ValueError naming ``option``."""
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{option} {value!r}: must be a number > 0")
    return value


def count_option(option: str, value: int) -> int:
    """``value`` if it is at least 1, else ValueError naming ``option``."""
    if value < 1:
        raise ValueError(f"{option} {value!r}: must be an integer >= 1")
    return value


def attenuation_rule(name: str) -> str:
    """``--attenuation``: one of the attenuation rules (:data:`muls.water.properties.ATTENUATION_MODELS`)."""
    from ..water.properties import ATTENUATION_MODELS

    return one_of("--attenuation", name, ATTENUATION_MODELS)


def add_attenuation_option(p) -> None:
    """``--attenuation``, the water's attenuation rule, ``monte_carlo`` unless given (:func:`attenuation_rule` checks
    it)."""
    from ..water.properties import ATTENUATION_MODELS

    p.add_argument("--attenuation", default="monte_carlo", type=nonempty(),
                   help=f"attenuation rule ({', '.join(ATTENUATION_MODELS)})")


def table_cell(v, digits: int = 3) -> str:
    """A printed table's cell: "-" for None, a float with ``digits`` decimals, anything else as str."""
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


def water_names() -> str:
    """The water presets' names, for a help text."""
    return ", ".join(sorted(WATER_PRESETS))


def add_output_options(p, plot=True, out_type=output_file):
    """``--json`` and, for a subcommand that draws (``plot``), ``--out`` (of type ``out_type``) and ``--no-plot``."""
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    if plot:
        p.add_argument("--out", default=None, type=out_type(),
                       help="picture file (PNG); default %(prog)s's own name")
        p.add_argument("--no-plot", action="store_true", help="do not write the picture")
