"""Project exceptions and input checks that name the key, the value and what is allowed."""

from __future__ import annotations

import math


class ParameterError(ValueError):
    """A parameter is outside what the model allows; the message says how to fix it."""


def check_positive(key: str, value: float) -> float:
    """Return ``value`` as float if it is finite and > 0, else raise naming ``key``."""
    value = _finite(key, value)
    if value <= 0.0:
        raise ParameterError(f"{key} = {value!r}: must be > 0")
    return value


def check_non_negative(key: str, value: float) -> float:
    """Return ``value`` as float if it is finite and >= 0, else raise naming ``key``."""
    value = _finite(key, value)
    if value < 0.0:
        raise ParameterError(f"{key} = {value!r}: must be >= 0")
    return value


def check_fraction(key: str, value: float, *, open_low: bool = False) -> float:
    """Return ``value`` if it lies in [0, 1] (or (0, 1] with ``open_low``), else raise."""
    value = _finite(key, value)
    low_ok = value > 0.0 if open_low else value >= 0.0
    if not (low_ok and value <= 1.0):
        allowed = "(0, 1]" if open_low else "[0, 1]"
        raise ParameterError(f"{key} = {value!r}: must lie in {allowed}")
    return value


def check_choice(key: str, value: str, allowed: tuple[str, ...] | list[str]) -> str:
    """Return ``value`` if it is one of ``allowed``, else raise listing the choices."""
    if value not in allowed:
        raise ParameterError(f"{key} = {value!r}: must be one of {', '.join(map(repr, allowed))}")
    return value


def _finite(key: str, value: float) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{key} = {value!r}: must be a number") from None
    if not math.isfinite(value):
        raise ParameterError(f"{key} = {value!r}: must be a finite number")
    return value
