"""Benchmarks behind ``objslam bench TARGET``.

Each target is one module of this package (``objslam_tools.subcommands``): adding
``objslam bench mapper`` means adding ``bench/mapper.py`` and touching nothing else.
"""

from __future__ import annotations

import os


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
