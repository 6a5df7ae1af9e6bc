"""Scenes for detector tests, rendered by the simulator's renderer (objslam_tools.sim).

The robot stands at the origin of a large room looking along +x, so a thing's camera-
frame bearing is its azimuth around the origin. Expected slices come from
objslam_tools.silhouette (the mapper's measurement model plus table cut and occlusion).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from objslam_common.cameras.unified import DEFAULT_CAMERA, UnifiedCamera
from objslam_common.catalog import load_catalog
from objslam_common.mount import CameraMount
from objslam_tools.ground_truth import Distractor, GroundTruth, GroundTruthObject, Room, Table
from objslam_tools.silhouette import VisibleObject, visible_objects
from objslam_tools.sim import Renderer, Scene

CATALOG = load_catalog()
ROOM = Room(-9.0, 9.0, -9.0, 9.0)
POSE = np.zeros(3)
_RENDERERS: dict[UnifiedCamera, Renderer] = {}


def place(object_id: int, label: str, range_m: float, bearing_deg: float, scale: float = 1.0) -> GroundTruthObject:
    """An object of nominal size (times ``scale``) at a range and bearing from the robot."""
    cls = CATALOG[label]
    a = math.radians(bearing_deg)
    return GroundTruthObject(
        object_id,
        label,
        (range_m * math.cos(a), range_m * math.sin(a), cls.z_base_m),
        (cls.diameter_m * scale, cls.height_m * scale),
    )


def table_for(table_id: int, obj: GroundTruthObject, diameter_m: float = 0.45) -> Table:
    return Table(table_id, (obj.position_m[0], obj.position_m[1], 0.0), (diameter_m, obj.position_m[2]), obj.id)


def scene_of(
    objects: tuple[GroundTruthObject, ...], tables: tuple[Table, ...] = (), distractors: tuple[Distractor, ...] = ()
) -> Scene:
    return Scene.with_catalog(ROOM, objects, CATALOG, tables=tables, distractors=distractors)


def render(scene: Scene, camera: UnifiedCamera = DEFAULT_CAMERA, seed: int | None = 0) -> NDArray[np.uint8]:
    """RGB image from the origin; ``seed`` None for no noise."""
    renderer = _RENDERERS.get(camera)
    if renderer is None:
        renderer = _RENDERERS[camera] = Renderer(camera, CameraMount())
    rng = None if seed is None else np.random.default_rng(seed)
    return renderer.render(scene, POSE, rng).image_rgb


def expected(scene: Scene, camera: UnifiedCamera = DEFAULT_CAMERA) -> dict[int, VisibleObject]:
    gt = GroundTruth(objects=scene.objects, tables=scene.tables, distractors=scene.distractors, room=ROOM)
    return {v.object_id: v for v in visible_objects(gt, POSE, camera)}
