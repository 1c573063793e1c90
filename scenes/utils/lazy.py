"""A package's public names loaded on first use (PEP 562): ``scenes`` and ``model`` list where each
of their heavier names lives and import that module only when the name is first asked for, so
that importing the package stays cheap."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(package: str, homes: Mapping[str, str]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``package``: a name of ``homes`` (name -> the dotted module
    that defines it) imported from its module on first use and kept in the package's namespace;
    any other name an ``AttributeError``, as Python's own."""

    def module_getattr(name: str) -> Any:
        if name not in homes:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(homes[name]), name)
        setattr(sys.modules[package], name, value)
        return value

    return module_getattr


__all__ = ["lazy_exports"]
