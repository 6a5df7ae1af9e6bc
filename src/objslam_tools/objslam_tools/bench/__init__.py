"""Benchmarks behind ``objslam bench TARGET``.

Each target is one module of this package exposing ``DESCRIPTION`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``; targets are discovered, so adding
``objslam bench mapper`` means adding ``bench/mapper.py`` and touching nothing else.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
from types import ModuleType


def targets() -> dict[str, ModuleType]:
    """Benchmark modules by target name, sorted."""
    found = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "run") and hasattr(module, "add_arguments"):
            found[info.name.replace("_", "-")] = module
    return found


def use_one_core() -> int:
    """Pin this process to one CPU (the first it may use) and OpenCV to one thread; returns the CPU.

    Thread-count variables (OMP_NUM_THREADS, ...) only act when libraries load, which has
    happened by now: pinning is what makes "one core" true.
    """
    import cv2

    cpu = min(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 0
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {cpu})
    cv2.setNumThreads(1)
    return cpu
