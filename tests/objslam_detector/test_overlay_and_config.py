"""Debug overlay and the detector's parameter file."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from objslam_common.cameras.unified import DEFAULT_CAMERA
from objslam_common.config import default_config_dir, flatten, load_config
from objslam_common.records import SliceMeasurement
from objslam_detector import Detector, DetectorConfig, draw_slices
from tests.objslam_detector.conftest import place, render, scene_of


def test_overlay_outlines_each_slice_without_touching_the_input():
    image = render(scene_of((place(0, "green", 2.5, 45.0),)))
    before = image.copy()
    detector = Detector()
    slices = detector.detect(image, DEFAULT_CAMERA)
    colours = {c.label: c.color_rgb for c in detector.catalog}
    canvas = draw_slices(image, slices, DEFAULT_CAMERA, class_rgb=colours)
    assert np.array_equal(image, before) and canvas.shape == image.shape
    changed = np.any(canvas != image, axis=2)
    v, u = np.nonzero(changed)
    # The outline surrounds the slice: pixels changed around the projected sector centre.
    sl = slices[0]
    cu, cv = DEFAULT_CAMERA.project(sl.bearing_rad, 0.5 * (sl.elevation_bottom_rad + sl.elevation_top_rad))
    assert np.hypot(u - cu, v - cv).min() < 40 and changed.sum() > 100
    assert not changed[int(cv), int(cu)]  # the inside stays visible


def test_overlay_labels_each_slice_beside_its_sector():
    r = math.radians
    slices = [
        SliceMeasurement("red", 0.9, r(bearing), r(12.0), r(-25.0), r(-5.0), 0.0, 0.0, 0.0, 0.0, 100)
        for bearing in (40.0, -120.0)
    ]
    image = np.full((640, 640, 3), 90, np.uint8)
    # No class colours: every outline is white whatever the label, so only the text can change.
    base = draw_slices(image, slices, DEFAULT_CAMERA)
    for i, sl in enumerate(slices):
        relabelled = [dataclasses.replace(s, label="blue") if k == i else s for k, s in enumerate(slices)]
        changed = np.any(draw_slices(image, relabelled, DEFAULT_CAMERA) != base, axis=2)
        v, u = np.nonzero(changed)
        assert changed.sum() > 20, i  # the text was drawn, and differs
        # The label sits just above and right of the top of the slice's sector, nowhere else.
        u0, v0 = DEFAULT_CAMERA.project(sl.bearing_rad, sl.elevation_top_rad)
        assert u.min() >= u0 - 2 and u.max() <= u0 + 120 and v.min() >= v0 - 30 and v.max() <= v0 + 5, i


def test_bundled_parameter_file_holds_the_defaults():
    config = load_config(DetectorConfig, default_config_dir() / "detector.yaml", "detector")
    assert config == DetectorConfig()
    names = flatten(config)
    assert "panorama.azimuth_resolution_deg" in names and "color.class_overrides" in names
