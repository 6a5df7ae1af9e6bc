"""The detector on frames rendered by the simulator, against the silhouettes the scene predicts."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from objslam_common.cameras.unified import DEFAULT_CAMERA
from objslam_common.geometry import wrap_angle
from objslam_common.records import SliceMeasurement
from objslam_detector import Detector
from tests.objslam_detector.conftest import CATALOG, expected, place, render, scene_of, table_for

DETECTOR = Detector()
DEG = math.radians(1.0)


def detect(image, encoding: str = "rgb8") -> list[SliceMeasurement]:
    return DETECTOR.detect(image, DEFAULT_CAMERA, encoding)


def of_label(slices: list[SliceMeasurement], label: str) -> list[SliceMeasurement]:
    return [s for s in slices if s.label == label]


def assert_matches(
    sl: SliceMeasurement, truth, bearing_tol=0.1 * DEG, width_rel=0.03, elevation_tol=0.25 * DEG
) -> None:
    """Within tolerances, the width's widened to 1.2 px of the image: the renderer does not anti-alias,
    so an edge is only known to the pixel where the pixel grid lines up with it (e.g. bearing 0)."""
    bearing, width, bottom, top = truth.sector
    width_rel = max(width_rel, 1.2 / truth.width_px)
    assert abs(wrap_angle(sl.bearing_rad - bearing)) < bearing_tol, (sl, truth)
    assert abs(sl.angular_width_rad / width - 1.0) < width_rel, (sl, truth)
    assert abs(sl.elevation_bottom_rad - bottom) < elevation_tol, (sl, truth)
    assert abs(sl.elevation_top_rad - top) < elevation_tol, (sl, truth)


@pytest.mark.parametrize("label", CATALOG.labels)
def test_single_object_of_each_class_is_measured_accurately(label):
    obj = place(0, label, 3.0, 35.0)
    tables = (table_for(0, obj),) if obj.position_m[2] > 0 else ()
    scene = scene_of((obj,), tables)
    slices = detect(render(scene))
    assert len(slices) == 1 and slices[0].label == label
    assert not slices[0].truncated and slices[0].confidence > 0.8
    assert_matches(slices[0], expected(scene)[0])


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    label=st.sampled_from(["red", "green", "blue", "yellow"]),
    range_m=st.floats(1.3, 7.0),
    bearing_deg=st.floats(-180.0, 180.0),
    scale=st.floats(0.9, 1.1),
)
# Found by CI: a sliver column at the silhouette's end made a least-squares rim fit see a jump.
@example(label="red", range_m=1.5, bearing_deg=120.0625, scale=0.97265625)
def test_one_floor_object_anywhere_gives_one_accurate_slice(label, range_m, bearing_deg, scale):
    scene = scene_of((place(0, label, range_m, bearing_deg, scale),))
    slices = detect(render(scene, seed=int(range_m * 1000)))
    assert len(slices) == 1, slices  # never split, never doubled
    assert_matches(slices[0], expected(scene)[0])


def test_object_straddling_the_azimuth_seam_stays_one_slice():
    scene = scene_of((place(0, "green", 2.5, 179.0),))
    slices = detect(render(scene))
    assert len(slices) == 1
    sl = slices[0]
    assert abs(wrap_angle(sl.bearing_rad - math.radians(179.0))) < 0.1 * DEG
    assert sl.angular_width_rad > 8 * DEG  # the whole width, both sides of +-pi
    assert -math.pi <= sl.bearing_rad < math.pi
    assert_matches(sl, expected(scene)[0])


def test_two_objects_of_one_colour_with_a_gap_are_two_slices():
    scene = scene_of((place(0, "red", 3.0, 10.0), place(1, "red", 3.0, 20.0)))
    slices = of_label(detect(render(scene)), "red")
    assert len(slices) == 2
    truth = expected(scene)
    for sl in slices:
        nearest = min(truth.values(), key=lambda o: abs(wrap_angle(o.bearing_rad - sl.bearing_rad)))
        assert_matches(sl, nearest)


def test_object_partly_behind_another_colour_is_a_separate_truncated_slice():
    near, far = place(0, "blue", 2.0, 40.0), place(1, "yellow", 4.0, 42.5)
    scene = scene_of((near, far))
    truth = expected(scene)
    assert 0.0 < truth[1].occluded_fraction < 1.0
    slices = detect(render(scene))
    blue, yellow = of_label(slices, "blue"), of_label(slices, "yellow")
    assert len(blue) == 1 and len(yellow) == 1
    assert_matches(blue[0], truth[0])
    assert yellow[0].truncated and yellow[0].confidence < blue[0].confidence
    assert yellow[0].angular_width_rad < truth[1].angular_width_rad  # only its visible part


def test_object_partly_behind_one_of_its_own_class_is_separated():
    near, far = place(0, "red", 2.8, 150.0), place(1, "red", 3.8, 154.5, scale=1.08)
    scene = scene_of((near, far))
    truth = expected(scene)
    assert truth[0].occluded_fraction == 0.0 and truth[1].occluded_fraction > 0.0
    slices = of_label(detect(render(scene)), "red")
    assert len(slices) == 2
    whole = min(slices, key=lambda s: abs(wrap_angle(s.bearing_rad - truth[0].bearing_rad)))
    behind = next(s for s in slices if s is not whole)
    assert_matches(whole, truth[0], elevation_tol=0.3 * DEG)
    assert behind.truncated and not whole.truncated


def test_object_on_a_table_ends_at_the_table_rim():
    obj = place(0, "cyan", 2.0, -70.0)
    scene = scene_of((obj,), (table_for(0, obj),))
    truth = expected(scene)[0]
    # The table hides the object's far base rim: the visible lower edge is higher.
    assert truth.elevation_bottom_rad > math.atan2(obj.position_m[2] - 0.5, truth.range_m + obj.radius_m)
    (sl,) = detect(render(scene))
    assert_matches(sl, truth)


def test_object_cut_by_the_image_circle_is_truncated():
    obj = place(0, "cyan", 1.0, 60.0)
    scene = scene_of((obj,), (table_for(0, obj),))
    assert not expected(scene)[0].in_view
    (sl,) = detect(render(scene))
    assert sl.truncated


def test_empty_room_gives_no_slices():
    assert detect(render(scene_of(()))) == []


def test_bgr_and_mono_images():
    scene = scene_of((place(0, "yellow", 2.5, -20.0),))
    rgb = render(scene)
    from_rgb = detect(rgb)
    from_bgr = detect(np.ascontiguousarray(rgb[:, :, ::-1]), "bgr8")
    assert from_rgb == from_bgr
    assert detect(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), "mono8") == []  # no colour, no class


def test_calibration_change_rebuilds_the_panorama():
    scene = scene_of((place(0, "red", 3.0, 90.0),))
    image = render(scene)
    shifted = type(DEFAULT_CAMERA)(640, 640, 0.9, 170.0, 170.0, 330.0, 320.0)
    a, b = DETECTOR.panorama(DEFAULT_CAMERA), DETECTOR.panorama(shifted)
    assert a is not b and DETECTOR.panorama(DEFAULT_CAMERA) is a
    # Same pixels read with a centre 10 px to the right: the object appears elsewhere.
    (sl,) = DETECTOR.detect(image, shifted)
    assert abs(sl.bearing_rad - math.radians(90.0)) > 1 * DEG
