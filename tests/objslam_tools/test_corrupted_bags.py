"""Damaged bags through ``objslam map``: a clear line and exit 2, or a map; never a traceback.

The bags are made here from bags/small: cut short, chunks overwritten, files missing,
metadata garbled, a topic of the wrong type. Overwritten bytes inside image data are not
caught by the reader (the map is built from whatever the JPEG decoder makes of them):
docs/reliability.md says so.
"""

from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest

from tests.conftest import BAGS, objslam_cmd
from tests.objslam_tools.synthetic_bag import image_msg, write_bag

SHORT = ("--samples", "200", "--burn-in", "50", "--chains", "1")


def _map(bag, tmp_path) -> subprocess.CompletedProcess:
    return subprocess.run(
        objslam_cmd("map", str(bag), "--out", str(tmp_path / "map.yaml"), *SHORT),
        capture_output=True,
        text=True,
        timeout=300,
    )


def _copy(tmp_path):
    copy = tmp_path / "bag"
    shutil.copytree(BAGS / "small", copy)
    return copy, copy / "small.mcap"


def _refused(done: subprocess.CompletedProcess, needle: str) -> None:
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 2, done.stderr
    errors = [line for line in done.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1, done.stderr
    assert needle in errors[0], errors[0]


@pytest.mark.parametrize("kept", [0.5, 0.999])
def test_a_bag_cut_short_is_one_line(tmp_path, kept):
    bag, mcap = _copy(tmp_path)
    with mcap.open("r+b") as f:
        f.truncate(int(os.path.getsize(mcap) * kept))
    _refused(_map(bag, tmp_path), f"cannot read bag {bag}")


# Where a 512-byte overwrite lands decides what breaks: a chunk or record header (refused),
# or image bytes (a map is built: nothing in the bag checks them). 0.01 and 0.97 once
# raised OverflowError out of the reader.
@pytest.mark.parametrize("at", [0.01, 0.3, 0.97])
def test_overwritten_bytes_give_a_map_or_one_line(tmp_path, at):
    bag, mcap = _copy(tmp_path)
    with mcap.open("r+b") as f:
        f.seek(int(os.path.getsize(mcap) * at))
        f.write(bytes([0xA5]) * 512)
    done = _map(bag, tmp_path)
    assert "Traceback" not in done.stderr, done.stderr
    if done.returncode == 0:
        assert (tmp_path / "map.yaml").is_file()
    else:
        _refused(done, f"bag {bag}")


def test_a_missing_storage_file_is_one_line(tmp_path):
    bag, mcap = _copy(tmp_path)
    mcap.unlink()
    _refused(_map(bag, tmp_path), "missing")


def test_garbled_metadata_is_one_line(tmp_path):
    bag, _ = _copy(tmp_path)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    _refused(_map(bag, tmp_path), f"cannot read bag {bag}")


def test_a_topic_of_the_wrong_type_is_one_line(tmp_path):
    bag = write_bag(tmp_path / "wrong", [("/odom", 1, image_msg(1, np.zeros((4, 4, 3), np.uint8)))])
    _refused(_map(bag, tmp_path), "topic /odom is sensor_msgs/msg/Image, expected nav_msgs/msg/Odometry")
