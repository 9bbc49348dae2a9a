"""Every baseline family by name: the open-loop profiles (:mod:`.profiles`) and the
closed-loop controllers (:mod:`.closed_loop`), validated from their declared fields."""
from __future__ import annotations

from typing import Any

from ..configuration import build as build_config
from .closed_loop import CLOSED_LOOP
from .profiles import FAMILIES as OPEN_LOOP
from .profiles import Family

__all__ = ["ALL_FAMILIES", "FAMILY_NAMES", "family_class", "build_family"]

ALL_FAMILIES: dict[str, type[Family]] = {**OPEN_LOOP, **CLOSED_LOOP}
FAMILY_NAMES = tuple(ALL_FAMILIES)


def family_class(name: str) -> type[Family]:
    """The class of family ``name`` (unknown names raise ``ValueError`` with the choices)."""
    if name not in ALL_FAMILIES:
        raise ValueError(f"unknown baseline {name!r}; available: {', '.join(ALL_FAMILIES)}")
    return ALL_FAMILIES[name]


def build_family(name: str, **params: Any) -> Family:
    """The family ``name`` with ``params`` (validated against its declarations)."""
    return build_config(family_class(name), params, f"baseline {name}")
