"""``objslam bench detector`` runs (in a subprocess: it pins its process to one CPU)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


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


@pytest.mark.ros
def test_bench_soak_answers_every_build_of_a_looped_bag(ros_env):
    # One lap here, to keep the suite short (the figures of many laps are in docs/reliability.md);
    # in this test session's domain, which no other test uses meanwhile.
    result = subprocess.run(
        [sys.executable, "-m", "objslam_tools.cli", "bench", "soak", "--laps", "1", "--samples", "200",
         "--burn-in", "50", "--domain-id", ros_env["ROS_DOMAIN_ID"], "--json"],
        capture_output=True, text=True, timeout=300, check=False, env=ros_env,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["answered"] == data["succeeded"] == 1, data["rows"]
    assert all(r["objects"] > 0 and r["mapper_rss_mb"] > 50 for r in data["rows"])


def test_bench_soak_refuses_a_bad_request():
    result = subprocess.run(
        [sys.executable, "-m", "objslam_tools.cli", "bench", "soak", "--laps", "0"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert result.returncode == 2 and "--laps must be >= 1" in result.stderr and "Traceback" not in result.stderr
    result = subprocess.run(
        [sys.executable, "-m", "objslam_tools.cli", "bench", "soak", "--domain-id", "300"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert result.returncode == 2 and "--domain-id must be in 0-232" in result.stderr
