"""Diagnostics behind ``objslam diagnose NAME``: measurements of the method on simulated bags.

Each is one module of this package exposing ``DESCRIPTION`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``; they are discovered like the
benchmarks, so adding one touches no other file.
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType


def diagnostics() -> dict[str, ModuleType]:
    """Diagnostic modules by name (``error_budget`` is ``error-budget``), sorted."""
    found = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "run") and hasattr(module, "add_arguments"):
            found[info.name.replace("_", "-")] = module
    return found
