"""``objslam bench detector`` runs (in a subprocess: it pins its process to one CPU)."""

from __future__ import annotations

import json
import subprocess
import sys


def test_bench_detector_reports_images_per_second():
    result = subprocess.run(
        [sys.executable, "-m", "objslam_tools.cli", "bench", "detector", "--frames", "3", "--distinct", "2", "--json"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["images"] == 3 and data["images_per_s"] > 0 and data["image_size"] == [640, 640]


def test_bench_without_a_target_is_a_usage_error():
    result = subprocess.run(
        [sys.executable, "-m", "objslam_tools.cli", "bench"], capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 2 and "TARGET" in result.stderr
