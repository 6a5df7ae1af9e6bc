"""Keyframes: which images get a graph pose, and the graph they make, against numbers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from objslam_common.catalog import load_catalog
from objslam_common.geometry import compose
from objslam_common.mount import CameraMount, CameraMounts
from objslam_mapper.config import GraphConfig, KeyframeConfig, SolverConfig
from objslam_mapper.graph.keyframes import keyframes_of, offset_slice_variance, select_keyframes
from objslam_mapper.graph.problem import build_problem, gaussian_log_normalizer
from objslam_mapper.graph.solver import solve
from objslam_mapper.model.odometry import increment_stddev
from objslam_mapper.model.slice_model import predict_reduced
from objslam_mapper.synthetic import ellipse_trajectory, office_scene, simulate_run

CATALOG = load_catalog()
KEYFRAMES = KeyframeConfig(min_travel_m=0.05, min_turn_rad=0.05)
MOUNT = CameraMount(height_m=0.5, offset_x_m=0.12, offset_y_m=-0.05, yaw_rad=0.3)


def test_an_image_is_a_keyframe_once_the_robot_has_moved_enough():
    travel = [0.02, 0.02, 0.02, 0.0, 0.0, 0.06, 0.01]
    turn = [0.0, 0.0, 0.0, 0.03, 0.03, 0.0, 0.0]
    # pose 3: 6 cm since pose 0; pose 5: 0.06 rad since pose 3; pose 6: 6 cm in one step.
    np.testing.assert_array_equal(select_keyframes(travel, turn, KEYFRAMES), [0, 3, 5, 6])
    off = dataclasses.replace(KEYFRAMES, enabled=False)
    np.testing.assert_array_equal(select_keyframes(travel, turn, off), np.arange(8))


@settings(max_examples=50, deadline=None)
@given(
    st.lists(st.tuples(st.floats(0.0, 0.1), st.floats(-0.1, 0.1)), min_size=1, max_size=60),
    st.floats(0.01, 0.2),
    st.floats(0.01, 0.2),
)
def test_keyframes_are_where_the_motion_since_the_last_reaches_a_threshold(steps, min_travel, min_turn):
    travel, turn = np.array(steps).T
    config = KeyframeConfig(min_travel_m=min_travel, min_turn_rad=min_turn)
    keyframes = select_keyframes(travel, turn, config)
    assert keyframes[0] == 0 and np.all(np.diff(keyframes) > 0)
    path, swept = np.r_[0.0, np.cumsum(travel)], np.r_[0.0, np.cumsum(np.abs(turn))]
    last = 0
    for pose in range(1, len(steps) + 1):
        reached = path[pose] - path[last] >= min_travel - 1e-12 or swept[pose] - swept[last] >= min_turn - 1e-12
        far = path[pose] - path[last] >= min_travel + 1e-12 or swept[pose] - swept[last] >= min_turn + 1e-12
        if pose in keyframes:
            assert reached
            last = pose
        else:
            assert not far


@settings(max_examples=60, deadline=None)
@given(
    pose=st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(-np.pi, np.pi)),
    offset=st.tuples(st.floats(-0.1, 0.1), st.floats(-0.1, 0.1), st.floats(-0.2, 0.2)),
    location=st.tuples(st.floats(-4, 4), st.floats(-4, 4), st.floats(0.0, 1.2)),
    size=st.tuples(st.floats(0.1, 0.6), st.floats(0.1, 1.0)),
)
def test_a_slice_predicted_from_its_keyframe_is_the_slice_from_its_image(pose, offset, location, size):
    """Through CameraMounts.behind: the same values, and the graph pose's Jacobian by finite differences."""
    keyframe, image = np.array([pose]), compose(pose, offset)[None, :]
    mounts = CameraMounts.behind(MOUNT, np.array([offset]))
    direct = predict_reduced(image, location, size, MOUNT)
    assume(direct.valid[0] and direct.range_m[0] > size[0])
    through = predict_reduced(keyframe, location, size, mounts)
    np.testing.assert_allclose(through.values, direct.values, atol=1e-12)
    # Column 2 of the reduced Jacobian is d/d theta of the graph pose (the offset's lever included).
    step = 1e-6
    turn = np.array([0.0, 0.0, step])
    moved = keyframe + turn
    back = keyframe - turn
    numeric = (
        predict_reduced(moved, location, size, mounts).values - predict_reduced(back, location, size, mounts).values
    ) / (2 * step)
    np.testing.assert_allclose(through.jacobian[:, 2, 0], numeric[:, 0], atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(
    bearing=st.floats(-np.pi, np.pi),
    range_m=st.floats(0.8, 6.0),
    z_base=st.floats(0.0, 1.2),
    size=st.tuples(st.floats(0.1, 0.6), st.floats(0.1, 1.0)),
)
def test_offset_noise_reaches_the_slice_as_the_model_linearized(bearing, range_m, z_base, size):
    """Exact range and radius: the added variance is J Sigma J^T of the slice model's own Jacobian."""
    location = np.array([[range_m * np.cos(bearing), range_m * np.sin(bearing), z_base]])
    mount = CameraMount(height_m=0.5)
    assume(abs(z_base - 0.5) > 1e-3 and abs(z_base + size[1] - 0.5) > 1e-3)  # away from the rim switch
    pred = predict_reduced(np.zeros((1, 3)), location, size, mount)
    xy_var, theta_var = 1e-4, 4e-5
    added = offset_slice_variance(
        pred.values.T, np.array([range_m]), np.array([0.5 * size[0]]), np.array([xy_var]), np.array([theta_var])
    )
    jac = pred.jacobian[:, :, 0]  # (4, 6): delta_x, delta_y, theta, ...
    expected = (jac[:, 0] ** 2 + jac[:, 1] ** 2) * xy_var + jac[:, 2] ** 2 * theta_var
    np.testing.assert_allclose(added[0], expected, rtol=1e-9, atol=1e-15)


def dense_run(n_poses=900, seed=3, keyframes=KEYFRAMES):
    """1.5 laps of the office ellipse at about 2.6 cm per image: two to three images per keyframe."""
    config = dataclasses.replace(GraphConfig(), solver=SolverConfig(keyframes=keyframes))
    poses = ellipse_trajectory(n_poses, (3.0, 2.0), laps=1.5)
    stamps = [k * 50_000_000 for k in range(n_poses)]
    run = simulate_run(poses, stamps, office_scene(), CATALOG, np.random.default_rng(seed), config=config)
    problem = build_problem(run.odometry, run.images, config.camera_mount.to_mount(), CATALOG, config)
    return run, problem


@pytest.fixture(scope="module")
def dense():
    return dense_run()


def test_the_graph_of_a_dense_run_has_a_pose_per_keyframe(dense):
    _run, problem = dense
    kf = keyframes_of(problem)
    graph = kf.problem
    assert kf.reduces and graph.pose_count == len(kf.keyframe_pose) < problem.pose_count / 2
    np.testing.assert_array_equal(graph.stamps_ns, problem.stamps_ns[kf.keyframe_pose])
    # Image poses are their keyframe's with the odometry between: exact on the odometry itself.
    np.testing.assert_allclose(kf.expand(kf.restrict(problem.odometry_poses)), problem.odometry_poses, atol=1e-12)
    # The random walk between keyframes: the noise model's for its path and turn (one floor,
    # not one per image: less than the increments' variances summed), and the trajectory's
    # normalizer that of these factors.
    cut = kf.keyframe_pose
    path = problem.increment_path_length_m[cut[0] : cut[1]].sum()
    turn = np.abs(problem.increments[cut[0] : cut[1], 2]).sum()
    np.testing.assert_allclose(graph.increment_stddev[0], increment_stddev(path, turn, problem.odometry_noise))
    summed = np.sum(problem.increment_stddev[cut[0] : cut[1]] ** 2, axis=0)
    assert np.all(graph.increment_stddev[0] ** 2 < summed)
    np.testing.assert_allclose(graph.increment_path_length_m.sum(), problem.increment_path_length_m[: cut[-1]].sum())
    expected = np.sum(gaussian_log_normalizer(graph.increment_stddev)) + gaussian_log_normalizer(
        graph.first_pose_stddev
    )
    expected += gaussian_log_normalizer(graph.calibration_prior_stddev)
    assert graph.trajectory_log_normalizer == pytest.approx(float(expected))
    # Slices of keyframe images keep their noise, the others' grows, and their caps and normalizers follow.
    own = np.isin(problem.measurement_pose, cut)
    np.testing.assert_array_equal(graph.measurement_stddev[own], problem.measurement_stddev[own])
    assert np.all(graph.measurement_stddev[~own] > problem.measurement_stddev[~own])
    change = gaussian_log_normalizer(graph.measurement_stddev) - gaussian_log_normalizer(problem.measurement_stddev)
    np.testing.assert_allclose(graph.measurement_outlier_cost - problem.measurement_outlier_cost, change)
    np.testing.assert_array_equal(graph.measurement_pose, kf.pose_keyframe[problem.measurement_pose])


def test_without_keyframes_or_a_worthwhile_reduction_the_graph_is_the_image_problem(dense):
    _run, problem = dense
    removed = 1.0 - keyframes_of(problem).problem.pose_count / problem.pose_count
    for keyframes in (KeyframeConfig(enabled=False), KeyframeConfig(min_reduction=removed + 0.01)):
        other = dataclasses.replace(problem, solver=SolverConfig(keyframes=keyframes))
        assert keyframes_of(other).problem is other and not keyframes_of(other).reduces
        np.testing.assert_array_equal(keyframes_of(other).pose_keyframe, np.arange(problem.pose_count))
    just = dataclasses.replace(problem, solver=SolverConfig(keyframes=KeyframeConfig(min_reduction=removed - 0.01)))
    assert keyframes_of(just).reduces


@pytest.mark.parametrize("seed", [3, 4])
def test_a_dense_run_maps_as_well_with_keyframes_as_with_a_pose_per_image(seed):
    """Same accuracy and consistency (NEES) of the objects; without the shared-error scaling
    seed 4 doubled its median error and had 4.7 times the NEES (6.5 against 1.4)."""
    run, problem = dense_run(seed=seed)
    groups = run.groups(problem)
    off = dataclasses.replace(problem, solver=SolverConfig(keyframes=KeyframeConfig(enabled=False)))
    with_keyframes = solve(problem, groups, with_covariances=True)
    per_image = solve(off, groups, with_covariances=True)
    assert with_keyframes.converged and per_image.converged
    assert with_keyframes.map_T_base.shape == per_image.map_T_base.shape == (problem.pose_count, 3)
    truth = np.array([o.location_m for o in run.objects])[:, :2]

    def scores(solution):
        found = np.array([o.location_m for o in solution.objects])[:, :2]
        nees = [
            e @ np.linalg.solve(o.location_cov[:2, :2], e) for e, o in zip(found - truth, solution.objects, strict=True)
        ]
        ate = np.sqrt(np.mean(np.sum((solution.map_T_base - run.true_map_T_base)[:, :2] ** 2, axis=1)))
        return np.median(np.hypot(*(found - truth).T)), np.mean(nees), ate

    (error, nees, ate), (error_ref, nees_ref, ate_ref) = scores(with_keyframes), scores(per_image)
    assert error <= 1.2 * error_ref + 0.002
    assert nees <= 1.5 * nees_ref + 0.5
    assert ate <= 1.2 * ate_ref + 0.002
    # A warm start from the solution is at the optimum already.
    again = solve(problem, groups, warm_start=with_keyframes)
    assert again.iterations <= 2
    assert again.log_evidence == pytest.approx(with_keyframes.log_evidence, abs=1e-3)
