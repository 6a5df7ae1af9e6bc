"""Missed detections (objslam_mapper.detection): what is in view, and what a miss costs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objslam_mapper.camera import CameraMount
from objslam_mapper.catalog import load_catalog
from objslam_mapper.detection import (
    DetectionConfig,
    detection_log_likelihood,
    hidden,
    sight,
    view_top_elevation,
    visible,
)
from objslam_mapper.graph_config import GraphConfig
from objslam_mapper.problem import build_problem
from objslam_mapper.synthetic import SyntheticObject, ellipse_trajectory, simulate_run

CONFIG = DetectionConfig()
MOUNT = CameraMount()


class _Problem:
    """The two fields the detection term reads of a GraphProblem."""

    def __init__(self, measurement_pose=()):
        self.mount = MOUNT
        self.measurement_pose = np.asarray(measurement_pose, dtype=np.int64)


def _shown(poses, things, config=CONFIG, view_top=0.4):
    seen = sight(_Problem(), np.asarray(poses, dtype=float), np.asarray(things, dtype=float), config, view_top)
    return visible(seen, seen, config)


ROBOT = [[0.0, 0.0, 0.0]]


def test_a_nearer_object_hides_one_behind_it():
    near = [2.0, 0.0, 0.0, 0.4, 0.4]
    far_behind = [4.0, 0.05, 0.0, 0.3, 0.6]
    far_aside = [4.0, 2.0, 0.0, 0.3, 0.6]
    shown = _shown(ROBOT, [near, far_behind, far_aside])
    assert shown.tolist() == [[True, False, True]]
    # Half hidden is still seen (cover must exceed one half).
    assert _shown(ROBOT, [near, [4.0, 0.45, 0.0, 0.3, 0.6]]).tolist() == [[True, True]]  # a third hidden


def test_too_narrow_too_far_or_above_the_view_is_not_in_view():
    narrow = [6.0, 0.0, 0.0, 0.15, 0.25]  # 0.025 rad wide, below the 0.035 rad gate
    far = [11.0, 3.0, 0.0, 0.5, 0.3]  # wide enough but beyond 10 m
    high = [0.5, 0.0, 0.75, 0.15, 0.25]  # on a table, close: its lower edge above the view
    ok = [2.0, -1.0, 0.0, 0.3, 0.6]
    assert _shown(ROBOT, [narrow, far, high, ok]).tolist() == [[False, False, False, True]]


def test_each_image_in_view_without_a_slice_costs_log_one_minus_pd():
    poses = np.column_stack([np.linspace(0.0, 2.0, 10), np.zeros(10), np.zeros(10)])
    thing = np.array([[2.0, 2.0, 0.0, 0.4, 0.4]])
    # Slices of the object in 3 of the 10 images (measurement -> pose 0, 4, 9).
    problem = _Problem(measurement_pose=[0, 4, 9])
    value = detection_log_likelihood(problem, poses, thing, [np.array([0, 1, 2])], CONFIG, 0.4)
    assert value == pytest.approx(7 * math.log1p(-CONFIG.probability))
    assert (
        detection_log_likelihood(problem, poses, thing, [np.array([0, 1, 2])], DetectionConfig(enabled=False), 0.4) == 0
    )


def test_the_view_top_is_read_off_the_slices_upper_edges():
    poses = ellipse_trajectory(40, (3.0, 1.8))
    scene = (
        SyntheticObject("red", (2.2, 0.3, 0.0), (0.31, 0.58)),
        SyntheticObject("cyan", (0.4, -0.9, 0.75), (0.15, 0.26)),
    )
    run = simulate_run(poses, [k * 250_000_000 for k in range(40)], scene, load_catalog(), np.random.default_rng(0))
    problem = build_problem(run.odometry, run.images, MOUNT, load_catalog(), GraphConfig())
    top = view_top_elevation(problem, CONFIG)
    assert top == pytest.approx(np.quantile(problem.measurements[:, 3], 0.995))
    assert top > 0.0  # the cyan object's top is above the camera


def test_a_thing_is_hidden_by_any_nearer_one_that_covers_it():
    near = [2.0, 0.0, 0.0, 0.4, 0.4]
    nearer = [1.0, 0.02, 0.0, 0.3, 0.6]
    far = [5.0, 0.0, 0.0, 0.4, 0.4]
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, np.pi / 2]])
    seen = sight(_Problem(), poses, np.array([near, nearer, far]), CONFIG, 0.4)
    # The far one is behind both, the near one behind the nearer (the heading does not matter).
    assert hidden(seen, seen, CONFIG).tolist() == [[True, False, True]] * 2
    assert hidden(seen, seen.columns([2]), CONFIG).tolist() == [[False, False, False]] * 2  # nothing behind
    assert visible(seen, seen, CONFIG).tolist() == [[False, True, False]] * 2
