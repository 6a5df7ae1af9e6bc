"""Predicted silhouettes (objslam_tools.silhouette) against the renderer's own pixel labels."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objslam_common.cameras.unified import DEFAULT_CAMERA
from objslam_common.catalog import load_catalog
from objslam_common.mount import CameraMount
from objslam_tools.ground_truth import GroundTruth, GroundTruthObject, Room, Table
from objslam_tools.silhouette import view_top_elevation, visible_objects
from objslam_tools.sim import Renderer, Scene

CATALOG = load_catalog()
ROOM = Room(-9.0, 9.0, -9.0, 9.0)
POSE = np.zeros(3)
RENDERER = Renderer(DEFAULT_CAMERA, CameraMount())


def obj(object_id: int, label: str, range_m: float, bearing_deg: float, z_base: float = 0.0) -> GroundTruthObject:
    cls = CATALOG[label]
    a = math.radians(bearing_deg)
    return GroundTruthObject(
        object_id, label, (range_m * math.cos(a), range_m * math.sin(a), z_base), (cls.diameter_m, cls.height_m)
    )


def seen(objects, tables=()):
    scene = Scene.with_catalog(ROOM, tuple(objects), CATALOG, tables=tuple(tables))
    rendering = RENDERER.render(scene, POSE, None)
    gt = GroundTruth(objects=tuple(objects), tables=tuple(tables), room=ROOM)
    return rendering, {v.object_id: v for v in visible_objects(gt, POSE, DEFAULT_CAMERA)}


def pixel_extent(rendering, object_id: int) -> tuple[float, float, float, float, int]:
    """(az min, az max, el min, el max) of the object's pixel centres, and their count."""
    v, u = np.nonzero(rendering.mask("object", object_id))
    az, el = DEFAULT_CAMERA.unproject(u.astype(float), v.astype(float))
    return float(az.min()), float(az.max()), float(el.min()), float(el.max()), len(u)


def pixel_angle(elevation: float) -> float:
    """Angle one pixel spans (radially) near an elevation, rad."""
    return 1.0 / float(DEFAULT_CAMERA.radius_px(elevation + 0.01) - DEFAULT_CAMERA.radius_px(elevation)) * 0.01


@pytest.mark.parametrize(
    ("label", "range_m", "bearing"), [("red", 3.0, 30.0), ("yellow", 2.0, -60.0), ("blue", 5.0, 120.0)]
)
def test_unoccluded_sector_hugs_the_rendered_pixels(label, range_m, bearing):
    rendering, views = seen([obj(0, label, range_m, bearing)])
    view = views[0]
    az0, az1, el0, el1, _ = pixel_extent(rendering, 0)
    radial = pixel_angle(view.elevation_bottom_rad)
    around = 1.0 / DEFAULT_CAMERA.radius_px(view.elevation_bottom_rad)
    half = view.angular_width_rad / 2
    assert view.bearing_rad - half <= az0 + 1e-9 and az0 - (view.bearing_rad - half) < 1.5 * around
    assert az1 <= view.bearing_rad + half + 1e-9 and (view.bearing_rad + half) - az1 < 1.5 * around
    assert view.elevation_bottom_rad <= el0 + 1e-9 and el0 - view.elevation_bottom_rad < 1.5 * radial
    assert el1 <= view.elevation_top_rad + 1e-9 and view.elevation_top_rad - el1 < 1.5 * pixel_angle(el1)
    assert view.occluded_fraction == 0.0 and view.in_view


def test_own_table_raises_the_visible_lower_edge():
    o = obj(0, "cyan", 2.0, 45.0, z_base=0.75)
    table = Table(0, (o.position_m[0], o.position_m[1], 0.0), (0.45, 0.75), object_id=0)
    rendering, views = seen([o], [table])
    _, _, el0, _, _ = pixel_extent(rendering, 0)
    assert abs(views[0].elevation_bottom_rad - el0) < 1.5 * pixel_angle(el0)
    assert views[0].occluded_fraction == 0.0  # its own table is not an occluder


def test_occluded_fraction_matches_the_hidden_pixels():
    near, far = obj(0, "blue", 2.0, 40.0), obj(1, "yellow", 4.0, 42.0)
    rendering, views = seen([near, far])
    alone, _ = seen([far])
    hidden = 1.0 - pixel_extent(rendering, 1)[4] / pixel_extent(alone, 1)[4]
    assert 0.2 < hidden < 0.9
    assert abs(views[1].occluded_fraction - hidden) < 0.1
    assert views[0].occluded_fraction == 0.0


def test_things_behind_the_camera_hide_nothing():
    front = obj(0, "yellow", 4.0, 50.0)
    behind = obj(1, "cyan", 1.0, -120.0, z_base=0.75)
    table = Table(0, (behind.position_m[0], behind.position_m[1], 0.0), (0.45, 0.75), object_id=1)
    _, views = seen([front, behind], [table])
    assert views[0].occluded_fraction == 0.0


def test_objects_beyond_the_image_circle_are_not_in_view():
    o = obj(0, "blue", 0.8, 10.0)
    _, views = seen([o])
    assert views[0].elevation_top_rad > view_top_elevation(DEFAULT_CAMERA)
    assert not views[0].in_view
