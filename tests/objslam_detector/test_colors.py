"""Colour gates: derived from the catalog, separated, overridable; classification by hue/saturation/value."""

from __future__ import annotations

import colorsys

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from objslam_common.catalog import load_catalog
from objslam_common.config import from_mapping
from objslam_common.errors import ConfigError
from objslam_detector import ColorConfig, DetectorConfig
from objslam_detector.colors import classify, derive_gates, hue_distance_deg, lookup_tables, parse_class_overrides

CATALOG = load_catalog()


def classify_rgb(rgb) -> int:
    pixel = np.array([[rgb]], dtype=np.uint8)
    return int(classify(cv2.cvtColor(pixel, cv2.COLOR_RGB2HSV_FULL), derive_gates(CATALOG, ColorConfig()))[0, 0])


def test_gates_centre_on_the_catalog_hues_and_never_overlap():
    gates = derive_gates(CATALOG, ColorConfig())
    assert [g.label for g in gates] == list(CATALOG.labels)
    for gate, cls in zip(gates, CATALOG, strict=True):
        hue = 360.0 * colorsys.rgb_to_hsv(*(c / 255.0 for c in cls.color_rgb))[0]
        assert hue_distance_deg(gate.hue_deg, hue) < 1e-9
    for a in gates:
        for b in gates:
            if a is not b:
                assert hue_distance_deg(a.hue_deg, b.hue_deg) > a.hue_halfwidth_deg + b.hue_halfwidth_deg
    assert lookup_tables(gates) is not None


@pytest.mark.parametrize("cls", list(CATALOG), ids=lambda c: c.label)
@pytest.mark.parametrize("gain", [0.55, 0.75, 1.0, 1.2])
def test_catalog_colours_under_lighting_are_their_class(cls, gain):
    rgb = np.clip(np.asarray(cls.color_rgb) * gain, 0, 255).astype(np.uint8)
    assert classify_rgb(rgb) == CATALOG.labels.index(cls.label) + 1


@given(grey=st.integers(80, 255), tint=st.integers(-12, 12), dark=st.integers(0, 25))
def test_greys_and_very_dark_pixels_are_no_class(grey, tint, dark):
    assert classify_rgb(np.clip([grey + tint, grey, grey - tint], 0, 255)) == 0
    assert classify_rgb([0, dark, dark // 2]) == 0  # hue is noise in the dark


def test_overrides_replace_derived_values():
    config = ColorConfig(class_overrides=("red: hue_halfwidth_deg=8, min_saturation=0.6", "cyan: min_value=0.3"))
    gates = {g.label: g for g in derive_gates(CATALOG, config)}
    assert gates["red"].hue_halfwidth_deg == 8.0 and gates["red"].min_saturation == 0.6
    assert gates["cyan"].min_value == 0.3
    assert gates["green"].min_value == config.min_value


def test_overlapping_overrides_still_classify_with_the_later_gate_winning():
    config = ColorConfig(class_overrides=("yellow: hue_halfwidth_deg=60",))
    gates = derive_gates(CATALOG, config)
    assert lookup_tables(gates) is None  # the slow path
    hsv = cv2.cvtColor(np.array([[[200, 30, 30]]], np.uint8), cv2.COLOR_RGB2HSV_FULL)
    assert classify(hsv, gates)[0, 0] == CATALOG.labels.index("yellow") + 1  # red's hue, yellow's wider gate


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ("red hue_deg=3", "expected 'LABEL: key=value"),
        ("red: colour=3", "unknown item 'colour=3'"),
        ("red: hue_deg=abc", "hue_deg must be a number"),
    ],
)
def test_malformed_overrides_are_config_errors(entry, message):
    with pytest.raises(ValueError, match=message):
        parse_class_overrides([entry])
    with pytest.raises(ConfigError, match=message):
        from_mapping(DetectorConfig, {"color": {"class_overrides": [entry]}})


def test_override_for_an_unknown_class_is_refused():
    from objslam_detector import Detector

    with pytest.raises(ConfigError, match="no such class in the catalog"):
        Detector(DetectorConfig(color=ColorConfig(class_overrides=("purple: hue_deg=280",))))
