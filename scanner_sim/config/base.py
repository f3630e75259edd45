"""The strict base model of scene sections, the value types of scene files, and one-line errors.

Every value type checks its input *before* pydantic does and raises :func:`invalid` with the house message
(``must be a number > 0``, ``must be one of 'a', 'b' (did you mean 'a'?)``); pydantic's own constraints on
the same types feed the JSON Schema. :func:`config_error` turns the first error of a ``ValidationError``
into one :class:`ConfigError` line, ``KEY = VALUE: what is allowed``, with KEY dotted as in the file
(``objects[2].radius_m``).
"""

import difflib
import math
from collections.abc import Mapping
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    model_validator,
)
from pydantic_core import PydanticCustomError

from muls.errors import ParameterError


class ConfigError(ParameterError):
    """A scene file is wrong; the one-line message names the dotted key, the value and what is allowed."""


_HIDDEN = object()


def invalid(allowed: str, *, key: str | None = None, value: Any = _HIDDEN) -> PydanticCustomError:
    """An error :func:`config_error` prints as ``KEY = VALUE: allowed`` (or ``KEY: allowed`` without a value).

    ``key`` extends the path of the failing value: a model's cross-key check names one of its keys with it.
    """
    ctx: dict[str, Any] = {"allowed": allowed}
    if key is not None:
        ctx["key"] = key
    if value is not _HIDDEN:
        ctx["value"] = value
    return PydanticCustomError("scene", "{allowed}", ctx)


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


# --------------------------------------------------------------------------------------------------------
# Value types: Annotated types whose before-check gives the message and whose constraints give the schema.
# --------------------------------------------------------------------------------------------------------

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
    allowed = "must be an integer" + (f" >= {ge}" if ge is not None else "") + (f" <= {le}" if le is not None else "")

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


def _sequence_check(sizes: tuple[int, ...], allowed: str):
    def check(value: Any) -> tuple:
        if not isinstance(value, (list, tuple)) or len(value) not in sizes:
            raise invalid(allowed, value=value)
        return tuple(value)

    return check


def Vector(*sizes: int, element=Real):
    """A list of ``sizes`` numbers (each an ``element``), kept as a tuple of floats."""
    check = _sequence_check(sizes, f"must be a list of {' or '.join(map(str, sizes))} numbers")
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


def checked_at(key: str, check, value: Any) -> Any:
    """``check(value)``, its error placed at ``key`` below the current path."""
    try:
        return check(value)
    except PydanticCustomError as exc:
        raise invalid(exc.context["allowed"], key=key, value=exc.context["value"]) from None


def _fractions(value: Any) -> float | tuple[float, ...]:
    one = number_check(ge=0.0, le=1.0)
    if not isinstance(value, (list, tuple)):
        return one(value)
    if not value:
        raise invalid("must be a number in [0, 1] or a non-empty list of them", value=value)
    return tuple(checked_at(f"[{i}]", one, v) for i, v in enumerate(value))


#: A fraction in [0, 1], or a list of them (one per point of a cable).
Fractions = Annotated[Fraction | Annotated[tuple[Fraction, ...], Field(min_length=1)], BeforeValidator(_fractions)]


# --------------------------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------------------------

#: Pydantic's error types the value types leave to pydantic, in the house style.
_MESSAGES = {"string_type": "must be a text string", "bool_type": "must be true or false"}


def config_error(exc: ValidationError, data: Any, path: str = "") -> ConfigError:
    """The first error of ``exc`` (raised validating ``data``) as one line naming the dotted key under
    ``path``, the value and what is allowed."""
    error = exc.errors(include_url=False)[0]
    where = _join(path, _dotted(error["loc"], data))
    ctx = error.get("ctx") or {}
    if error["type"] == "scene":
        where = _join(where, ctx.get("key", ""))
        if "value" not in ctx:
            return ConfigError(f"{where}: {ctx['allowed']}")
        value, allowed = ctx["value"], ctx["allowed"]
    elif error["type"] == "missing":
        return ConfigError(f"{where}: missing required key")
    else:
        value, allowed = error["input"], _MESSAGES.get(error["type"], error["msg"])
    return ConfigError(f"{where or 'scene'} = {value!r}: {allowed}")


def _join(path: str, key: str) -> str:
    if not key or key.startswith("["):
        return path + key
    return f"{path}.{key}" if path else key


def _dotted(loc: tuple, data: Any) -> str:
    """``objects[2].radius_m`` from pydantic's ``("objects", 2, "cylinder_mine", "radius_m")``: the path
    follows ``data``, so a discriminated union's tag (the object's ``type``, not a key) is left out."""
    path, node = "", data
    for item in loc:
        if isinstance(node, Mapping) and item not in node and item == node.get("type"):
            continue
        path = _join(path, f"[{item}]" if isinstance(item, int) else str(item))
        if isinstance(node, Mapping):
            node = node.get(item)
        elif isinstance(node, (list, tuple)) and isinstance(item, int) and item < len(node):
            node = node[item]
        else:
            node = None
    return path


def build(model: type[BaseModel], data: Any, path: str = "", context: dict | None = None):
    """``data`` validated as ``model``; raises :class:`ConfigError` naming keys under ``path``."""
    try:
        return model.model_validate(data, context=context)
    except ValidationError as exc:
        raise config_error(exc, data, path) from None
