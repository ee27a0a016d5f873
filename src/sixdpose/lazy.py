"""Lazy package attributes: a package names the module each public name lives in, and the module is
imported on first access (so building the CLI parser does not import torch, Open3D or Drake)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def by_module(**modules: tuple[str, ...]) -> dict[str, str]:
    """``{name: module}`` from ``module=(name, ...)`` keyword arguments (the table of :func:`lazy_getattr`)."""
    return {name: module for module, names in modules.items() for name in names}


def lazy_getattr(package: str, names: dict[str, str]) -> Callable[[str], Any]:
    """A module-level ``__getattr__`` for ``package`` (its ``__name__``) that imports
    ``package.<names[name]>`` on first access of ``name`` and returns its attribute ``name``.

    Usage, in a package's ``__init__``: ``__getattr__ = lazy_getattr(__name__, _LAZY)``.
    """

    def __getattr__(name: str) -> Any:
        if name in names:
            return getattr(importlib.import_module(f".{names[name]}", package), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
