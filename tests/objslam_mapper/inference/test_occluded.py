"""Slice edges on a nearer thing's silhouette become bounds (objslam_mapper.inference.occluded)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objslam_common.mount import CameraMount
from objslam_common.records import CUT_LEFT, CUT_RIGHT
from objslam_mapper.config import DetectionConfig
from objslam_mapper.inference.occluded import occluded_edges
from objslam_mapper.model.slice_model import (
    BEARING,
    ELEVATION_TOP,
    LOWER_BOUND,
    MEASURED,
    UNMEASURED,
    UPPER_BOUND,
    WIDTH,
    bounds_of_cuts,
    predict_reduced,
    with_side_cuts,
)

CONFIG = DetectionConfig(occluded_edge_margin_rad=0.02)
MOUNT = CameraMount()
GREEN, CYAN = 0, 1
# Class rows: (x, y, z_base, diameter, height); only the diameter is read (range from width).
PRIOR = np.array([[0.0, 0.0, 0.0, 0.4, 0.4], [0.0, 0.0, 0.75, 0.15, 0.25]])
ROBOT = np.zeros((1, 3))
GREEN_BEHIND = [4.0, -0.2, 0.0, 0.4, 0.4]  # its left third behind the table below
CYAN_ON_TABLE = [2.0, 0.15, 0.75, 0.15, 0.25]


class _Problem:
    """The fields the edge test reads of a GraphProblem: one image, its slices."""

    def __init__(self, slices, labels):
        self.mount = MOUNT
        self.measurements = np.asarray(slices, dtype=float).reshape(-1, 4)
        self.measurement_label = np.asarray(labels, dtype=np.int64)
        self.measurement_pose = np.zeros(len(labels), dtype=np.int64)
        self.prior_mean = PRIOR

    @property
    def measurement_count(self):
        return len(self.measurement_label)


def _slice_of(thing, bearing_lo=-math.inf, bearing_hi=math.inf):
    """The slice of a cylinder from the robot, its bearing interval clipped to [lo, hi]."""
    t = np.asarray(thing, dtype=float)
    v = predict_reduced(ROBOT, t[None, :3], t[None, 3:], MOUNT, jacobians=False).values[:, 0]
    left = min(v[BEARING] + 0.5 * v[WIDTH], bearing_hi)
    right = max(v[BEARING] - 0.5 * v[WIDTH], bearing_lo)
    return [0.5 * (left + right), left - right, v[2], v[3]]


def _table_right_edge():
    """Bearing of the right (clockwise) edge of the table under the cyan object."""
    x, y = CYAN_ON_TABLE[:2]
    return math.atan2(y, x) - math.asin(0.5 * CONFIG.table_diameter_m / math.hypot(x, y))


def _cuts(slices, labels, things, thing_labels, on_table):
    return occluded_edges(
        _Problem(slices, labels),
        ROBOT,
        np.asarray(things, dtype=float),
        np.asarray(thing_labels),
        np.asarray(on_table),
        CONFIG,
    )


def test_an_object_half_behind_a_table_has_that_edge_cut():
    # The green object's left half is behind the table: its blob ends at the table's edge.
    half_hidden = _slice_of(GREEN_BEHIND, bearing_hi=_table_right_edge())
    cuts = _cuts([half_hidden], [GREEN], [CYAN_ON_TABLE], [CYAN], [True])
    assert cuts.tolist() == [CUT_LEFT]
    # Without the table (nothing under the cyan object) nothing is cut: the cyan object
    # itself is higher than the green one, their silhouettes do not meet.
    assert _cuts([half_hidden], [GREEN], [CYAN_ON_TABLE], [CYAN], [False]).tolist() == [0]


def test_a_clear_object_and_the_object_on_the_table_are_not_cut():
    clear = _slice_of([4.0, -1.5, 0.0, 0.4, 0.4])
    on_its_table = _slice_of(CYAN_ON_TABLE)
    cuts = _cuts([clear, on_its_table], [GREEN, CYAN], [CYAN_ON_TABLE], [CYAN], [True])
    # The table under an object shares its footprint: it is the object's own, not an occluder.
    assert cuts.tolist() == [0, 0]


def test_only_nearer_things_of_another_class_cut():
    # A green object in front of the green one: the detector would see one blob, no edge.
    near_green = [2.0, 0.1, 0.0, 0.4, 0.4]
    edge = math.atan2(0.1, 2.0) - math.asin(0.2 / math.hypot(2.0, 0.1))
    half_hidden = _slice_of(GREEN_BEHIND, bearing_hi=edge)
    assert _cuts([half_hidden], [GREEN], [near_green], [GREEN], [False]).tolist() == [0]
    # The same place taken by a (floor-standing) thing of another class cuts its left edge ...
    assert _cuts([half_hidden], [GREEN], [near_green], [CYAN], [False]).tolist() == [CUT_LEFT]
    # ... and one behind the slice's object cuts nothing.
    behind = [8.0, 0.5, 0.0, 0.4, 0.4]
    assert _cuts([_slice_of(GREEN_BEHIND)], [GREEN], [behind], [CYAN], [False]).tolist() == [0]


def test_a_right_edge_is_cut_the_same_way():
    mirrored = [2.0, -0.15, 0.75, 0.15, 0.25]
    x, y = mirrored[:2]
    edge = math.atan2(y, x) + math.asin(0.5 * CONFIG.table_diameter_m / math.hypot(x, y))
    half_hidden = _slice_of([4.0, 0.2, 0.0, 0.4, 0.4], bearing_lo=edge)
    assert _cuts([half_hidden], [GREEN], [mirrored], [CYAN], [True]).tolist() == [CUT_RIGHT]


def test_side_cuts_add_to_the_view_cuts():
    view = bounds_of_cuts(np.array([0, CUT_LEFT, 0, CUT_RIGHT]), np.array([False, False, True, False]))
    merged = with_side_cuts(view, np.array([0, CUT_RIGHT, CUT_LEFT, CUT_RIGHT]))
    assert merged[:, BEARING].tolist() == [MEASURED, UNMEASURED, LOWER_BOUND, UPPER_BOUND]
    assert merged[:, WIDTH].tolist() == [MEASURED, LOWER_BOUND, LOWER_BOUND, LOWER_BOUND]
    assert merged[:, ELEVATION_TOP].tolist() == view[:, ELEVATION_TOP].tolist()  # the top's bound kept
    assert np.array_equal(with_side_cuts(view, np.zeros(4, dtype=np.int64)), view)


@pytest.mark.parametrize("cut", [CUT_LEFT, CUT_RIGHT, CUT_LEFT | CUT_RIGHT])
def test_side_cuts_equal_the_detectors_cuts(cut):
    """A side cut found later bounds the slice exactly as the detector's would have."""
    cuts = np.array([cut])
    assert np.array_equal(
        with_side_cuts(bounds_of_cuts(np.zeros(1), np.zeros(1, bool)), cuts), bounds_of_cuts(cuts, np.zeros(1, bool))
    )


def test_a_map_without_objects_cuts_nothing():
    assert _cuts([_slice_of(GREEN_BEHIND)], [GREEN], np.zeros((0, 5)), [], []).tolist() == [0]
