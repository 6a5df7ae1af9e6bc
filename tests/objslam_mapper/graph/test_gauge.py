"""The trajectory gauge: the rigid motion fitted to pose errors, and covariances about it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from objslam_mapper.graph.gauge import about_trajectory, object_motion, trajectory_gauge
from objslam_tools.trajectory import fit_se2

_coordinate = st.floats(-5.0, 5.0)


def _rigid_errors(xy, centroid, t, phi):
    """Pose (or object) errors of a small rigid motion about ``centroid`` (first order)."""
    lever = xy - centroid
    return t + phi * np.c_[-lever[:, 1], lever[:, 0]]


@settings(max_examples=50, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    t=st.tuples(_coordinate, _coordinate),
    phi=st.floats(-1.0, 1.0),
)
def test_a_rigid_motion_of_the_trajectory_is_recovered_and_leaves_no_object_error(seed, t, phi):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-4, 4, (12, 2))
    weights = rng.uniform(0.5, 3.0, 12)
    gauge = trajectory_gauge(xy, weights)
    pose_errors = np.zeros((12, 3))
    pose_errors[:, :2] = _rigid_errors(xy, gauge.centroid_xy, np.array(t), phi)
    pose_errors[:, 2] = rng.normal(size=12)  # headings are not part of the fit
    np.testing.assert_allclose(gauge.rows @ pose_errors.ravel(), [*t, phi], atol=1e-9)
    objects = rng.uniform(-6, 6, (3, 2))
    motion = object_motion(objects, gauge.centroid_xy, 5)
    moved = np.einsum("kdg,g->kd", motion, [*t, phi])
    np.testing.assert_allclose(moved[:, :2], _rigid_errors(objects, gauge.centroid_xy, np.array(t), phi))
    np.testing.assert_allclose(moved[:, 2:], 0.0)


def test_the_gauge_is_the_linearized_least_squares_fit_of_objslam_eval():
    rng = np.random.default_rng(4)
    truth = rng.uniform(-3, 3, (30, 2))
    estimate = truth + 1e-4 * rng.normal(size=truth.shape)
    gauge = trajectory_gauge(truth)
    pose_errors = np.c_[estimate - truth, np.zeros(30)].ravel()
    tx, ty, phi = gauge.rows @ pose_errors
    gt_T_est = fit_se2(estimate, truth)  # undoes the fitted motion, about the origin
    assert gt_T_est[2] == pytest.approx(-phi, abs=1e-7)
    c = gauge.centroid_xy
    undone = np.array([tx, ty]) + phi * np.array([c[1], -c[0]])  # the same motion about the origin
    np.testing.assert_allclose(gt_T_est[:2], -undone, atol=1e-7)


def test_covariance_about_the_trajectory_is_that_of_the_error_less_the_fitted_motion():
    rng = np.random.default_rng(7)
    n_poses, n_objects = 6, 2
    dim = 3 * n_poses + 5 * n_objects
    root = rng.normal(size=(dim, dim))
    cov = root @ root.T + dim * np.eye(dim)
    xy = rng.uniform(-2, 2, (n_poses, 2))
    objects = rng.uniform(-3, 3, (n_objects, 2))
    gauge = trajectory_gauge(xy)
    rows = np.zeros((3, dim))
    rows[:, : 3 * n_poses] = gauge.rows
    motion = object_motion(objects, gauge.centroid_xy, 5)
    split = 3 * n_poses
    marginals = np.array([cov[split + 5 * k : split + 5 * k + 5, split + 5 * k : split + 5 * k + 5] for k in range(2)])
    cross = np.array([(cov @ rows.T)[split + 5 * k : split + 5 * k + 5] for k in range(2)])
    aligned = about_trajectory(marginals, cross, rows @ cov @ rows.T, objects, gauge.centroid_xy)
    for k in range(n_objects):
        functional = -motion[k] @ rows
        functional[:, split + 5 * k : split + 5 * k + 5] += np.eye(5)
        np.testing.assert_allclose(aligned[k], functional @ cov @ functional.T, rtol=1e-10)


def test_a_robot_that_never_moved_fits_no_rotation():
    gauge = trajectory_gauge(np.zeros((4, 2)))
    assert np.all(gauge.rows[2] == 0.0)
    np.testing.assert_allclose(gauge.rows[0, 0::3], 0.25)
