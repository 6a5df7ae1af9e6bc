"""Debug overlay and the detector's parameter file."""

from __future__ import annotations

import numpy as np

from objslam_detector import Detector, DetectorConfig, draw_slices
from objslam_mapper.camera import DEFAULT_CAMERA
from objslam_mapper.config import default_config_dir, flatten, load_config
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


def test_bundled_parameter_file_holds_the_defaults():
    config = load_config(DetectorConfig, default_config_dir() / "detector.yaml", "detector")
    assert config == DetectorConfig()
    names = flatten(config)
    assert "panorama.azimuth_resolution_deg" in names and "color.class_overrides" in names
