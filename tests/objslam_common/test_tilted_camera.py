"""The mount's roll and pitch: rotations against scipy, a tilted camera against OpenCV's
projection with the same rotation, the round trip, and a level mount left untouched."""

from __future__ import annotations

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from objslam_common.cameras import PRESET_CAMERAS, TiltedCamera, level_view
from objslam_common.cameras.rays import rays_from_directions
from objslam_common.geometry import quaternion_from_rpy, rotation_from_rpy, rpy_from_quaternion
from objslam_common.mount import CameraMount

ANGLES = st.floats(-1.2, 1.2)
# Optical frame (X right, Y down, Z forward) from REP 103 camera axes (x forward, y left, z up).
OPTICAL_R_CAMERA = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


@settings(max_examples=50, deadline=None)
@given(roll=ANGLES, pitch=ANGLES, yaw=st.floats(-3.1, 3.1))
def test_roll_pitch_yaw_are_ros_fixed_axes(roll, pitch, yaw):
    expected = Rotation.from_euler("xyz", [roll, pitch, yaw])  # extrinsic x, y, z: Rz Ry Rx
    np.testing.assert_allclose(rotation_from_rpy(roll, pitch, yaw), expected.as_matrix(), atol=1e-12)
    q = quaternion_from_rpy(roll, pitch, yaw)
    assert abs(abs(np.dot(q, expected.as_quat())) - 1.0) < 1e-12
    np.testing.assert_allclose(rpy_from_quaternion(*q), [roll, pitch, yaw], atol=1e-9)


def test_positive_pitch_looks_down():
    forward = rotation_from_rpy(0.0, 0.3) @ np.array([1.0, 0.0, 0.0])
    assert forward[2] < 0.0
    camera = TiltedCamera(PRESET_CAMERAS["pinhole"], 0.0, 0.3)
    u, v = camera.project(0.0, -0.3)  # the optical axis, 0.3 rad below the horizon
    np.testing.assert_allclose([u, v], [camera.lens.cx, camera.lens.cy], atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(roll=st.floats(-0.5, 0.5), pitch=st.floats(-0.6, 0.6), seed=st.integers(0, 2**16))
def test_a_tilted_pinhole_projects_as_opencv_does_with_the_mount_rotation(roll, pitch, seed):
    lens = PRESET_CAMERAS["pinhole"]
    camera = TiltedCamera(lens, roll, pitch)
    rng = np.random.default_rng(seed)
    # Level-frame directions the camera sees: around its optical axis, within 35 degrees.
    axis_az, axis_el = 0.0, -pitch
    rays = rays_from_directions(axis_az + rng.uniform(-0.6, 0.6, 50), axis_el + rng.uniform(-0.45, 0.45, 50))
    uv, valid = camera.project_rays(rays)
    optical_R_level = OPTICAL_R_CAMERA @ rotation_from_rpy(roll, pitch).T
    rvec, _ = cv2.Rodrigues(optical_R_level)
    k = np.array([[lens.fx, 0.0, lens.cx], [0.0, lens.fy, lens.cy], [0.0, 0.0, 1.0]])
    expected, _ = cv2.projectPoints(rays[valid].reshape(-1, 1, 3), rvec, np.zeros(3), k, np.array(lens.d))
    assert valid.mean() > 0.9
    np.testing.assert_allclose(uv[valid], expected.reshape(-1, 2), atol=1e-6)


@settings(max_examples=40, deadline=None)
@given(
    camera_name=st.sampled_from(["pinhole", "fisheye"]),
    roll=ANGLES,
    pitch=ANGLES,
    u=st.floats(20.0, 600.0),
    v=st.floats(20.0, 440.0),
)
def test_a_tilted_camera_round_trips_its_pixels(camera_name, roll, pitch, u, v):
    camera = TiltedCamera(PRESET_CAMERAS[camera_name], roll, pitch)
    azimuth, elevation = camera.unproject(u, v)
    back_u, back_v = camera.project(azimuth, elevation)
    np.testing.assert_allclose([back_u, back_v], [u, v], atol=1e-6)


def test_a_level_mount_keeps_the_lens_itself():
    lens = PRESET_CAMERAS["omni"]
    assert level_view(lens, 0.0, 0.0) is lens
    assert CameraMount(yaw_rad=1.0, offset_x_m=0.2).level_view(lens) is lens
    assert isinstance(CameraMount(pitch_rad=0.1).level_view(lens), TiltedCamera)
