"""``objslam play`` refuses bad input with one line on stderr and exit code 2, before any ROS work."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import objslam_cmd
from tests.objslam_tools.synthetic_bag import odometry_records, write_bag

S = 1_000_000_000


def _odometry_only_bag(path):
    return write_bag(path, odometry_records("/odom", [S, 2 * S], np.zeros((2, 3))))


def _not_a_bag(tmp_path):
    (tmp_path / "notes.txt").write_text("not a bag")
    return tmp_path, "is not a rosbag2 bag (no metadata.yaml)"


def _missing(tmp_path):
    return tmp_path / "nope", "bag not found"


def _without_images(tmp_path):
    return _odometry_only_bag(tmp_path / "odom_only"), "has no camera image topic"


@pytest.mark.parametrize("make", [_not_a_bag, _missing, _without_images], ids=["not-a-bag", "missing", "no-image"])
def test_bad_bag_is_one_line_exit_2_without_traceback(tmp_path, processes, make):
    path, message = make(tmp_path)
    # The isolated domain of `processes` keeps a player that wrongly starts off the shared graph.
    proc = processes.run(objslam_cmd("play", str(path), "--delay", "0"))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("objslam play: error: ") and message in lines[0]
    assert "Traceback" not in proc.stderr
    assert proc.stdout == ""


def test_topics_missing_from_the_bag_are_refused(tmp_path, processes):
    # --topics lifts the image rule, but what it names must still be there.
    proc = processes.run(objslam_cmd("play", str(_odometry_only_bag(tmp_path / "b")), "--topics", "/odom", "/x"))
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"objslam play: error: bag {tmp_path / 'b'} has no topic /x (topics: /odom)"
    ]
