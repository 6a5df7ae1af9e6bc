"""Poses at image stamps from odometry, odometry increments and their noise model."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from objslam_common.geometry import compose, interpolate_pose, wrap_angle
from objslam_common.records import OdometrySample
from objslam_mapper.config import OdometryNoiseConfig
from objslam_mapper.model.odometry import TrajectoryError, increment_stddev, odometry_increments, poses_at_stamps

SECOND = 1_000_000_000


def _odometry(poses, t0=5 * SECOND, dt=SECOND // 10):
    return [OdometrySample(t0 + k * dt, *map(float, p)) for k, p in enumerate(poses)]


def test_interpolates_between_the_surrounding_samples():
    odom = _odometry([(0.0, 0.0, 3.0), (1.0, 0.5, -3.0), (2.0, 0.0, -2.5)])
    stamps = [odom[0].stamp_ns, odom[0].stamp_ns + SECOND // 40, odom[1].stamp_ns + SECOND // 20, odom[2].stamp_ns]
    at = poses_at_stamps(odom, stamps)
    assert at.accepted.all()
    np.testing.assert_allclose(at.poses[0], [0.0, 0.0, 3.0])
    np.testing.assert_allclose(at.poses[1], interpolate_pose([0, 0, 3.0], [1.0, 0.5, -3.0], 0.25))
    np.testing.assert_allclose(at.poses[2], interpolate_pose([1.0, 0.5, -3.0], [2.0, 0.0, -2.5], 0.5))
    np.testing.assert_allclose(at.poses[3], [2.0, 0.0, -2.5])
    # Heading interpolates across the +-pi seam, not through zero.
    assert abs(at.poses[1, 2]) > 3.0


def test_stamps_outside_the_odometry_span_are_rejected_and_counted(caplog):
    odom = _odometry([(0.0, 0.0, 0.0), (1.0, 0.0, 0.0)])
    stamps = [odom[0].stamp_ns - 1, odom[0].stamp_ns, odom[1].stamp_ns, odom[1].stamp_ns + 1, 0]
    with caplog.at_level(logging.WARNING, logger="objslam_mapper.model.odometry"):
        at = poses_at_stamps(odom, stamps)
    assert at.accepted.tolist() == [False, True, True, False, False]
    assert at.rejected_count == 3
    assert len(at.poses) == 2
    assert "3 of 5 image stamps" in caplog.text


def test_unsorted_odometry_and_repeated_stamps():
    odom = _odometry([(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (2.0, 0.0, 0.0)])
    shuffled = [odom[2], odom[0], odom[1], OdometrySample(odom[1].stamp_ns, 1.0, 0.0, 0.0)]
    at = poses_at_stamps(shuffled, [odom[0].stamp_ns + SECOND // 20])
    np.testing.assert_allclose(at.poses[0], [0.5, 0.0, 0.0])


def test_no_odometry_is_an_error():
    with pytest.raises(TrajectoryError):
        poses_at_stamps([], [1])


def test_path_length_follows_the_curve_not_the_chord():
    theta = np.linspace(0, np.pi, 50)
    odom = _odometry(np.c_[np.cos(theta), np.sin(theta), theta + np.pi / 2])
    at = poses_at_stamps(odom, [odom[0].stamp_ns, odom[-1].stamp_ns])
    assert at.path_length_m[-1] - at.path_length_m[0] == pytest.approx(np.pi, rel=1e-3)
    assert at.turn_rad[-1] - at.turn_rad[0] == pytest.approx(np.pi, rel=1e-9)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-np.pi, np.pi)), min_size=2, max_size=8))
def test_increments_chain_back_to_the_poses(poses):
    poses = np.array(poses)
    increments = odometry_increments(poses)
    for k, inc in enumerate(increments):
        chained = compose(poses[k], inc)
        np.testing.assert_allclose(chained[:2], poses[k + 1, :2], atol=1e-9)
        assert wrap_angle(chained[2] - poses[k + 1, 2]) == pytest.approx(0.0, abs=1e-9)


def test_noise_is_a_random_walk_in_distance_and_turn():
    noise = OdometryNoiseConfig(min_xy_stddev_m=1e-9, min_theta_stddev_rad=1e-9)
    whole = increment_stddev(np.array([2.0]), np.array([1.0]), noise) ** 2
    halves = increment_stddev(np.array([1.0, 1.0]), np.array([0.5, 0.5]), noise) ** 2
    # Splitting a motion into more images must not change the total uncertainty.
    np.testing.assert_allclose(halves.sum(axis=0), whole[0], rtol=1e-9)
    longer = increment_stddev(np.array([1.0, 2.0]), np.array([0.0, 0.0]), noise)
    turned = increment_stddev(np.array([1.0, 1.0]), np.array([0.0, 1.0]), noise)
    assert np.all(longer[1] > longer[0])
    assert np.all(turned[1] > turned[0])
    standing = increment_stddev(np.array([0.0]), np.array([0.0]), OdometryNoiseConfig())
    np.testing.assert_allclose(standing[0], [0.002, 0.002, 0.002])
