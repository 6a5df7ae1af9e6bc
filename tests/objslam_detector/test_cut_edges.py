"""A perspective camera's view ends on four sides: a blob it cuts is flagged on exactly the
edges it cannot see, and the mount's pitch is taken out of the measured angles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objslam_common.cameras import PRESET_CAMERAS
from objslam_common.mount import CameraMount, CameraMountConfig
from objslam_common.records import CUT_BOTTOM, CUT_LEFT, CUT_RIGHT, CUT_TOP
from objslam_detector.config import DetectorConfig
from objslam_detector.detector import Detector
from objslam_tools.ground_truth import GroundTruth
from objslam_tools.silhouette import visible_objects
from objslam_tools.sim import Renderer
from tests.objslam_detector.conftest import CATALOG, POSE, ROOM, place, scene_of

PITCH_RAD = 0.25
MOUNT = CameraMount(pitch_rad=PITCH_RAD)
LENS = PRESET_CAMERAS["pinhole"]  # about 90 degrees across, 74 degrees high
RENDERER = Renderer(LENS, MOUNT)
DETECTOR = Detector(DetectorConfig(camera_mount=CameraMountConfig.of(MOUNT)), CATALOG)


def _slice_of(label: str, range_m: float, bearing_deg: float):
    scene = scene_of((place(0, label, range_m, bearing_deg),))
    image = RENDERER.render(scene, POSE, None).image_rgb
    slices = [s for s in DETECTOR.detect(image, LENS) if s.label == label]
    assert slices
    return scene, max(slices, key=lambda s: s.pixel_count)


@pytest.mark.parametrize(
    ("label", "range_m", "bearing_deg", "cuts", "not_cut"),
    [
        ("red", 2.5, 10.0, 0, 15),  # whole in view
        # Across the left (counter-clockwise) border; the pitched view's border is slanted in
        # the level frame, so the top may be cut there too.
        ("red", 3.0, 44.0, CUT_LEFT, CUT_RIGHT | CUT_BOTTOM),
        ("red", 3.0, -44.0, CUT_RIGHT, CUT_LEFT | CUT_BOTTOM),
        # Tall and near: above and below the view (where the slanted border may touch its sides too).
        ("blue", 0.45, 0.0, CUT_TOP | CUT_BOTTOM, 0),
    ],
)
def test_the_edges_the_view_cuts_are_flagged_and_the_others_are_not(label, range_m, bearing_deg, cuts, not_cut):
    _scene, sl = _slice_of(label, range_m, bearing_deg)
    assert sl.cut_edges & cuts == cuts and not sl.cut_edges & not_cut
    assert sl.truncated == (sl.cut_edges != 0)


def test_a_whole_object_seen_by_a_pitched_camera_is_measured_in_the_level_frame():
    scene, sl = _slice_of("green", 2.5, 15.0)
    gt = GroundTruth(objects=scene.objects, mount=MOUNT, room=ROOM)
    (truth,) = visible_objects(gt, POSE, MOUNT.level_view(LENS))
    assert truth.in_view
    assert sl.bearing_rad == pytest.approx(truth.bearing_rad, abs=math.radians(0.3))
    assert sl.angular_width_rad == pytest.approx(truth.angular_width_rad, rel=0.1)
    assert sl.elevation_bottom_rad == pytest.approx(truth.elevation_bottom_rad, abs=math.radians(0.5))
    assert sl.elevation_top_rad == pytest.approx(truth.elevation_top_rad, abs=math.radians(0.5))
    # Measured as if the camera were level: the pitch does not leak into the elevations.
    assert abs(sl.elevation_top_rad - truth.elevation_top_rad) < 0.1 * PITCH_RAD
    assert np.isfinite(sl.confidence) and sl.cut_edges == 0
