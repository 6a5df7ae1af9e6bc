"""Process-wide settings for numeric work: one BLAS thread, and freed memory kept for reuse.

Both are applied when :mod:`objslam_common` is imported (every objslam package imports it
first), before numpy loads its BLAS; a value the user exported wins.

- **BLAS threads.** The solver's linear systems are small (poses banded, a few objects
  dense): BLAS threads only contend for the cores, and made a warm solve several times
  slower when measured.
- **glibc's allocator.** A chain allocates and frees many arrays of a few hundred kB to a
  few MB per solve. With glibc's defaults those above its mmap threshold are handed back to
  the kernel when freed, and the top of the heap is trimmed, so the next solve faults the
  same pages in again: a chain of 6000 steps on ``bags/office`` in a fresh process took 1.0
  million page faults and 2.1 s of system time (24.9 s in all), against 0.08 million and
  0.9 s (23.6 s) with the thresholds below. Memory is kept, not grown: the peak resident
  size was the same (436 MB) both ways. Where the C library is not glibc nothing changes.
"""

from __future__ import annotations

import ctypes
import logging
import os
import sys

logger = logging.getLogger(__name__)

BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

# mallopt(3) parameters and the values set: allocations up to 32 MiB come from the heap,
# and up to 256 MiB of free memory at its top stays mapped.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
TRIM_THRESHOLD_BYTES = 256 * 1024 * 1024
_ALLOCATOR_VARIABLES = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")


def pin_blas_threads() -> None:
    """One BLAS thread, unless the user exported a count (only takes effect before numpy loads)."""
    for variable in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(variable, "1")


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds (module docstring); whether they were set.

    Nothing is changed off Linux, under another C library, or when the user exported either
    threshold (glibc reads those at start, and theirs wins).
    """
    if not sys.platform.startswith("linux") or any(v in os.environ for v in _ALLOCATOR_VARIABLES):
        return False
    try:
        # The symbols this process already has: the C library whose allocator is in use, found
        # without the search (and, on some systems, the subprocess) of ctypes.util.find_library.
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # musl and others have no mallopt
        return False
    ok = mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1 and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
    if not ok:
        logger.debug("mallopt refused the allocator thresholds; glibc's defaults stay")
    return ok
