"""Values that validate but are far outside their key's physical range for its unit: most likely written in
another unit (radians in a ``_deg`` key, seconds in a ``_ns`` key, degrees in a ``_rad`` key, millijoules in
``pulse_energy_j`` read as joules). Each draws a :class:`SetupWarning` naming the key and the likely slip; the
pass still runs. ``docs/errors.md`` lists the ranges.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from typing import NamedTuple

from scanner_sim.config.errors import SetupWarning


class UnitSlip(NamedTuple):
    """A key, the test its value fails when it is likely in another unit, and what to say then."""

    key: str
    suspicious: Callable[[float], bool]
    slip: Callable[[float], str]


def _seconds_as_ns(v: float) -> str:
    return f"under 1e-3 ns: seconds? ({v:g} s would be {v * 1e9:g} ns)"


def _radians_as_deg(v: float) -> str:
    return f"under 2 degrees: radians? ({v:g} rad would be {math.degrees(v):.0f} deg)"


def _degrees_as_rad(v: float) -> str:
    return (f"over 1 rad ({math.degrees(v):.0f} deg): degrees or milliradians? ({v:g} deg would be "
            f"{math.radians(v):.4g} rad, {v:g} mrad {v * 1e-3:g} rad)")


#: The checked keys. A scan sector of under 2 degrees or a pulse, gate or delay under a picosecond is not an
#: instrument anyone flies; a 532 nm survey lidar's pulse is micro- to millijoules (the MUL's 500 uJ, a few mJ at
#: most); beams and fields of view wider than a radian are not lidar optics.
UNIT_SLIPS = (
    UnitSlip("scanner.sector_deg", lambda v: 0.0 < v < 2.0, _radians_as_deg),
    UnitSlip("instrument.gate_delay_ns", lambda v: 0.0 < v < 1e-3, _seconds_as_ns),
    UnitSlip("instrument.gate_width_ns", lambda v: 0.0 < v < 1e-3, _seconds_as_ns),
    UnitSlip("instrument.pulse_width_ns", lambda v: 0.0 < v < 1e-3, _seconds_as_ns),
    UnitSlip("instrument.pulse_energy_j", lambda v: v > 1.0,
             lambda v: f"over 1 J: millijoules or microjoules? ({v:g} mJ would be {v * 1e-3:g} J, {v:g} uJ "
                       f"{v * 1e-6:g} J)"),
    UnitSlip("instrument.beam_divergence_full_rad", lambda v: v > 1.0, _degrees_as_rad),
    UnitSlip("instrument.fov_full_rad", lambda v: v > 1.0, _degrees_as_rad),
)


def _value(config, key: str):
    node = config
    for name in key.split("."):
        node = getattr(node, name, None)
        if node is None:
            return None
    return node


def warn_unit_slips(config) -> None:
    """Warn (:class:`SetupWarning`) for each key of :data:`UNIT_SLIPS` whose value in ``config`` (a
    :class:`~scanner_sim.config.SceneConfig`) is likely in another unit."""
    for check in UNIT_SLIPS:
        value = _value(config, check.key)
        if isinstance(value, (int, float)) and check.suspicious(float(value)):
            warnings.warn(SetupWarning(f"{check.key} = {value:g}: {check.slip(float(value))}"), stacklevel=2)
