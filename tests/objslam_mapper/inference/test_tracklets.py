"""Chaining slices into tracklets, on slices drawn from the graph's slice model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from objslam_common.catalog import load_catalog
from objslam_common.records import ImageSlices, SliceMeasurement
from objslam_mapper.config import GraphConfig, TrackletConfig
from objslam_mapper.graph.problem import build_problem
from objslam_mapper.inference.tracklets import (
    ClassShape,
    chain_tracklets,
    class_shapes,
    estimate_range,
    tracklets_of_problem,
)
from objslam_mapper.model.slice_model import predict_slices
from objslam_mapper.synthetic import SyntheticObject, simulate_run

CATALOG = load_catalog()
CONFIG = GraphConfig()
MOUNT = CONFIG.camera_mount.to_mount()
RED = SyntheticObject("red", (2.0, 0.8, 0.0), (0.30, 0.60))
STAMPS = [k * 200_000_000 for k in range(20)]


def straight_poses(n=20, step_m=0.15):
    return np.column_stack([np.arange(n) * step_m, np.zeros(n), np.zeros(n)])


def problem_of(odometry, images):
    return build_problem(odometry, images, MOUNT, CATALOG, CONFIG)


def run_of(objects, poses=None, seed=0):
    poses = straight_poses() if poses is None else poses
    return simulate_run(poses, STAMPS[: len(poses)], objects, CATALOG, np.random.default_rng(seed))


def test_a_continuous_track_is_one_tracklet():
    run = run_of([RED])
    problem = problem_of(run.odometry, run.images)
    result = tracklets_of_problem(problem)
    assert len(result.tracklets) == 1 and result.dropped_tracklets == 0
    (tracklet,) = result.tracklets
    assert tracklet.label == "red"
    assert tracklet.measurement_indices == tuple(range(20))
    assert tracklet.frame_indices == tuple(range(20))
    assert np.hypot(*(np.subtract(tracklet.position_xy_m, RED.location_m[:2]))) < 0.3


def test_odometry_carries_the_track_through_a_fast_turn():
    # Turning on the spot at 0.3 rad per image: the bearing jumps six gates per image.
    poses = np.column_stack([np.zeros(20), np.zeros(20), np.arange(20) * 0.3])
    run = run_of([RED], poses)
    problem = problem_of(run.odometry, run.images)
    assert len(tracklets_of_problem(problem).tracklets) == 1
    still = chain_tracklets(
        problem.measurements,
        problem.measurement_pose,
        ["red"] * problem.measurement_count,
        np.zeros_like(problem.odometry_poses),  # as if the robot had not moved
        class_shapes(problem),
        MOUNT,
        measurement_stddev=problem.measurement_stddev,
    )
    assert still.dropped_tracklets == 20 and not still.tracklets


def test_isolated_detections_are_dropped_and_counted():
    run = run_of([RED])
    images = list(run.images)
    lone = SliceMeasurement("green", 1.0, -2.0, 0.15, -0.2, 0.05)
    images[7] = ImageSlices(images[7].stamp_ns, (*images[7].slices, lone))
    problem = problem_of(run.odometry, images)
    lone_index = int(np.flatnonzero(problem.measurement_label == problem.labels.index("green"))[0])
    result = tracklets_of_problem(problem)
    assert [t.label for t in result.tracklets] == ["red"]
    assert result.dropped_tracklets == 1 and result.dropped_measurements == (lone_index,)
    kept_all = tracklets_of_problem(problem, TrackletConfig(min_length=1))
    assert kept_all.dropped_tracklets == 0 and len(kept_all.tracklets) == 2


def test_slices_of_different_classes_are_never_chained():
    # Identical measurements in every image, but two classes.
    run = run_of([RED])
    images = [
        ImageSlices(im.stamp_ns, (*im.slices, *(dataclasses.replace(s, label="blue") for s in im.slices)))
        for im in run.images
    ]
    problem = problem_of(run.odometry, images)
    result = tracklets_of_problem(problem)
    assert sorted(t.label for t in result.tracklets) == ["blue", "red"]
    for t in result.tracklets:
        assert {problem.label_of(m) for m in t.measurement_indices} == {t.label}
        assert len(t) == 20


def test_a_jump_to_another_object_starts_a_new_tracklet():
    other = SyntheticObject("red", (1.0, -1.5, 0.0), (0.30, 0.60))
    first, second = run_of([RED]), run_of([other])
    images = [*first.images[:10], *second.images[10:]]
    problem = problem_of(first.odometry, images)
    result = tracklets_of_problem(problem)
    assert [t.frame_indices for t in result.tracklets] == [tuple(range(10)), tuple(range(10, 20))]


def test_a_gap_is_bridged_only_when_allowed():
    run = run_of([RED])
    images = list(run.images)
    images[9] = ImageSlices(images[9].stamp_ns, ())  # a missed detection
    problem = problem_of(run.odometry, images)
    assert len(tracklets_of_problem(problem).tracklets) == 2
    bridged = tracklets_of_problem(problem, TrackletConfig(max_frame_gap=2))
    assert len(bridged.tracklets) == 1 and len(bridged.tracklets[0]) == 19


def dense_run(images_per_step: int, step_m: float = 0.15, steps: int = 19):
    """The straight path of ``run_of`` seen in ``images_per_step`` times as many images."""
    n = steps * images_per_step + 1
    poses = np.column_stack([np.arange(n) * step_m / images_per_step, np.zeros(n), np.zeros(n)])
    return exact_odometry_run(poses)


def exact_odometry_run(poses):
    stamps = [k * 200_000_000 for k in range(len(poses))]
    return simulate_run(poses, stamps, [RED], CATALOG, np.random.default_rng(0), odometry_noise_scale=0.0)


def without_images(run, frames):
    return [ImageSlices(im.stamp_ns, ()) if k in frames else im for k, im in enumerate(run.images)]


@pytest.mark.parametrize("images_per_step", [1, 2, 4])
def test_more_images_along_the_same_path_give_the_same_tracklets(images_per_step):
    # Detections lost over the same stretches of path: seen at 1.2 m and again at 1.5 m (a
    # short loss, bridged at every frame rate), at 1.8 m and again at 2.25 m (bridged at none).
    run = dense_run(images_per_step)
    x_m = run.true_map_T_base[:, 0]
    lost = {k for k, x in enumerate(x_m) if 1.21 < x < 1.49 or 1.81 < x < 2.24}
    problem = problem_of(run.odometry, without_images(run, lost))
    result = tracklets_of_problem(problem, TrackletConfig(max_gap_travel_m=0.35))
    spans = [(x_m[t.frame_indices[0]], x_m[t.frame_indices[-1]]) for t in result.tracklets]
    assert np.allclose(spans, [(0.0, 1.8), (2.25, 2.85)], atol=1e-9)


def test_a_gap_is_bounded_by_how_far_the_robot_moved_and_turned():
    # Turning on the spot at 0.01 rad per image: no travel, so the turn bounds the gap.
    poses = np.column_stack([np.zeros(20), np.zeros(20), np.arange(20) * 0.01])
    run = exact_odometry_run(poses)
    images = without_images(run, {8, 9, 10})  # 0.04 rad between the slices either side
    problem = problem_of(run.odometry, images)
    assert len(tracklets_of_problem(problem, TrackletConfig(max_gap_turn_rad=0.05)).tracklets) == 1
    assert len(tracklets_of_problem(problem, TrackletConfig(max_gap_turn_rad=0.03)).tracklets) == 2


@pytest.mark.parametrize("label", ["red", "blue", "yellow", "cyan"])
@pytest.mark.parametrize("range_m", [0.8, 1.5, 3.0, 5.0])
def test_range_from_apparent_size_inverts_the_slice_model(label, range_m):
    cls = CATALOG[label]
    shape = ClassShape(cls.z_base_m, cls.diameter_m, cls.height_m)
    location = np.array([[range_m, 0.0, cls.z_base_m]])
    prediction = predict_slices(np.zeros((1, 3)), location, np.array([[cls.diameter_m, cls.height_m]]), MOUNT)
    estimate = estimate_range(prediction.values, shape, MOUNT.height_m)
    assert estimate[0] == pytest.approx(range_m, rel=1e-6)
