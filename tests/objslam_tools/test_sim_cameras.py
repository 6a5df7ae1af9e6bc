"""Perspective and fisheye bags end to end: ``objslam sim --camera``, the detector on them
(``objslam eval-detector``) and a pinhole map (``objslam map``, ``objslam eval``)."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from objslam_common.cameras import PRESET_CAMERAS, FisheyeCamera, PinholeCamera
from objslam_tools.bag import open_bag
from objslam_tools.ground_truth import load_ground_truth
from objslam_tools.sim.render import Renderer
from tests.conftest import objslam_cmd


def _run(*args: str) -> subprocess.CompletedProcess:
    done = subprocess.run(objslam_cmd(*args), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return done


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """office, 80 frames, seen by each of the two cameras."""
    out = tmp_path_factory.mktemp("cameras")
    for camera in ("pinhole", "fisheye"):
        _run("sim", "office", "--camera", camera, "--frames", "80", "--out", str(out / camera))
    return out


@pytest.mark.parametrize(
    ("camera", "model", "kind"), [("pinhole", "plumb_bob", PinholeCamera), ("fisheye", "equidistant", FisheyeCamera)]
)
def test_a_rendered_bag_carries_its_camera_and_the_detector_measures_it(rendered, camera, model, kind):
    bag = open_bag(rendered / camera)
    read = bag.read_camera()
    assert isinstance(read, kind) and read.distortion_model == model and read == PRESET_CAMERAS[camera]
    # The mount, pitched down, is in /tf_static and in ground_truth.yaml alike.
    mount = bag.read_mount().mount
    truth = load_ground_truth(bag.directory).mount
    assert mount.pitch_rad == pytest.approx(0.1) and truth.pitch_rad == pytest.approx(0.1)
    for name in ("height_m", "offset_x_m", "offset_y_m", "yaw_rad", "roll_rad", "pitch_rad"):
        assert getattr(mount, name) == pytest.approx(getattr(truth, name), abs=1e-9), name
    report = json.loads(_run("eval-detector", str(bag.path), "--every", "5", "--json").stdout)
    overall = report["overall"]
    assert overall["recall"] >= 0.9
    assert overall["bearing_deg"]["median"] <= 0.3 and overall["elevation_top_deg"]["median"] <= 0.5


def test_a_pinhole_map_finds_the_objects_it_saw(rendered, tmp_path):
    out = tmp_path / "map.yaml"
    _run("map", str(rendered / "pinhole"), "--out", str(out), "--chains", "1", "--samples", "2000", "--burn-in", "500")
    maps = json.loads(_run("eval", str(out), "--bag", str(rendered / "pinhole"), "--json").stdout)["maps"]
    metrics = maps[0]["metrics"]
    # Measured 1.00 and 11 of 12 (one object is seen too rarely on this short run).
    assert metrics["precision"] == 1.0
    assert metrics["recall"] >= 0.8
    assert metrics["xy_error_median_m"] <= 0.1


def test_the_renderer_puts_a_direction_on_its_pixel_for_every_model():
    for camera in (PRESET_CAMERAS["pinhole"], PRESET_CAMERAS["fisheye"]):
        renderer = Renderer(camera)
        assert renderer.ray_count > 0.5 * camera.width_px * camera.height_px
        u, v = camera.project(np.array([0.2]), np.array([-0.1]))
        azimuth, elevation = camera.unproject(u, v)
        np.testing.assert_allclose([azimuth[0], elevation[0]], [0.2, -0.1], atol=1e-9)
