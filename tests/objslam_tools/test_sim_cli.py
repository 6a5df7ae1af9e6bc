"""``objslam sim``: user mistakes are one line and exit 2; a short run writes a complete bag."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from objslam_tools import cli
from objslam_tools.ground_truth import load_ground_truth


def run_cli(capsys, *args: str) -> tuple[int, str, str]:
    code = cli.main(["sim", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_unknown_scenario_is_one_line_exit_2_without_traceback(tmp_path) -> None:
    out = tmp_path / "x"
    proc = subprocess.run(
        [sys.executable, "-m", "objslam_tools.cli", "sim", "nosuchscenario", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("objslam sim: error: unknown scenario 'nosuchscenario'")
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_refuses_to_overwrite_an_existing_directory(tmp_path, capsys) -> None:
    out = tmp_path / "bag"
    out.mkdir()
    (out / "precious.txt").write_text("keep me")
    code, _out, err = run_cli(capsys, "small", "--out", str(out), "--frames", "2")
    assert code == 2
    assert "already exists" in err and len(err.strip().splitlines()) == 1
    assert (out / "precious.txt").read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]


@pytest.mark.parametrize("args", [("--frames", "1"), ("--seed", "-3"), ("--jpeg-quality", "0", "--compressed")])
def test_bad_numbers_are_user_errors(tmp_path, capsys, args) -> None:
    code, _out, err = run_cli(capsys, "small", "--out", str(tmp_path / "bag"), *args)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "bag").exists()


@pytest.mark.parametrize("compressed", [True, False])
def test_short_run_writes_a_complete_bag(tmp_path, capsys, compressed: bool) -> None:
    out = tmp_path / "nested" / "bag"
    code, stdout, err = run_cli(
        capsys, "twins", "--out", str(out), "--frames", "3", "--seed", "4", *(["--compressed"] if compressed else [])
    )
    assert code == 0, err
    assert "3/3 frames" in err  # progress on stderr
    assert "wrote" in stdout
    assert sorted(p.name for p in out.iterdir()) == ["bag.mcap", "ground_truth.yaml", "metadata.yaml"]
    assert sorted(p.name for p in out.parent.iterdir()) == ["bag"]  # no staging left behind
    gt = load_ground_truth(out)
    assert gt.simulation["scenario"] == "twins" and gt.simulation["seed"] == 4 and gt.simulation["frames"] == 3
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Reader(out) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        image_topic = "/camera/image_raw/compressed" if compressed else "/camera/image_raw"
        assert counts[image_topic] == 3 and counts["/camera/camera_info"] == 3
        assert counts["/odom"] == counts["/ground_truth/odom"] >= 21
        conn = next(c for c in reader.connections if c.topic == image_topic)
        _c, _t, raw = next(reader.messages(connections=[conn]))
        msg = typestore.deserialize_cdr(raw, conn.msgtype)
        if compressed:
            assert msg.format == "jpeg" and bytes(msg.data[:2]) == b"\xff\xd8"
        else:
            assert (msg.encoding, msg.width, msg.height) == ("rgb8", 640, 640)
            assert np.asarray(msg.data).size == 640 * 640 * 3
