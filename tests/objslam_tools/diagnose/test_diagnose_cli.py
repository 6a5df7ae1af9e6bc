"""``objslam diagnose NAME`` on the bundled small bag: each diagnostic runs as a user would run it."""

from __future__ import annotations

import subprocess

import pytest

from tests.conftest import objslam_cmd


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("object-bias", "bias share (root mean square of the means over 5 objects)"),
        ("error-budget", "parts: rms over the objects"),
        ("aligned-covariance", "joint NEES xy, aligned, all objects"),
    ],
)
def test_each_diagnostic_runs_on_a_simulated_bag(repo_root, name, expected):
    done = subprocess.run(
        objslam_cmd("diagnose", name, str(repo_root / "bags" / "small")), capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert expected in done.stdout


def test_a_bag_without_ground_truth_is_one_line_and_exit_2(tmp_path):
    done = subprocess.run(objslam_cmd("diagnose", "object-bias", str(tmp_path)), capture_output=True, text=True)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "error:" in done.stderr
