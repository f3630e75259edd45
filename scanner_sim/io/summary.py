"""summary.json: a pass's counts, rates and settings as UTF-8 JSON, and the JSON conversion LAS metadata shares."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from muls.infra.atomic import PathLike, atomic_open

__all__ = ["jsonable", "write_summary_json"]


def jsonable(obj):
    """``obj`` with numpy scalars/arrays, paths, tuples, sets and dataclasses turned into JSON types.

    Non-finite floats (NaN, +-inf) become ``None``: JSON has no such numbers, and a ``NaN`` token
    breaks strict readers. Unknown objects raise ValueError naming their type.
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (int, np.integer)) and not isinstance(obj, bool):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (set, frozenset)):
        return [jsonable(v) for v in sorted(obj)]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return jsonable(dataclasses.asdict(obj))
    raise ValueError(f"summary value of type {type(obj).__name__} is not JSON-serialisable: {obj!r}")


def write_summary_json(path: PathLike, summary: Mapping[str, Any]) -> None:
    """Write ``summary`` as JSON (indent 2, keys in insertion order, UTF-8), atomically.

    Values are converted by :func:`jsonable` (numpy numbers become plain numbers, NaN ``null``).
    """
    if not isinstance(summary, Mapping):
        raise TypeError(f"write_summary_json: expected a mapping, got {type(summary).__name__}")
    text = json.dumps(jsonable(summary), indent=2, sort_keys=False, ensure_ascii=False, allow_nan=False)
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text + "\n")
