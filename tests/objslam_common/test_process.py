"""objslam_common.process: BLAS pinned before numpy loads, glibc keeping freed memory."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from objslam_common import process

# Frees that glibc's defaults hand back to the kernel: a 1 MiB array sets its dynamic mmap
# threshold to 1 MiB (trim threshold 2 MiB), then two 1.5 MiB arrays come from the heap
# and, freed, leave 3 MiB at its top, which is trimmed, so each round faults them in again.
_CHURN = """
import resource, sys
if sys.argv[1] == "objslam":
    import objslam_common
import numpy as np
def faults():
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
a = np.ones(1 << 17); del a
before = faults()
for _ in range(100):
    b = np.ones(3 << 16); c = np.ones(3 << 16)
    del b, c
print(faults() - before)
"""


def _faults(mode: str) -> int:
    result = subprocess.run([sys.executable, "-c", _CHURN, mode], capture_output=True, text=True, check=True)
    return int(result.stdout.strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator only")
def test_importing_objslam_keeps_freed_memory() -> None:
    plain, tuned = _faults("numpy"), _faults("objslam")
    assert plain > 10_000  # the churn above does fault under glibc's defaults
    assert tuned < plain / 20


def test_user_thresholds_win(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "131072")
    assert process.keep_freed_memory() is False


def test_blas_pinned_before_numpy_for_a_direct_submodule_import() -> None:
    code = "import os, sys; import objslam_mapper.inference.chains;print(os.environ['OPENBLAS_NUM_THREADS'])"
    env = {k: v for k, v in os.environ.items() if k not in process.BLAS_THREAD_VARIABLES}
    out = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", code], capture_output=True, text=True, env=env, check=True
    )
    order = [line.rsplit("|", 1)[1].strip() for line in out.stderr.splitlines() if line.startswith("import time:")]
    assert out.stdout.strip() == "1"
    assert order.index("objslam_common") < order.index("numpy")
