"""Public names that load on first use (PEP 562): a package's ``__getattr__`` and ``__dir__`` from a table of where
each name is defined, so that importing the package (and a command line's ``--help``) imports nothing behind it."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable


def lazy_names(package: str, where: dict[str, str]) -> tuple[list[str], Callable, Callable]:
    """``__all__``, ``__getattr__`` and ``__dir__`` for ``package`` (its ``__name__``); ``where`` maps each public
    name to the module that defines it (absolute, or relative to ``package``). A name is looked up once: it is then
    stored in the package's globals, and later look-ups do not reach ``__getattr__``."""

    def __getattr__(name: str):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(where[name], package), name)
        setattr(sys.modules[package], name, value)
        return value

    public = sorted(where, key=str.lower)

    def __dir__() -> list[str]:
        return sorted({*vars(sys.modules[package]), *public})

    return public, __getattr__, __dir__
