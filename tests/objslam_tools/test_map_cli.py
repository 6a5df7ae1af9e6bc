"""``objslam map`` as a user runs it: mistakes cost one line and exit 2, before any work,
and outputs never overwrite inputs or earlier maps unasked."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess

import pytest
import yaml

from tests.conftest import BAGS, objslam_cmd

SHORT = ("--samples", "200", "--burn-in", "50", "--chains", "1")


def _map(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(objslam_cmd("map", *args), capture_output=True, text=True, timeout=timeout)


def _one_line_exit_2(done: subprocess.CompletedProcess, *needles: str) -> None:
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    errors = [line for line in done.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1, done.stderr
    for needle in needles:
        assert needle in errors[0]
    assert "detecting" not in done.stderr  # refused before the work


@pytest.fixture
def bag_copy(tmp_path):
    copy = tmp_path / "small"
    shutil.copytree(BAGS / "small", copy)
    return copy


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (("--samples", "10"), ("burn-in (2500) must be below the samples (10)", "--burn-in")),
        (("--samples", "100", "--burn-in", "100"), ("burn-in (100) must be below the samples (100)",)),
        (("--chains", "0"), ("--chains must be >= 1",)),
        (("--seed", "-1"), ("--seed must be >= 0",)),
    ],
)
def test_bad_chain_settings_are_one_line(tmp_path, args, needles):
    _one_line_exit_2(_map(str(BAGS / "small"), "--out", str(tmp_path / "m.yaml"), *args), *needles)
    assert not (tmp_path / "m.yaml").exists()


def test_out_inside_the_input_bag_is_refused_and_the_bag_kept(bag_copy):
    metadata = (bag_copy / "metadata.yaml").read_bytes()
    for out in (bag_copy / "metadata.yaml", bag_copy / "map.yaml"):
        _one_line_exit_2(_map(str(bag_copy), "--out", str(out), "--force", *SHORT), "would overwrite the input")
    assert (bag_copy / "metadata.yaml").read_bytes() == metadata
    assert not (bag_copy / "map.yaml").exists()


def test_an_existing_map_is_replaced_only_with_force(tmp_path):
    out = tmp_path / "m.yaml"
    out.write_text("mine\n")
    _one_line_exit_2(_map(str(BAGS / "small"), "--out", str(out), *SHORT), "exists; pass --force")
    assert out.read_text() == "mine\n"
    done = _map(str(BAGS / "small"), "--out", str(out), "--force", *SHORT)
    assert done.returncode == 0, done.stderr
    assert "objects" in yaml.safe_load(out.read_text())


def test_the_map_file_is_an_ordinary_file(tmp_path):
    out = tmp_path / "m.yaml"
    old = os.umask(0o022)
    try:
        done = _map(str(BAGS / "small"), "--out", str(out), *SHORT)
    finally:
        os.umask(old)
    assert done.returncode == 0, done.stderr
    assert stat.S_IMODE(out.stat().st_mode) == 0o644
    assert [p.name for p in tmp_path.iterdir()] == ["m.yaml"]  # no temporary file left


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_an_unwritable_output_is_found_before_the_work(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    _one_line_exit_2(_map(str(BAGS / "small"), "--out", str(locked / "m.yaml"), *SHORT), "no permission")
    _one_line_exit_2(
        _map(str(BAGS / "small"), "--out", str(tmp_path / "m.yaml"), "--figures", str(locked / "f"), *SHORT),
        "--figures",
        "no permission",
    )


def test_figures_that_are_a_file_are_found_before_the_work(tmp_path):
    (tmp_path / "f").write_text("a file\n")
    _one_line_exit_2(
        _map(str(BAGS / "small"), "--out", str(tmp_path / "m.yaml"), "--figures", str(tmp_path / "f"), *SHORT),
        "--figures",
        "is a file",
    )
    assert not (tmp_path / "m.yaml").exists()


def test_bad_messages_are_skipped_counted_and_reported_not_fatal(damaged_small_bag, tmp_path):
    out = tmp_path / "map.yaml"
    done = _map(str(damaged_small_bag), "--out", str(out), *SHORT)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    # One warning per kind of problem (the first), then one line with every count.
    assert "skipping an odometry message: odometry pose is not finite" in done.stderr
    assert "skipping a frame: cannot decode compressed image" in done.stderr
    assert (
        "objslam map: left out 3 invalid odometry messages (NaN or non-unit quaternion), "
        "1 frames (corrupt compressed data), 1 frames (size mismatch)"
    ) in done.stderr
    diagnostics = yaml.safe_load(out.read_text())["diagnostics"]
    assert diagnostics["invalid_odometry"] == 3
    assert diagnostics["dropped_messages"] == 3
    assert diagnostics["skipped_frames"] == {"corrupt compressed data": 1, "size mismatch": 1}
    assert diagnostics["slice_arrays"] == 98
    assert diagnostics["odometry_messages"] == 992 - 3


def test_a_calibration_that_fits_no_image_is_one_line(tmp_path):
    from tests.damaged_bag import damage_bag

    def wider(msg) -> None:
        msg.width += 10

    bag = damage_bag(BAGS / "small", tmp_path / "wrong_info", {"/camera/camera_info": dict.fromkeys(range(100), wider)})
    done = _map(str(bag), "--out", str(tmp_path / "map.yaml"), *SHORT)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    errors = [line for line in done.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1
    assert "no image of /camera/image_raw/compressed could be used (size mismatch: 100)" in errors[0]
    assert "but the camera calibration is" in done.stderr  # the warning gives the sizes
