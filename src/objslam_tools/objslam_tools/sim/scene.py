"""The world the simulator renders: a room, the ground truth in it, light and colours.

A ``Scene`` is plain data: the renderer turns it into pixels, the scenario generator
builds it, and ``Scene.ground_truth`` is what ``ground_truth.yaml`` records.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from objslam_common.catalog import Catalog
from objslam_common.mount import CameraMount
from objslam_tools.ground_truth import Distractor, GroundTruth, GroundTruthObject, Room, Table

RGB = tuple[int, int, int]

# Neutral (unsaturated) surfaces, so that only objects and distractors carry class colours.
TABLE_RGB: RGB = (125, 125, 130)
POST_RGB: RGB = (110, 110, 110)
SIGN_POST_RADIUS_M = 0.025


@dataclass(frozen=True)
class Lighting:
    """Directional light plus ambient: a surface of albedo A and normal n looks A * (ambient + diffuse * max(0, n.L)).

    With the defaults a surface facing the light looks 7 % brighter than its albedo and
    one facing away 25 % darker, so lit colours vary around the nominal albedo.
    """

    azimuth_rad: float = 0.8
    elevation_rad: float = np.pi / 4
    ambient: float = 0.75
    diffuse: float = 0.45

    @property
    def direction(self) -> NDArray[np.float64]:
        """Unit vector towards the light."""
        ce = np.cos(self.elevation_rad)
        return np.array([ce * np.cos(self.azimuth_rad), ce * np.sin(self.azimuth_rad), np.sin(self.elevation_rad)])


@dataclass(frozen=True)
class Appearance:
    """Colours of the room and image noise."""

    floor_rgb: RGB = (150, 145, 138)
    floor_line_rgb: RGB = (118, 114, 108)
    floor_tile_m: float = 0.6
    floor_line_m: float = 0.02
    wall_rgb: tuple[RGB, ...] = ((205, 203, 196), (196, 198, 200), (208, 205, 200), (198, 196, 192))
    baseboard_rgb: RGB = (80, 78, 76)
    baseboard_m: float = 0.08
    ceiling_rgb: RGB = (225, 225, 222)
    pixel_noise_sigma: float = 2.0  # grey levels, per channel
    exposure_jitter: float = 0.03  # relative, per frame (auto exposure)


@dataclass(frozen=True)
class Scene:
    room: Room
    objects: tuple[GroundTruthObject, ...]
    object_rgb: Mapping[str, RGB]  # nominal albedo by class label
    tables: tuple[Table, ...] = ()
    distractors: tuple[Distractor, ...] = ()
    lighting: Lighting = field(default_factory=Lighting)
    appearance: Appearance = field(default_factory=Appearance)

    @classmethod
    def with_catalog(cls, room: Room, objects: tuple[GroundTruthObject, ...], catalog: Catalog, **kwargs: Any) -> Scene:
        return cls(room=room, objects=objects, object_rgb={c.label: c.color_rgb for c in catalog}, **kwargs)

    def ground_truth(self, mount: CameraMount, frame_id: str, simulation: Mapping[str, Any]) -> GroundTruth:
        return GroundTruth(
            objects=self.objects,
            tables=self.tables,
            distractors=self.distractors,
            mount=mount,
            room=self.room,
            frame_id=frame_id,
            simulation=dict(simulation),
        )


@dataclass(frozen=True)
class Footprint:
    """What the robot must keep clear of, seen from above: a disc or a segment with a radius."""

    name: str
    start_xy: tuple[float, float]
    end_xy: tuple[float, float]
    radius_m: float


def footprints(scene: Scene) -> tuple[Footprint, ...]:
    """Every solid thing standing on the floor (objects, tables, signs), as seen from above."""
    out: list[Footprint] = []
    for o in scene.objects:
        xy = (o.position_m[0], o.position_m[1])
        out.append(Footprint(f"object {o.id} ({o.label})", xy, xy, o.radius_m))
    for t in scene.tables:
        xy = (t.position_m[0], t.position_m[1])
        out.append(Footprint(f"table {t.id}", xy, xy, t.radius_m))
    for d in scene.distractors:
        if d.kind != "sign":
            continue
        w_axis, _h, _n = d.axes()
        c = np.asarray(d.center_m[:2])
        half = w_axis[:2] * d.size_m[0] / 2.0
        out.append(Footprint(f"sign {d.id}", tuple(c - half), tuple(c + half), SIGN_POST_RADIUS_M))  # type: ignore[arg-type]
    return tuple(out)


def distance_to_footprint(points_xy: NDArray[np.float64], fp: Footprint) -> NDArray[np.float64]:
    """Distance (m) from (N, 2) points to the footprint's surface (negative inside)."""
    a = np.asarray(fp.start_xy, dtype=float)
    b = np.asarray(fp.end_xy, dtype=float)
    ab = b - a
    denom = float(ab @ ab)
    s = np.zeros(len(points_xy)) if denom == 0.0 else np.clip((points_xy - a) @ ab / denom, 0.0, 1.0)
    nearest = a + s[:, None] * ab
    return np.linalg.norm(points_xy - nearest, axis=1) - fp.radius_m


def path_clearance_m(scene: Scene, path_xy: NDArray[np.float64]) -> tuple[float, str]:
    """Smallest distance from path points to any solid surface, and what it is closest to."""
    best, name = np.inf, "nothing"
    for fp in footprints(scene):
        d = float(np.min(distance_to_footprint(path_xy, fp)))
        if d < best:
            best, name = d, fp.name
    r = scene.room
    walls = np.min(
        np.stack(
            [path_xy[:, 0] - r.x_min_m, r.x_max_m - path_xy[:, 0], path_xy[:, 1] - r.y_min_m, r.y_max_m - path_xy[:, 1]]
        )
    )
    if walls < best:
        best, name = float(walls), "a wall"
    return best, name
