"""Names of a package that load their module on first use (PEP 562), so that importing the
package stays light: ``import abb_gym`` loads no numba, which the first use of the simulator
compiles and loads (docs/getting-started.md, "The first start compiles")."""
from __future__ import annotations

import importlib
import sys
from typing import Any, Callable, Mapping

__all__ = ["lazy_names"]


def lazy_names(package: str, homes: Mapping[str, str]
               ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module-level ``__getattr__`` and ``__dir__`` of ``package`` for the names in
    ``homes`` (name -> the package's submodule that defines it, e.g. ``"drives"``): a name is
    imported from its module when first read, then kept in the package."""

    def __getattr__(name: str) -> Any:
        if name in homes:
            value = getattr(importlib.import_module(f".{homes[name]}", package), name)
            setattr(sys.modules[package], name, value)
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(homes))

    return __getattr__, __dir__
