"""The unified camera model against the data contract's formula (docs/design.md, "Cameras and the mount")."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from objslam_common.cameras.unified import DEFAULT_CAMERA, UnifiedCamera
from objslam_common.errors import CameraModelError
from objslam_common.mount import CameraMount


@st.composite
def cameras(draw: st.DrawFn, square: bool = False) -> UnifiedCamera:
    xi = draw(st.floats(min_value=0.3, max_value=1.0, exclude_min=True))
    fx = draw(st.floats(min_value=50.0, max_value=400.0))
    fy = fx if square else draw(st.floats(min_value=50.0, max_value=400.0))
    cx = draw(st.floats(min_value=100.0, max_value=500.0))
    cy = draw(st.floats(min_value=100.0, max_value=500.0))
    return UnifiedCamera(width_px=640, height_px=640, xi=xi, fx=fx, fy=fy, cx=cx, cy=cy)


def unit_vector(azimuth: np.ndarray, elevation: np.ndarray) -> np.ndarray:
    """Direction (x forward, y left, z up) of an azimuth/elevation pair."""
    ce = np.cos(elevation)
    return np.stack([ce * np.cos(azimuth), ce * np.sin(azimuth), np.sin(elevation)], axis=-1)


@settings(max_examples=200, deadline=None)
@given(
    camera=cameras(),
    azimuth=st.floats(min_value=-np.pi, max_value=np.pi),
    elevation_fraction=st.floats(min_value=0.0, max_value=1.0),
)
def test_unproject_inverts_project(camera: UnifiedCamera, azimuth: float, elevation_fraction: float) -> None:
    # From straight down up to just below the highest elevation the model can image.
    elevation = -np.pi / 2 + 1e-4 + elevation_fraction * (camera.max_elevation_rad - 0.05 + np.pi / 2 - 1e-4)
    u, v = camera.project(azimuth, elevation)
    assert np.isfinite(u) and np.isfinite(v)
    az, el = camera.unproject(u, v)
    np.testing.assert_allclose(unit_vector(az, el), unit_vector(azimuth, elevation), atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(camera=cameras(), u=st.floats(min_value=0.0, max_value=640.0), v=st.floats(min_value=0.0, max_value=640.0))
def test_project_inverts_unproject(camera: UnifiedCamera, u: float, v: float) -> None:
    az, el = camera.unproject(u, v)
    assert el < camera.max_elevation_rad
    u2, v2 = camera.project(az, el)
    np.testing.assert_allclose([u2, v2], [u, v], atol=1e-6)


@settings(max_examples=100, deadline=None)
@given(camera=cameras(square=True), azimuth=st.floats(min_value=-np.pi, max_value=np.pi))
def test_horizon_is_the_ring_of_radius_f_over_xi(camera: UnifiedCamera, azimuth: float) -> None:
    u, v = camera.project(azimuth, 0.0)
    expected = camera.fx / camera.xi
    assert np.hypot(u - camera.cx, v - camera.cy) == pytest.approx(expected, rel=1e-12)
    assert camera.horizon_radius_px == pytest.approx(expected)
    assert camera.radius_px(0.0) == pytest.approx(expected)
    _az, el = camera.unproject(camera.cx + expected * np.cos(azimuth), camera.cy - expected * np.sin(azimuth))
    assert el == pytest.approx(0.0, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(camera=cameras(), azimuth=st.floats(min_value=-np.pi, max_value=np.pi))
def test_image_centre_looks_straight_down(camera: UnifiedCamera, azimuth: float) -> None:
    u, v = camera.project(azimuth, -np.pi / 2)
    assert (u, v) == (pytest.approx(camera.cx, abs=1e-9), pytest.approx(camera.cy, abs=1e-9))
    _az, el = camera.unproject(camera.cx, camera.cy)
    assert el == pytest.approx(-np.pi / 2, abs=1e-12)
    # unproject(project) is the identity at the centre too: the direction is straight down.
    np.testing.assert_allclose(unit_vector(*camera.unproject(u, v)), [0.0, 0.0, -1.0], atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(camera=cameras(square=True), e1=st.floats(-1.5, 0.3), e2=st.floats(-1.5, 0.3))
def test_radius_grows_with_elevation(camera: UnifiedCamera, e1: float, e2: float) -> None:
    lo, hi = sorted((e1, e2))
    if hi - lo < 1e-6 or hi >= camera.max_elevation_rad - 0.05:
        return
    assert camera.radius_px(lo) < camera.radius_px(hi)
    u, v = camera.project(0.3, hi)
    assert np.hypot(u - camera.cx, v - camera.cy) == pytest.approx(camera.radius_px(hi), rel=1e-9)


def test_default_camera_against_hand_computed_pixels() -> None:
    cam = DEFAULT_CAMERA
    assert (cam.width_px, cam.height_px, cam.xi, cam.fx, cam.fy, cam.cx, cam.cy) == (640, 640, 0.9, 170, 170, 320, 320)
    # Forward on the horizon: sphere point (1, 0, 0), m = 1 / 0.9.
    np.testing.assert_allclose(cam.project(0.0, 0.0), (320 + 170 / 0.9, 320))
    # Left (azimuth +90 deg) is up in the image: v = cy - fy * m_y.
    np.testing.assert_allclose(cam.project(np.pi / 2, 0.0), (320, 320 - 170 / 0.9), atol=1e-9)
    # 30 deg below the horizon, forward: sphere point (cos 30, 0, sin 30), m = 0.8660 / 1.4.
    np.testing.assert_allclose(cam.project(0.0, -np.pi / 6), (320 + 170 * np.cos(np.pi / 6) / 1.4, 320))


def test_from_camera_info_reads_the_contract_fields() -> None:
    cam = UnifiedCamera.from_camera_info(640, 640, "unified", [0.9], [170, 0, 320, 0, 170, 320, 0, 0, 1])
    assert cam == DEFAULT_CAMERA
    with pytest.raises(CameraModelError):
        UnifiedCamera.from_camera_info(640, 640, "plumb_bob", [0.9], [170, 0, 320, 0, 170, 320, 0, 0, 1])
    with pytest.raises(CameraModelError):
        UnifiedCamera(640, 640, xi=1.5, fx=170, fy=170, cx=320, cy=320)


def test_mount_directions() -> None:
    mount = CameraMount(height_m=0.5)
    az, el, rng = mount.direction_to([1.0, 2.0, np.pi / 2], [[1.0, 4.0, 0.5], [0.0, 2.0, 1.5]])
    np.testing.assert_allclose(az, [0.0, np.pi / 2])
    np.testing.assert_allclose(el, [0.0, np.pi / 4])
    np.testing.assert_allclose(rng, [2.0, 1.0])
