"""The registry of ``scanner-sim``'s subcommands: a builder function per subcommand that adds its parser and sets
``func``, registered with ``@subcommand("name")``."""

from __future__ import annotations

from collections.abc import Callable

SUBCOMMANDS: dict[str, Callable] = {}


def subcommand(name: str):
    """Register a builder ``f(subparsers) -> None`` that adds subcommand ``name``."""

    def deco(builder):
        SUBCOMMANDS[name] = builder
        return builder

    return deco
