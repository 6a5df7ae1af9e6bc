"""What the camera really sees of each ground-truth object in one image.

The unoccluded sector (bearing, angular width, lowest and highest elevation) is the
mapper's measurement model, :func:`objslam_mapper.model.slice_model.predict_slices`. On top of
it this module works out, by sampling the silhouette in azimuth and elevation:

- the lower edge actually visible: a table taller than the camera hides the lowest part
  of the object on it (its near top rim is in front), so the visible lower edge is the
  lowest point of the object above that rim;
- how much of the silhouette other things hide (other objects, tables, sign boards and
  their posts): an object partly hidden cannot yield a complete slice;
- whether the sector lies in the image (inside the image circle, above the lowest
  elevation the detector unwarps) and how wide it is in pixels.

Along a ray of azimuth ``theta`` a vertical cylinder (or a board) covers an elevation
interval, between its lowest and highest points in front of the object; a thing hides
the object where that interval overlaps the object's and it is nearer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.cameras import CameraModel, UnifiedCamera
from objslam_mapper.model.slice_model import BEARING, ELEVATION_BOTTOM, ELEVATION_TOP, WIDTH, predict_slices
from objslam_tools.ground_truth import GroundTruth, GroundTruthObject
from objslam_tools.sim.scene import SIGN_POST_RADIUS_M

AZIMUTH_SAMPLES = 65
ELEVATION_SAMPLES = 24
_EDGE_SHRINK = 0.999  # stay just inside the tangents, where the chord length is defined


@dataclass(frozen=True)
class VisibleObject:
    """One ground-truth object as one image sees it (angles in the camera frame, rad)."""

    object_id: int
    label: str
    bearing_rad: float
    angular_width_rad: float
    elevation_bottom_rad: float  # lowest visible point: the object's own table may hide its base
    elevation_top_rad: float
    range_m: float  # horizontal distance from the camera to the axis
    occluded_fraction: float  # share of the silhouette hidden by other things (not its own table)
    in_view: bool  # the whole sector lies in the image
    width_px: float  # arc length of the sector at its middle elevation

    @property
    def sector(self) -> tuple[float, float, float, float]:
        return (self.bearing_rad, self.angular_width_rad, self.elevation_bottom_rad, self.elevation_top_rad)


@dataclass(frozen=True)
class _Cylinder:
    x: float
    y: float
    radius: float
    z_base: float
    z_top: float


@dataclass(frozen=True)
class _Board:
    a_xy: NDArray[np.float64]
    b_xy: NDArray[np.float64]
    z_low: float
    z_high: float


class _Thing(NamedTuple):
    shape: _Cylinder | _Board
    object_id: int | None = None  # the object it is
    supports: int | None = None  # the object standing on it (tables)


def view_top_elevation(camera: CameraModel, circle_radius_px: float | None = None) -> float:
    """Highest elevation inside the image circle (default: the largest circle inside the
    image); for a perspective or fisheye camera, the highest direction it sees."""
    if not isinstance(camera, UnifiedCamera):
        from objslam_detector.panorama import highest_visible_elevation

        return highest_visible_elevation(camera)
    if circle_radius_px is None:
        circle_radius_px = min(camera.cx, camera.cy, camera.width_px - 1 - camera.cx, camera.height_px - 1 - camera.cy)
    grid = np.linspace(-math.pi / 2, camera.max_elevation_rad - 1e-3, 4000)
    radius = camera.radius_px(grid)  # increasing with elevation
    return float(np.interp(circle_radius_px, radius, grid))


def _ray_cylinder(origin_xy: NDArray, directions: NDArray, cyl: _Cylinder) -> tuple[NDArray, NDArray]:
    """Near and far horizontal distances where rays (K, 2 unit vectors) cross a circle; NaN on a miss."""
    rel = np.array([cyl.x, cyl.y]) - origin_xy
    along = directions @ rel
    across2 = rel @ rel - along * along
    half = np.sqrt(np.where(across2 < cyl.radius**2, cyl.radius**2 - across2, np.nan))
    return along - half, along + half


def _ray_board(origin_xy: NDArray, directions: NDArray, board: _Board) -> NDArray:
    """Horizontal distance where rays cross a vertical board's footprint segment; NaN on a miss."""
    seg = board.b_xy - board.a_xy
    rel = board.a_xy - origin_xy
    denom = directions[:, 0] * seg[1] - directions[:, 1] * seg[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (rel[0] * seg[1] - rel[1] * seg[0]) / denom
        s = (rel[0] * directions[:, 1] - rel[1] * directions[:, 0]) / denom
    return np.where((t > 0) & (s >= 0) & (s <= 1), t, np.nan)


def _cover(
    z_base: float, z_top: float, near: NDArray, far: NDArray, limit: NDArray, height: float
) -> tuple[NDArray, NDArray]:
    """Elevation interval a solid covers along rays, counting only its part nearer than ``limit``."""
    reach = np.minimum(far, limit)
    low = np.arctan2(z_base - height, np.where(z_base <= height, near, reach))
    high = np.arctan2(z_top - height, np.where(z_top >= height, near, reach))
    hidden = ~((near > 0) & (near < limit))  # a miss (NaN), or a thing behind the object or the camera
    return np.where(hidden, np.nan, low), np.where(hidden, np.nan, high)


def visible_objects(
    ground_truth: GroundTruth,
    map_T_base: ArrayLike,
    camera: CameraModel,
    min_elevation_rad: float = math.radians(-80.0),
    circle_radius_px: float | None = None,
) -> list[VisibleObject]:
    """Every ground-truth object as seen from robot pose ``map_T_base`` (ground-truth frame)."""
    objects = ground_truth.objects
    if not objects:
        return []
    mount = ground_truth.mount
    pose = np.asarray(map_T_base, dtype=float)
    cam = mount.camera_pose(pose)
    origin = cam[:2]
    height = mount.height_m
    view_top = view_top_elevation(camera, circle_radius_px)
    pred = predict_slices(pose, [o.position_m for o in objects], [o.size_m for o in objects], mount, jacobians=False)
    things = _occluders(ground_truth)
    out = []
    for k, obj in enumerate(objects):
        if not pred.valid[k]:
            continue
        values = pred.values[k]
        half = 0.5 * values[WIDTH] * _EDGE_SHRINK
        axis = math.atan2(obj.position_m[1] - origin[1], obj.position_m[0] - origin[0])
        theta = axis + np.linspace(-half, half, AZIMUTH_SAMPLES)
        directions = np.column_stack([np.cos(theta), np.sin(theta)])
        body = _object_cylinder(obj)
        near, far = _ray_cylinder(origin, directions, body)
        low, high = _cover(body.z_base, body.z_top, near, far, np.full_like(near, np.inf), height)
        hidden_by = []
        for thing in things:
            if thing.object_id == obj.id:
                continue
            shape = thing.shape
            if isinstance(shape, _Board):
                dist = _ray_board(origin, directions, shape)
                cover = _cover(shape.z_low, shape.z_high, dist, dist, near, height)
            else:
                cover = _cover(shape.z_base, shape.z_top, *_ray_cylinder(origin, directions, shape), near, height)
            if thing.supports == obj.id:
                # Its own support only raises the visible lower edge.
                low = np.where(cover[0] <= low, np.fmax(low, cover[1]), low)
            else:
                hidden_by.append(cover)
        seen = high > low
        bottom = float(np.min(low[seen])) if seen.any() else float(values[ELEVATION_BOTTOM])
        fraction = _hidden_fraction(low, high, seen, hidden_by)
        top = float(values[ELEVATION_TOP])
        mid = 0.5 * (bottom + top)
        out.append(
            VisibleObject(
                object_id=obj.id,
                label=obj.label,
                bearing_rad=float(values[BEARING]),
                angular_width_rad=float(values[WIDTH]),
                elevation_bottom_rad=bottom,
                elevation_top_rad=top,
                range_m=float(pred.range_m[k]),
                occluded_fraction=fraction,
                in_view=bool(top <= view_top and bottom >= min_elevation_rad)
                and _inside_image(camera, float(values[BEARING]), float(values[WIDTH]), bottom, top),
                width_px=_width_px(camera, float(values[BEARING]), float(values[WIDTH]), mid),
            )
        )
    return out


def _inside_image(camera: CameraModel, bearing: float, width: float, bottom: float, top: float) -> bool:
    """The silhouette's four corners project into the image (always, for the omnidirectional
    camera: its view is all around, bounded in elevation only)."""
    if isinstance(camera, UnifiedCamera):
        return True
    azimuth = np.array([bearing - width / 2, bearing + width / 2] * 2)
    elevation = np.array([bottom, bottom, top, top])
    u, v = camera.project(azimuth, elevation)
    return bool(
        np.all(np.isfinite(u))
        and np.all((u >= 0) & (u <= camera.width_px - 1) & (v >= 0) & (v <= camera.height_px - 1))
    )


def _width_px(camera: CameraModel, bearing: float, width: float, elevation: float) -> float:
    """How many pixels across the silhouette is, at ``elevation``."""
    if isinstance(camera, UnifiedCamera):
        return float(width * camera.radius_px(elevation))
    u, v = camera.project(np.array([bearing - width / 2, bearing + width / 2]), np.array([elevation, elevation]))
    return float(np.hypot(u[1] - u[0], v[1] - v[0])) if np.all(np.isfinite(u)) else 0.0


def _hidden_fraction(low: NDArray, high: NDArray, seen: NDArray, covers: list[tuple[NDArray, NDArray]]) -> float:
    if not seen.any():
        return 1.0
    steps = (np.arange(ELEVATION_SAMPLES) + 0.5) / ELEVATION_SAMPLES
    elevations = low[seen, None] + steps[None, :] * (high[seen] - low[seen])[:, None]
    hidden = np.zeros(elevations.shape, dtype=bool)
    for c_low, c_high in covers:
        lo, hi = c_low[seen, None], c_high[seen, None]
        with np.errstate(invalid="ignore"):
            hidden |= (elevations >= lo) & (elevations <= hi)
    return float(hidden.mean())


def _occluders(gt: GroundTruth) -> list[_Thing]:
    """Everything solid that can stand between the camera and an object."""
    things = [_Thing(_object_cylinder(o), object_id=o.id) for o in gt.objects]
    for t in gt.tables:
        x, y, z = t.position_m
        things.append(_Thing(_Cylinder(x, y, t.radius_m, z, z + t.size_m[1]), supports=t.object_id))
    for d in gt.distractors:
        if not d.is_vertical:
            continue  # floor patches lie flat: they hide nothing
        w_axis, _h, _n = d.axes()
        centre = np.asarray(d.center_m, dtype=float)
        half = 0.5 * d.size_m[0] * w_axis[:2]
        low, high = centre[2] - 0.5 * d.size_m[1], centre[2] + 0.5 * d.size_m[1]
        things.append(_Thing(_Board(centre[:2] - half, centre[:2] + half, low, high)))
        if d.kind == "sign":
            things.append(_Thing(_Cylinder(centre[0], centre[1], SIGN_POST_RADIUS_M, 0.0, low)))
    return things


def _object_cylinder(o: GroundTruthObject) -> _Cylinder:
    return _Cylinder(o.position_m[0], o.position_m[1], o.radius_m, o.position_m[2], o.z_top_m)
