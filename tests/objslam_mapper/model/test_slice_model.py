"""Slice model: silhouette extremes against brute force, analytic Jacobians against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from objslam_common.geometry import wrap_angle
from objslam_common.mount import CameraMount
from objslam_mapper.model.slice_model import (
    BEARING,
    ELEVATION_BOTTOM,
    ELEVATION_TOP,
    WIDTH,
    camera_positions,
    predict_reduced,
    predict_slices,
    slice_error,
)

MOUNT = CameraMount(height_m=0.5, offset_x_m=0.12, offset_y_m=-0.05, yaw_rad=0.3)


def brute_force_silhouette(mount, pose, location, size, samples=20000):
    """Bearing centre, azimuth extent and elevation range over points of the solid cylinder."""
    phi = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
    radius, height = 0.5 * size[0], size[1]
    points = []
    # Rims, faces and side: the extremes must come out of these, whichever they are.
    for z in np.linspace(location[2], location[2] + height, 21):
        for rho in (radius, 0.5 * radius):
            points.append(np.c_[location[0] + rho * np.cos(phi), location[1] + rho * np.sin(phi), np.full(samples, z)])
    points.append(np.array([location]))
    az, el, _ = mount.direction_to(pose, np.vstack(points))
    centre = np.arctan2(np.mean(np.sin(az)), np.mean(np.cos(az)))
    rel = wrap_angle(az - centre)
    lo, hi = rel.min(), rel.max()
    return wrap_angle(centre + 0.5 * (lo + hi)), hi - lo, el.min(), el.max()


CASES = {
    # name: (location, size) seen from pose (0.3, -0.2, 0.7) with the camera 0.5 m high
    "floor object below the camera": ((2.1, 1.4, 0.0), (0.5, 0.3)),
    "floor object taller than the camera": ((2.1, 1.4, 0.0), (0.2, 0.9)),
    "object on a table above the camera": ((1.2, 0.9, 0.75), (0.15, 0.25)),
    "raised object straddling the camera height": ((1.5, -0.4, 0.3), (0.3, 0.5)),
    "floating object below the camera": ((-1.0, 2.0, 0.2), (0.4, 0.1)),
    "close and wide": ((0.9, 0.3, 0.0), (0.5, 0.3)),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_extremes_match_brute_force_silhouette(name):
    location, size = CASES[name]
    pose = np.array([0.3, -0.2, 0.7])
    predicted = predict_slices(pose, location, size, MOUNT, jacobians=False).values[0]
    bearing, width, bottom, top = brute_force_silhouette(MOUNT, pose, np.array(location), np.array(size))
    assert predicted[BEARING] == pytest.approx(bearing, abs=1e-6)
    assert predicted[WIDTH] == pytest.approx(width, abs=1e-6)
    assert predicted[ELEVATION_BOTTOM] == pytest.approx(bottom, abs=1e-6)
    assert predicted[ELEVATION_TOP] == pytest.approx(top, abs=1e-6)


def test_axis_model_would_be_biased():
    """The real extremes differ from the axis' elevations by more than the measurement noise."""
    pose, location, size = np.zeros(3), np.array([1.5, 0.0, 0.0]), np.array([0.5, 0.3])
    values = predict_slices(pose, location, size, CameraMount(), jacobians=False).values[0]
    axis_top = np.arctan2(0.3 - 0.5, 1.5)
    axis_bottom = np.arctan2(-0.5, 1.5)
    assert values[ELEVATION_TOP] - axis_top > 0.01  # far rim of the top is higher
    assert axis_bottom - values[ELEVATION_BOTTOM] > 0.01  # near rim of the base is lower


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-3, 3),
    y=st.floats(-3, 3),
    theta=st.floats(-np.pi, np.pi),
    lx=st.floats(-4, 4),
    ly=st.floats(-4, 4),
    lz=st.floats(0.0, 1.2),
    diameter=st.floats(0.1, 0.6),
    height=st.floats(0.1, 1.0),
    offset_x=st.floats(-0.2, 0.2),
    yaw=st.floats(-np.pi, np.pi),
)
def test_silhouette_matches_brute_force_at_random(x, y, theta, lx, ly, lz, diameter, height, offset_x, yaw):
    mount = CameraMount(height_m=0.5, offset_x_m=offset_x, offset_y_m=0.03, yaw_rad=yaw)
    pose = np.array([x, y, theta])
    location, size = np.array([lx, ly, lz]), np.array([diameter, height])
    cam = mount.camera_pose(pose)
    assume(np.hypot(lx - cam[0], ly - cam[1]) > 0.75 * diameter)
    predicted = predict_slices(pose, location, size, mount, jacobians=False).values[0]
    expected = brute_force_silhouette(mount, pose, location, size, samples=4000)
    error = slice_error(predicted, expected)[0]
    assert np.all(np.abs(error) < 1e-5), (predicted, expected)


def _finite_difference(pose, location, size, mount, which, column, step=1e-6):
    args = [pose.copy(), location.copy(), size.copy()]
    args[which][:, column] += step
    plus = predict_slices(*args, mount, jacobians=False).values
    args[which][:, column] -= 2 * step
    minus = predict_slices(*args, mount, jacobians=False).values
    return slice_error(plus, minus) / (2 * step)


@settings(max_examples=60, deadline=None)
@given(
    pose=st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(-np.pi, np.pi)),
    location=st.tuples(st.floats(-4, 4), st.floats(-4, 4), st.floats(0.0, 1.2)),
    size=st.tuples(st.floats(0.1, 0.6), st.floats(0.1, 1.0)),
    offset=st.tuples(st.floats(-0.2, 0.2), st.floats(-0.2, 0.2)),
    yaw=st.floats(-np.pi, np.pi),
)
def test_jacobians_match_finite_differences(pose, location, size, offset, yaw):
    mount = CameraMount(height_m=0.5, offset_x_m=offset[0], offset_y_m=offset[1], yaw_rad=yaw)
    pose, location, size = np.array([pose]), np.array([location]), np.array([size])
    cam = mount.camera_pose(pose[0])
    dist = np.hypot(location[0, 0] - cam[0], location[0, 1] - cam[1])
    assume(dist > size[0, 0])  # r/D <= 1/2: away from the tangent singularity
    # Away from the kinks where the extreme rim switches sides.
    assume(abs(location[0, 2] - 0.5) > 1e-3 and abs(location[0, 2] + size[0, 1] - 0.5) > 1e-3)
    pred = predict_slices(pose, location, size, mount)
    assert pred.valid[0]
    scale = 1.0 + np.abs(pred.values)
    for which, jacobian in ((0, pred.d_pose), (1, pred.d_location), (2, pred.d_size)):
        for column in range(jacobian.shape[2]):
            numeric = _finite_difference(pose, location, size, mount, which, column)
            np.testing.assert_allclose(jacobian[:, :, column], numeric, atol=2e-6 * scale.max(), rtol=1e-5)


def test_reduced_form_is_the_full_jacobian():
    """The solver relies on pose x, y entering only as -delta and location x, y as +delta."""
    rng = np.random.default_rng(3)
    pose = np.c_[rng.uniform(-1, 1, (50, 2)), rng.uniform(-3, 3, 50)]
    location = np.c_[rng.uniform(2, 4, (50, 2)), rng.uniform(0, 1, 50)]
    size = np.c_[rng.uniform(0.1, 0.5, 50), rng.uniform(0.1, 1.0, 50)]
    full = predict_slices(pose, location, size, MOUNT)
    reduced = predict_reduced(pose, location, size, MOUNT)
    np.testing.assert_array_equal(full.values, reduced.values.T)
    np.testing.assert_array_equal(full.d_pose[:, :, :2], -full.d_location[:, :, :2])
    np.testing.assert_array_equal(reduced.jacobian[:, :2].transpose(2, 0, 1), full.d_location[:, :, :2])
    np.testing.assert_array_equal(reduced.jacobian[:, 2].T, full.d_pose[:, :, 2])
    np.testing.assert_array_equal(reduced.jacobian[:, 3].T, full.d_location[:, :, 2])
    np.testing.assert_array_equal(reduced.jacobian[:, 4:].transpose(2, 0, 1), full.d_size)


def test_camera_positions_match_the_mount():
    poses = np.array([[0.3, -0.2, 0.7], [1.0, 2.0, -2.5]])
    x, y = camera_positions(poses, MOUNT)
    for k, pose in enumerate(poses):
        np.testing.assert_allclose([x[k], y[k]], MOUNT.camera_pose(pose)[:2])


def test_camera_inside_the_object_is_flagged_invalid():
    pred = predict_slices(np.zeros((2, 3)), [[0.1, 0.0, 0.0], [2.0, 0.0, 0.0]], [0.4, 0.5], CameraMount())
    assert pred.valid.tolist() == [False, True]
    assert np.all(np.isfinite(pred.values))


def test_bearing_error_is_wrapped():
    error = slice_error([[np.pi - 0.01, 0.1, 0.0, 0.2]], [[-np.pi + 0.01, 0.1, 0.0, 0.2]])
    assert error[0, BEARING] == pytest.approx(-0.02)
