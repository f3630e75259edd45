"""The strict base model of scene sections and the value types of scene files.

Every value type checks its input *before* pydantic does and raises :func:`~.errors.invalid` with the house
message (``must be a number > 0``, ``must be one of 'a', 'b' (did you mean 'a'?)``); pydantic's own
constraints on the same types feed the JSON Schema.
"""

import difflib
import math
from collections.abc import Mapping
from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from scanner_sim.config.errors import checked_at, invalid


class StrictModel(BaseModel):
    """A scene-file section: unknown keys are rejected with the nearest valid key suggested; values are
    checked strictly (no text for numbers but YAML's ``1e-3``, no numbers for text); instances are frozen."""

    model_config = ConfigDict(strict=True, extra="forbid", frozen=True, use_attribute_docstrings=True)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        keys = list(cls.model_fields)
        if data is None:  # an empty section in YAML (``scanner:``) takes every default
            return {}
        if isinstance(data, cls):
            return data
        if not isinstance(data, Mapping):
            raise invalid(f"must be a mapping with keys {', '.join(keys)}", value=data)
        for key in data:
            if key not in cls.model_fields:
                hint = difflib.get_close_matches(str(key), keys, n=1, cutoff=0.5)
                suggestion = f"did you mean {hint[0]!r}? " if hint else ""
                raise invalid(f"unknown key; {suggestion}(allowed: {', '.join(keys)})", key=str(key))
        return data


def number_check(gt: float | None = None, ge: float | None = None, lt: float | None = None,
                 le: float | None = None):
    """``check(value) -> float``: a finite number within the bounds. Text that reads as a number is taken,
    since YAML 1.1 (PyYAML) reads ``4e-3``, without a dot, as text."""
    bounds = [f"{op} {b:g}" for op, b in ((">", gt), (">=", ge), ("<", lt), ("<=", le)) if b is not None]
    allowed = " ".join(["must be a number", " and ".join(bounds)]).rstrip()

    def check(value: Any) -> float:
        if isinstance(value, str):
            try:
                value = float(value)
            except ValueError:
                raise invalid(allowed, value=value) from None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise invalid(allowed, value=value)
        value = float(value)
        if not math.isfinite(value):
            raise invalid("must be a finite number" + (f" ({' and '.join(bounds)})" if bounds else ""), value=value)
        if ((gt is not None and value <= gt) or (ge is not None and value < ge) or (lt is not None and value >= lt)
                or (le is not None and value > le)):
            raise invalid(allowed, value=value)
        return value

    return check


def Number(gt: float | None = None, ge: float | None = None, lt: float | None = None, le: float | None = None):
    """A finite float within the bounds (see :func:`number_check`)."""
    return Annotated[float, Field(gt=gt, ge=ge, lt=lt, le=le), BeforeValidator(number_check(gt, ge, lt, le))]


Real = Number()
Positive = Number(gt=0.0)
NonNegative = Number(ge=0.0)
Fraction = Number(ge=0.0, le=1.0)


def Integer(ge: int | None = None, le: int | None = None):
    """An integer within the bounds; a float with an integer value (``3.0``) is taken."""
    allowed = " ".join(["must be an integer", " and ".join(f"{op} {b}" for op, b in ((">=", ge), ("<=", le))
                                                         if b is not None)]).rstrip()

    def check(value: Any) -> int:
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise invalid(allowed, value=value)
        if (ge is not None and value < ge) or (le is not None and value > le):
            raise invalid(allowed, value=value)
        return value

    return Annotated[int, Field(ge=ge, le=le), BeforeValidator(check)]


def choice_check(*options: str | int):
    """``check(value)``: one of ``options``, of the same type (``True`` is not ``1``); a text typo gets the
    nearest option suggested."""
    allowed = f"must be one of {', '.join(map(repr, options))}"
    types = {type(o) for o in options}

    def check(value: Any) -> Any:
        if type(value) not in types or value not in options:
            hint = difflib.get_close_matches(value, [str(o) for o in options], n=1) if isinstance(value, str) else []
            raise invalid(allowed + (f" (did you mean {hint[0]!r}?)" if hint else ""), value=value)
        return value

    return check


def Choice(*options: str | int):
    """One of ``options`` (see :func:`choice_check`)."""
    return Annotated[Literal[options], BeforeValidator(choice_check(*options))]


def Vector(*sizes: int, element=Real):
    """A list of ``sizes`` numbers (each an ``element``), kept as a tuple of floats."""
    allowed = f"must be a list of {' or '.join(map(str, sizes))} numbers"

    def check(value: Any) -> tuple:
        if not isinstance(value, (list, tuple)) or len(value) not in sizes:
            raise invalid(allowed, value=value)
        return tuple(value)

    return Annotated[tuple[element, ...], Field(min_length=min(sizes), max_length=max(sizes)), BeforeValidator(check)]


def Points(*sizes: int, min_count: int = 2):
    """A list of at least ``min_count`` points of ``sizes`` numbers each, all of the same length [m]."""
    allowed = (f"must be a list of at least {min_count} points, each a list of {' or '.join(map(str, sizes))} "
               "numbers")

    def check(value: Any) -> tuple:
        if not isinstance(value, (list, tuple)) or len(value) < min_count:
            raise invalid(allowed, value=value)
        if len({len(p) for p in value if isinstance(p, (list, tuple))}) > 1:
            raise invalid("points must all have the same number of coordinates", value=value)
        return tuple(value)

    return Annotated[tuple[Vector(*sizes), ...], Field(min_length=min_count), BeforeValidator(check)]


def _fractions(value: Any) -> float | tuple[float, ...]:
    one = number_check(ge=0.0, le=1.0)
    if not isinstance(value, (list, tuple)):
        return one(value)
    if not value:
        raise invalid("must be a number in [0, 1] or a non-empty list of them", value=value)
    return tuple(checked_at(f"[{i}]", one, v) for i, v in enumerate(value))


#: A fraction in [0, 1], or a list of them (one per point of a cable).
Fractions = Annotated[Fraction | Annotated[tuple[Fraction, ...], Field(min_length=1)], BeforeValidator(_fractions)]
