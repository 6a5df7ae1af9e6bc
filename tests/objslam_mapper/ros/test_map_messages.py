"""A built map as ROS messages (plain conversions, no ROS graph): markers, path, ObjectMap."""

from __future__ import annotations

import math

import pytest
from visualization_msgs.msg import Marker

from objslam_common.catalog import load_catalog
from objslam_common.ros.conversions import time_from_ns
from objslam_mapper.map_file import BuiltMap, MappedObject, TrajectoryPose
from objslam_mapper.ros.map_messages import to_marker_array, to_object_map, to_path

CATALOG = load_catalog()
STAMP = time_from_ns(12_500_000_000)
RED = MappedObject(3, "red", (1.0, -2.0, 0.0), (0.30, 0.60), 0.9)
CYAN = MappedObject(7, "cyan", (-0.5, 0.25, 0.75), (0.15, 0.25), 0.62)  # on a table: z_base 0.75
GHOST = MappedObject(3, "green", (4.0, 4.0, 0.0), (0.4, 0.4), 0.2)  # rejected; same id as RED
BUILT = BuiltMap(objects=(RED, CYAN), rejected=(GHOST,), frame_id="odom")


def _by(markers, ns: str) -> dict[int, Marker]:
    return {m.id: m for m in markers if m.ns == ns}


def _rgba(marker: Marker) -> tuple[float, float, float, float]:
    c = marker.color
    return (c.r, c.g, c.b, c.a)


def test_markers_clear_first_then_a_cylinder_per_object_at_its_centre():
    markers = to_marker_array(BUILT, CATALOG, STAMP).markers
    # DELETEALL first, once: a new map replaces the old one in RViz, stale objects included.
    assert markers[0].action == Marker.DELETEALL
    assert [m.action for m in markers[1:]] == [Marker.ADD] * (len(markers) - 1)
    assert all(m.header.frame_id == "odom" and m.header.stamp == STAMP for m in markers)

    cylinders = _by(markers, "objects")
    assert sorted(cylinders) == [3, 7]
    for obj in (RED, CYAN):
        m = cylinders[obj.id]
        x, y, z_base = obj.position_m
        diameter, height = obj.size_m
        assert m.type == Marker.CYLINDER
        # RViz centres a cylinder on its pose: the base is at z_base, not the centre.
        assert (m.pose.position.x, m.pose.position.y, m.pose.position.z) == pytest.approx((x, y, z_base + height / 2))
        q = m.pose.orientation
        assert (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.0, 1.0)  # upright
        assert (m.scale.x, m.scale.y, m.scale.z) == pytest.approx((diameter, diameter, height))
        r, g, b = CATALOG[obj.label].color_rgb
        assert _rgba(m) == pytest.approx((r / 255, g / 255, b / 255, obj.existence_probability))


def test_each_object_has_a_text_label_with_its_probability_above_it():
    markers = to_marker_array(BUILT, CATALOG, STAMP).markers
    labels = _by(markers, "labels")
    assert sorted(labels) == [3, 7]
    for obj in (RED, CYAN):
        m = labels[obj.id]
        assert m.type == Marker.TEXT_VIEW_FACING
        assert obj.label in m.text and f"p={obj.existence_probability:.2f}" in m.text
        assert m.pose.position.z > obj.position_m[2] + obj.size_m[1]  # above the top, readable
        assert m.color.a == 1.0  # the text stays readable whatever the probability


def test_rejected_identities_have_their_own_namespaces():
    markers = to_marker_array(BUILT, CATALOG, STAMP).markers
    # Same id as RED, but in their own namespaces: neither replaces the other, and a
    # display can hide the rejected ones.
    rejected = _by(markers, "rejected")
    assert list(rejected) == [3] and rejected[3].type == Marker.CYLINDER
    assert rejected[3].color.a == pytest.approx(GHOST.existence_probability)
    assert _by(markers, "rejected_labels")[3].type == Marker.TEXT_VIEW_FACING
    assert _by(markers, "objects")[3].pose.position.x == pytest.approx(RED.position_m[0])
    assert len(markers) == 1 + 2 * 3  # DELETEALL, then a cylinder and a text per identity


def test_an_empty_map_still_clears_the_display():
    markers = to_marker_array(BuiltMap(objects=()), CATALOG, STAMP).markers
    assert [m.action for m in markers] == [Marker.DELETEALL]


def test_object_map_keeps_z_base_and_path_keeps_the_stamps():
    built = BuiltMap(
        objects=(CYAN,),
        trajectory=(TrajectoryPose(1_000_000_001, 0.5, -0.5, math.pi / 2),),
        diagnostics={"samples": 300, "burn_in": 100},
    )
    objects = to_object_map(built, STAMP)
    (obj,) = objects.objects
    # The structured map uses the contract's convention (z of the base), unlike the marker.
    assert (obj.position.x, obj.position.y, obj.position.z) == (-0.5, 0.25, 0.75)
    assert (obj.diameter, obj.height, obj.id, obj.label) == (0.15, 0.25, 7, "cyan")
    assert (objects.samples, objects.burn_in) == (300, 100)
    (pose,) = to_path(built, STAMP).poses
    assert (pose.header.stamp.sec, pose.header.stamp.nanosec) == (1, 1)
    q = pose.pose.orientation
    assert 2 * math.atan2(q.z, q.w) == pytest.approx(math.pi / 2)
