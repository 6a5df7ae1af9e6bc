"""Perspective and fisheye camera models against OpenCV's own functions, the round trip,
the field of view's edge, and the calibrations they refuse (docs/design.md, "Cameras and the mount")."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from objslam_common.cameras import (
    FisheyeCamera,
    PinholeCamera,
    UnifiedCamera,
    camera_from_calibration,
)
from objslam_common.cameras.rays import directions_from_rays, optical_from_camera, rays_from_directions
from objslam_common.errors import CameraModelError

K_640x480 = [300.0, 0.0, 321.5, 0.0, 305.0, 238.0, 0.0, 0.0, 1.0]


def _k(camera) -> np.ndarray:
    return np.array([[camera.fx, 0.0, camera.cx], [0.0, camera.fy, camera.cy], [0.0, 0.0, 1.0]])


def _unit(rays: np.ndarray) -> np.ndarray:
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


# Distortions like real lenses': barrel with some tangential, and a rational lens.
PLUMB_BOBS = st.tuples(
    st.floats(-0.4, 0.1),
    st.floats(-0.1, 0.2),
    st.floats(-0.003, 0.003),
    st.floats(-0.003, 0.003),
    st.floats(-0.05, 0.05),
)
RATIONALS = st.tuples(
    st.floats(-0.4, 0.4), st.floats(-0.1, 0.1), st.floats(-0.003, 0.003), st.floats(-0.003, 0.003),
    st.floats(-0.02, 0.02), st.floats(-0.2, 0.4), st.floats(-0.05, 0.05), st.floats(-0.01, 0.01),
)  # fmt: skip
FISHEYES = st.tuples(st.floats(-0.05, 0.1), st.floats(-0.03, 0.03), st.floats(-0.01, 0.01), st.floats(-0.003, 0.003))


def _rays_in_view(seed: int, count: int, max_off_axis_rad: float) -> np.ndarray:
    """Camera-frame rays within ``max_off_axis_rad`` of the optical axis (camera x)."""
    rng = np.random.default_rng(seed)
    off = rng.uniform(0.0, max_off_axis_rad, count)
    around = rng.uniform(-np.pi, np.pi, count)
    # optical (X, Y, Z) = (sin off cos around, sin off sin around, cos off); camera = (Z, -X, -Y)
    return np.stack([np.cos(off), -np.sin(off) * np.cos(around), -np.sin(off) * np.sin(around)], axis=1)


@settings(max_examples=60, deadline=None)
@given(d=PLUMB_BOBS | RATIONALS, seed=st.integers(0, 2**16))
def test_pinhole_models_project_and_unproject_as_opencv_does(d, seed):
    model = "plumb_bob" if len(d) == 5 else "rational_polynomial"
    camera = camera_from_calibration(640, 480, model, d, K_640x480)
    assert isinstance(camera, PinholeCamera)
    # Up to 80 % of the fold's angle: near the fold the inverse is ill-conditioned and
    # OpenCV's iteration (the reference) may settle on the fold's other side.
    rays = _rays_in_view(seed, 50, min(np.arctan(camera.max_tan), np.radians(55)) * 0.8)
    uv, valid = camera.project_rays(rays)
    assert valid.all()
    reference, _ = cv2.projectPoints(optical_from_camera(rays), np.zeros(3), np.zeros(3), _k(camera), np.array(d))
    np.testing.assert_allclose(uv, reference.reshape(-1, 2), atol=1e-8)
    # Back: our Newton solve against OpenCV's iterated undistortion, run to convergence.
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    normalized = cv2.undistortPoints(
        uv.reshape(-1, 1, 2), _k(camera), np.array(d), None, np.eye(3), np.eye(3), criteria
    )
    optical = np.concatenate([normalized.reshape(-1, 2), np.ones((len(uv), 1))], axis=1)
    np.testing.assert_allclose(optical_from_camera(camera.unproject_pixels(uv)), _unit(optical), atol=1e-9)
    np.testing.assert_allclose(camera.unproject_pixels(uv), _unit(rays), atol=1e-9)  # the round trip


@settings(max_examples=60, deadline=None)
@given(d=FISHEYES, seed=st.integers(0, 2**16))
def test_the_fisheye_projects_and_unprojects_as_opencv_does(d, seed):
    camera = camera_from_calibration(640, 640, "equidistant", d, [180.0, 0.0, 320.0, 0.0, 181.0, 318.0, 0.0, 0.0, 1.0])
    assert isinstance(camera, FisheyeCamera)
    # OpenCV's fisheye takes points in front of the camera only (it divides by Z).
    rays = _rays_in_view(seed, 50, min(camera.max_theta, np.radians(85)) * 0.98)
    uv, valid = camera.project_rays(rays)
    assert valid.all()
    reference, _ = cv2.fisheye.projectPoints(
        optical_from_camera(rays).reshape(-1, 1, 3), np.zeros(3), np.zeros(3), _k(camera), np.array(d)
    )
    np.testing.assert_allclose(uv, reference.reshape(-1, 2), atol=1e-8)
    # OpenCV's fisheye undistortion clamps the distorted angle to 90 degrees: compare below it
    # (the round trip covers the rest).
    below = np.hypot((uv[:, 0] - camera.cx) / camera.fx, (uv[:, 1] - camera.cy) / camera.fy) < np.pi / 2 - 1e-3
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    normalized = cv2.fisheye.undistortPoints(uv[below].reshape(-1, 1, 2), _k(camera), np.array(d), criteria=criteria)
    optical = np.concatenate([normalized.reshape(-1, 2), np.ones((int(below.sum()), 1))], axis=1)
    ours = optical_from_camera(camera.unproject_pixels(uv[below]))
    np.testing.assert_allclose(ours, _unit(optical), atol=1e-8)
    np.testing.assert_allclose(camera.unproject_pixels(uv), _unit(rays), atol=1e-9)


def test_a_fisheye_sees_beyond_90_degrees_and_round_trips_there():
    camera = camera_from_calibration(640, 640, "equidistant", [0.0, 0.0, 0.0, 0.0], [100, 0, 320, 0, 100, 320, 0, 0, 1])
    # 100 degrees off the axis (behind the image plane): equidistant, r = f * theta.
    rays = _rays_in_view(1, 20, np.radians(100))
    uv, valid = camera.project_rays(rays)
    assert valid.all()
    off_axis = np.arccos(np.clip(rays[:, 0], -1, 1))
    np.testing.assert_allclose(np.hypot(uv[:, 0] - 320, uv[:, 1] - 320), 100 * off_axis, rtol=1e-12)
    np.testing.assert_allclose(camera.unproject_pixels(uv), rays, atol=1e-12)


def test_the_field_of_view_ends_behind_a_pinhole_and_where_the_distortion_folds():
    camera = camera_from_calibration(640, 480, "plumb_bob", [-0.35, 0.0, 0.0, 0.0, 0.0], K_640x480)
    # r (1 + k1 r^2) stops growing where 1 + 3 k1 r^2 = 0: r = 1 / sqrt(1.05).
    assert camera.max_tan == pytest.approx(1 / np.sqrt(1.05), abs=1e-3)
    just_in = np.radians(np.degrees(np.arctan(camera.max_tan)) - 0.5)
    just_out = np.radians(np.degrees(np.arctan(camera.max_tan)) + 0.5)
    rays = rays_from_directions([0.0, just_in, just_out, np.pi, 0.3], [0.0, 0.0, 0.0, 0.0, -0.2])
    _uv, valid = camera.project_rays(rays)
    assert valid.tolist() == [True, True, False, False, True]  # ahead, edge, past the fold, behind, ahead


def test_the_unified_model_has_the_same_interface_and_its_contract_formula():
    camera = camera_from_calibration(640, 640, "unified", [0.9], [170, 0, 320, 0, 170, 320, 0, 0, 1])
    assert isinstance(camera, UnifiedCamera)
    azimuth, elevation = np.array([0.3, -2.0, 1.0]), np.array([-0.4, 0.1, 1.2])
    rays = rays_from_directions(azimuth, elevation)
    uv, valid = camera.project_rays(rays)
    assert valid.tolist() == [True, True, False]  # 1.2 rad is above arcsin(0.9) = 1.12 rad: not seen
    sphere = np.stack([rays[:, 0], rays[:, 1], -rays[:, 2]], axis=1)  # the contract's sphere point
    m = sphere[:2, :2] / (sphere[:2, 2:] + 0.9)
    np.testing.assert_allclose(uv[:2], np.stack([320 + 170 * m[:, 0], 320 - 170 * m[:, 1]], axis=1), atol=1e-9)
    np.testing.assert_allclose(directions_from_rays(camera.unproject_pixels(uv[:2])), (azimuth[:2], elevation[:2]))


@pytest.mark.parametrize(
    ("model", "d", "k", "message"),
    [
        ("kannala_brandt", [0.0] * 4, K_640x480, "unknown distortion_model 'kannala_brandt' (supported: unified, "),
        ("plumb_bob", [0.0] * 4, K_640x480, "plumb_bob: d must hold 5 coefficients, got 4"),
        ("rational_polynomial", [0.0] * 5, K_640x480, "rational_polynomial: d must hold 8 coefficients, got 5"),
        ("equidistant", [0.0] * 5, K_640x480, "equidistant: d must hold 4 coefficients, got 5"),
        ("plumb_bob", [0.0] * 5, [0.0, 0, 320, 0, 300, 240, 0, 0, 1], "plumb_bob: focal lengths must be positive"),
        ("equidistant", [0.0] * 4, [-3.0, 0, 320, 0, 300, 240, 0, 0, 1], "equidistant: focal lengths must be positive"),
        ("plumb_bob", [float("nan")] + [0.0] * 4, K_640x480, "plumb_bob: calibration values must be finite"),
        ("plumb_bob", [0.0] * 5, [300.0] * 4, "plumb_bob: k must hold 9 values, got 4"),
    ],
)
def test_calibrations_no_model_fits_are_one_line(model, d, k, message):
    with pytest.raises(CameraModelError) as error:
        camera_from_calibration(640, 480, model, d, k)
    assert message in str(error.value) and "\n" not in str(error.value)
