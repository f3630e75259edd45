"""Scene errors as one line: ``KEY = VALUE: what is allowed``, KEY dotted as in the file.

Checks raise :func:`invalid` (a pydantic custom error carrying the house message); :func:`config_error`
turns the first error of a pydantic ``ValidationError`` into one :class:`ConfigError` line, with the key
dotted as in the file (``objects[2].radius_m``); :func:`build` validates a mapping with that conversion.
"""

import reprlib
from collections.abc import Mapping
from typing import Any

from pydantic import BaseModel, ValidationError
from pydantic_core import PydanticCustomError

from muls.infra.errors import ParameterError


class ConfigError(ParameterError):
    """A scene file is wrong; the one-line message names the dotted key, the value and what is allowed."""


class SetupWarning(UserWarning):
    """A scene that runs but likely not as meant (a track partly off the seabed, a speed in the wrong unit);
    the message names the key. ``scanner-sim`` prints it as one line."""


#: Values in messages are cut to about this many characters, so that a message stays one readable line.
_SHOWN = reprlib.Repr()
_SHOWN.maxstring = _SHOWN.maxother = 80
_SHOWN.maxlist = _SHOWN.maxtuple = 8


def shown(value: Any) -> str:
    """``repr(value)``, shortened (``[1, 2, 3, ...]``) when long or deeply nested."""
    return _SHOWN.repr(value)


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


def checked_at(key: str, check, value: Any) -> Any:
    """``check(value)``, its error placed at ``key`` below the current path."""
    try:
        return check(value)
    except PydanticCustomError as exc:
        raise invalid(exc.context["allowed"], key=key, value=exc.context["value"]) from None



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
    return ConfigError(f"{where or 'scene'} = {shown(value)}: {allowed}")


def _join(path: str, key: str) -> str:
    if not key or key.startswith("["):
        return path + key
    return f"{path}.{key}" if path else key


#: Tags of the discriminated unions that are not a ``type`` key of the data (the seabed section's kinds).
UNION_TAGS = ("procedural_seabed", "raster_seabed")


def _dotted(loc: tuple, data: Any) -> str:
    """``objects[2].radius_m`` from pydantic's ``("objects", 2, "cylinder_mine", "radius_m")``: the path
    follows ``data``, so a discriminated union's tag (the object's ``type``, the seabed's kind: not a key) is
    left out."""
    path, node = "", data
    for item in loc:
        if isinstance(node, Mapping) and item not in node and (item == node.get("type") or item in UNION_TAGS):
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


def config_value(config, key: str) -> str:
    """The value of a dotted scene key of ``config``, shortened for a message."""
    node = config
    for name in key.split("."):
        node = getattr(node, name)
    if hasattr(node, "model_dump"):
        node = node.model_dump()

    def lists(v):
        return [lists(x) for x in v] if isinstance(v, (tuple, list)) else v

    return shown(lists(node))
