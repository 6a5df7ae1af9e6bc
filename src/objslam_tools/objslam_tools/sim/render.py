"""Ray-casting renderer for any camera model (docs/design.md, "Cameras and the mount").

Every pixel that sees something (inside the omnidirectional image circle; every pixel of a
perspective or fisheye image within its field of view) gets one ray, computed once per
camera by the model's ``unproject``. Rays are kept sorted by their azimuth in the camera frame,
so the rays that can hit a cylinder or a rectangle form one or two contiguous slices of
that order: each thing in the scene is intersected analytically with just the rays of
its azimuth interval, and the nearest hit wins (occlusion). The room (floor, walls,
ceiling) closes every ray. Shading is Lambertian with ambient light (``Lighting``);
per-frame exposure jitter and Gaussian pixel noise come from the caller's generator.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from objslam_common.cameras import DEFAULT_CAMERA, CameraModel, UnifiedCamera
from objslam_common.geometry import wrap_angle
from objslam_common.mount import CameraMount
from objslam_tools.sim.scene import POST_RGB, SIGN_POST_RADIUS_M, TABLE_RGB, Scene

# Element indices of the room; things in the scene follow.
FLOOR, CEILING, WALL_X_MIN, WALL_X_MAX, WALL_Y_MIN, WALL_Y_MAX = range(6)
_ROOM_ELEMENTS = (("floor", 0), ("ceiling", 0), ("wall", 0), ("wall", 1), ("wall", 2), ("wall", 3))
_ROOM_NORMALS = np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], dtype=np.float32)
_AZIMUTH_MARGIN_RAD = 1e-3
_NO_HIT = np.inf


@dataclass(frozen=True)
class Rendering:
    """One rendered frame and which scene element every pixel shows."""

    image_rgb: NDArray[np.uint8]  # (H, W, 3)
    element: NDArray[np.int32]  # (H, W): index into ``elements``; -1 outside the image circle
    elements: tuple[tuple[str, int], ...]  # (kind, id): floor, ceiling, wall, object, table, distractor, sign_post

    def mask(self, kind: str, element_id: int) -> NDArray[np.bool_]:
        """Pixels that show the given element (e.g. ``("object", 3)``)."""
        try:
            index = self.elements.index((kind, element_id))
        except ValueError:
            return np.zeros(self.element.shape, dtype=bool)
        return self.element == index


@dataclass(frozen=True)
class _Cylinder:
    element: int
    x: float
    y: float
    radius: float
    z_base: float
    z_top: float


@dataclass(frozen=True)
class _Rectangle:
    element: int
    center: NDArray[np.float64]
    width_axis: NDArray[np.float64]
    height_axis: NDArray[np.float64]
    normal: NDArray[np.float64]
    half_width: float
    half_height: float
    corners: NDArray[np.float64]  # (4, 3)


@dataclass(frozen=True)
class _CompiledScene:
    elements: tuple[tuple[str, int], ...]
    albedo: NDArray[np.float32]  # (n_elements, 3)
    cylinders: tuple[_Cylinder, ...]
    rectangles: tuple[_Rectangle, ...]


def _compile(scene: Scene) -> _CompiledScene:
    elements = list(_ROOM_ELEMENTS)
    app = scene.appearance
    albedo: list[tuple[int, int, int]] = [app.floor_rgb, app.ceiling_rgb, *app.wall_rgb[:4]]
    cylinders: list[_Cylinder] = []
    rectangles: list[_Rectangle] = []

    def add(kind: str, element_id: int, rgb: tuple[int, int, int]) -> int:
        elements.append((kind, element_id))
        albedo.append(rgb)
        return len(elements) - 1

    for o in scene.objects:
        e = add("object", o.id, scene.object_rgb[o.label])
        x, y, z = o.position_m
        cylinders.append(_Cylinder(e, x, y, o.radius_m, z, z + o.size_m[1]))
    for t in scene.tables:
        e = add("table", t.id, TABLE_RGB)
        x, y, z = t.position_m
        cylinders.append(_Cylinder(e, x, y, t.radius_m, z, z + t.size_m[1]))
    for d in scene.distractors:
        e = add("distractor", d.id, d.color_rgb)
        w_axis, h_axis, normal = d.axes()
        rectangles.append(
            _Rectangle(
                element=e,
                center=np.asarray(d.center_m, float),
                width_axis=w_axis,
                height_axis=h_axis,
                normal=normal,
                half_width=d.size_m[0] / 2,
                half_height=d.size_m[1] / 2,
                corners=d.corners_m(),
            )
        )
        if d.kind == "sign":
            e = add("sign_post", d.id, POST_RGB)
            bottom = d.center_m[2] - d.size_m[1] / 2.0
            cylinders.append(_Cylinder(e, d.center_m[0], d.center_m[1], SIGN_POST_RADIUS_M, 0.0, bottom))
    return _CompiledScene(tuple(elements), np.asarray(albedo, dtype=np.float32), tuple(cylinders), tuple(rectangles))


class _Hits(NamedTuple):
    """Per ray, the nearest surface found so far: its distance, element and normal (updated in place)."""

    distance: NDArray[np.float64]
    element: NDArray[np.int32]
    normal: NDArray[np.float64]


class Renderer:
    """Renders scenes through one camera on one mount; build once, render many frames."""

    def __init__(
        self,
        camera: CameraModel = DEFAULT_CAMERA,
        mount: CameraMount | None = None,
        circle_radius_px: float | None = None,
    ) -> None:
        self.camera = camera
        self.mount = mount or CameraMount()
        h, w = camera.height_px, camera.width_px
        v, u = np.mgrid[0:h, 0:w].astype(float)
        view = self.mount.level_view(camera)  # rays in the camera's level frame: roll and pitch applied
        azimuth, elevation = view.unproject(u, v)
        if isinstance(camera, UnifiedCamera):
            if circle_radius_px is None:
                circle_radius_px = min(camera.cx, camera.cy, w - 1 - camera.cx, h - 1 - camera.cy)
            # Directions at the model's maximum elevation are degenerate; the image circle hides them anyway.
            inside = (np.hypot(u - camera.cx, v - camera.cy) <= circle_radius_px) & (
                elevation < camera.max_elevation_rad - 1e-3
            )
        else:
            # A pixel beyond the fold of the distortion has no ray (its unprojection does not
            # come back to it): left black, as the lens's vignetted corners are.
            back_u, back_v = view.project(azimuth, elevation)
            inside = np.isfinite(back_u) & (np.hypot(back_u - u, back_v - v) < 0.01)
        pixels = np.flatnonzero(inside.ravel())
        azimuth = np.asarray(azimuth).ravel()[pixels]
        elevation = np.asarray(elevation).ravel()[pixels]
        order = np.argsort(azimuth, kind="stable")
        self._pixel = pixels[order]
        self._azimuth = azimuth[order]
        self._cos_az = np.cos(self._azimuth)
        self._sin_az = np.sin(self._azimuth)
        self._cos_el = np.cos(elevation[order])
        self._sin_el = np.sin(elevation[order])
        self.ray_count = len(self._pixel)
        self._noise_pool: NDArray[np.float32] | None = None

    # ---- ray bookkeeping -------------------------------------------------------------

    def _slices(self, lo_cam_rad: float, span_rad: float) -> list[slice]:
        """Contiguous slices of the azimuth-sorted rays covering [lo, lo + span] (camera frame)."""
        if span_rad >= 2.0 * np.pi:
            return [slice(0, self.ray_count)]
        lo = float(wrap_angle(lo_cam_rad))
        hi = lo + span_rad
        az = self._azimuth
        if hi < np.pi:
            return [slice(int(np.searchsorted(az, lo)), int(np.searchsorted(az, hi, side="right")))]
        return [
            slice(int(np.searchsorted(az, lo)), self.ray_count),
            slice(0, int(np.searchsorted(az, hi - 2.0 * np.pi, side="right"))),
        ]

    # ---- rendering ---------------------------------------------------------------------

    def render(
        self, scene: Scene, map_T_base: NDArray[np.float64], rng: np.random.Generator | None = None
    ) -> Rendering:
        """Render the view from robot pose map_T_base; ``rng`` None gives a noiseless image."""
        compiled = _compile(scene)
        cam_x, cam_y, yaw = self.mount.camera_pose(map_T_base)
        origin = np.array([cam_x, cam_y, self.mount.height_m])
        cy, sy = np.cos(yaw), np.sin(yaw)
        dx = self._cos_el * (self._cos_az * cy - self._sin_az * sy)
        dy = self._cos_el * (self._sin_az * cy + self._cos_az * sy)
        dz = self._sin_el
        rays = (dx, dy, dz)

        hits = self._room(scene, origin, rays)
        for cyl in compiled.cylinders:
            self._cylinder(cyl, origin, yaw, rays, hits)
        for rect in compiled.rectangles:
            self._rectangle(rect, origin, yaw, rays, hits)

        rgb = self._shade(scene, compiled, origin, rays, hits, rng)
        element = hits.element
        h, w = self.camera.height_px, self.camera.width_px
        image = np.zeros((h * w, 3), dtype=np.uint8)
        image[self._pixel] = rgb
        element_map = np.full(h * w, -1, dtype=np.int32)
        element_map[self._pixel] = element
        return Rendering(image.reshape(h, w, 3), element_map.reshape(h, w), compiled.elements)

    def _room(self, scene: Scene, origin: NDArray, rays: tuple[NDArray, NDArray, NDArray]) -> _Hits:
        """Exit distance of every ray from the room box, and which face it leaves through."""
        r = scene.room
        dx, dy, dz = rays
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = (np.where(dx > 0, r.x_max_m, r.x_min_m) - origin[0]) / dx
            ty = (np.where(dy > 0, r.y_max_m, r.y_min_m) - origin[1]) / dy
            tz = (np.where(dz > 0, r.wall_height_m, 0.0) - origin[2]) / dz
        tx = np.where(tx > 0, tx, _NO_HIT)
        ty = np.where(ty > 0, ty, _NO_HIT)
        tz = np.where(tz > 0, tz, _NO_HIT)
        element = np.where(dx > 0, WALL_X_MAX, WALL_X_MIN).astype(np.int32)
        t = tx
        closer = ty < t
        element[closer] = np.where(dy[closer] > 0, WALL_Y_MAX, WALL_Y_MIN)
        t = np.where(closer, ty, t)
        closer = tz < t
        element[closer] = np.where(dz[closer] > 0, CEILING, FLOOR)
        t = np.where(closer, tz, t)
        return _Hits(t, element, _ROOM_NORMALS[element])

    def _candidate_slices(self, bearing_rad: float, half_width_rad: float, yaw: float) -> list[slice]:
        lo = bearing_rad - half_width_rad - _AZIMUTH_MARGIN_RAD - yaw
        return self._slices(lo, 2.0 * (half_width_rad + _AZIMUTH_MARGIN_RAD))

    def _cylinder(self, cyl: _Cylinder, origin, yaw, rays, hits: _Hits) -> None:
        t_best, element, normal = hits
        px, py = origin[0] - cyl.x, origin[1] - cyl.y
        dist = np.hypot(px, py)
        if dist <= cyl.radius:
            return  # the camera is inside it: never happens on a valid path
        half = np.arcsin(cyl.radius / dist)
        c = px * px + py * py - cyl.radius * cyl.radius
        oz = origin[2]
        for sl in self._candidate_slices(np.arctan2(-py, -px), half, yaw):
            dx, dy, dz = rays[0][sl], rays[1][sl], rays[2][sl]
            a = dx * dx + dy * dy
            b = px * dx + py * dy
            disc = b * b - a * c
            with np.errstate(invalid="ignore", divide="ignore"):
                t_side = (-b - np.sqrt(disc)) / a
                z = oz + t_side * dz
                side = (disc >= 0) & (t_side > 0) & (z >= cyl.z_base) & (z <= cyl.z_top)
                t = np.where(side, t_side, _NO_HIT)
                cap_z = cyl.z_top if oz > cyl.z_top else (cyl.z_base if oz < cyl.z_base else None)
                if cap_z is not None:
                    t_cap = (cap_z - oz) / dz
                    hx, hy = px + t_cap * dx, py + t_cap * dy
                    cap = (t_cap > 0) & (hx * hx + hy * hy <= cyl.radius * cyl.radius) & (t_cap < t)
                    t = np.where(cap, t_cap, t)
                else:
                    cap = np.zeros(len(t), dtype=bool)
            hit = t < t_best[sl]
            if not hit.any():
                continue
            idx = np.flatnonzero(hit) + sl.start
            th = t[hit]
            t_best[idx] = th
            element[idx] = cyl.element
            n = np.empty((len(idx), 3), dtype=np.float32)
            n[:, 0] = (px + th * dx[hit]) / cyl.radius
            n[:, 1] = (py + th * dy[hit]) / cyl.radius
            n[:, 2] = 0.0
            capped = cap[hit]
            n[capped] = (0.0, 0.0, 1.0 if oz > cyl.z_top else -1.0)
            normal[idx] = n

    def _rectangle(self, rect: _Rectangle, origin, yaw, rays, hits: _Hits) -> None:
        t_best, element, normal = hits
        rel = rect.corners[:, :2] - origin[:2]
        bearings = np.arctan2(rel[:, 1], rel[:, 0])
        offsets = wrap_angle(bearings - bearings[0])
        lo, hi = float(np.min(offsets)), float(np.max(offsets))
        from_camera = origin - rect.center
        inside_footprint = (
            not np.any(rect.normal[:2])  # horizontal: is the camera right above it?
            and abs(from_camera @ rect.width_axis) <= rect.half_width
            and abs(from_camera @ rect.height_axis) <= rect.half_height
        )
        if inside_footprint or hi - lo > np.pi - 1e-6:
            slices = [slice(0, self.ray_count)]
        else:
            half = (hi - lo) / 2.0
            slices = self._candidate_slices(bearings[0] + lo + half, half, yaw)
        plane_distance = -(from_camera @ rect.normal)  # signed distance from the camera to the plane along n
        face = rect.normal if plane_distance < 0 else -rect.normal  # double-sided: the side facing the camera
        s0 = from_camera @ rect.width_axis
        q0 = from_camera @ rect.height_axis
        for sl in slices:
            dx, dy, dz = rays[0][sl], rays[1][sl], rays[2][sl]
            dn = dx * rect.normal[0] + dy * rect.normal[1] + dz * rect.normal[2]
            with np.errstate(invalid="ignore", divide="ignore"):
                t = plane_distance / dn
            dw = dx * rect.width_axis[0] + dy * rect.width_axis[1] + dz * rect.width_axis[2]
            dh = dx * rect.height_axis[0] + dy * rect.height_axis[1] + dz * rect.height_axis[2]
            hit = (
                (t > 0)
                & (np.abs(s0 + t * dw) <= rect.half_width)
                & (np.abs(q0 + t * dh) <= rect.half_height)
                & (t < t_best[sl])
            )
            if not hit.any():
                continue
            idx = np.flatnonzero(hit) + sl.start
            t_best[idx] = t[hit]
            element[idx] = rect.element
            normal[idx] = face

    def _shade(self, scene: Scene, compiled: _CompiledScene, origin, rays, hits: _Hits, rng):
        t_best, element, normal = hits
        app = scene.appearance
        albedo = compiled.albedo[element]
        floor = np.flatnonzero(element == FLOOR)
        if len(floor):
            tile, line = app.floor_tile_m, app.floor_line_m
            hx = origin[0] + t_best[floor] * rays[0][floor]
            hy = origin[1] + t_best[floor] * rays[1][floor]
            on_line = (np.mod(hx + line / 2, tile) < line) | (np.mod(hy + line / 2, tile) < line)
            albedo[floor[on_line]] = app.floor_line_rgb
        walls = np.flatnonzero((element >= WALL_X_MIN) & (element <= WALL_Y_MAX))
        hz = origin[2] + t_best[walls] * rays[2][walls]
        albedo[walls[hz < app.baseboard_m]] = app.baseboard_rgb

        light = scene.lighting
        lx, ly, lz = light.direction.astype(np.float32)
        lambert = np.maximum(normal[:, 0] * lx + normal[:, 1] * ly + normal[:, 2] * lz, 0.0)
        gain = np.float32(light.ambient) + np.float32(light.diffuse) * lambert
        if rng is not None:
            gain *= np.float32(1.0 + app.exposure_jitter * rng.uniform(-1.0, 1.0))
        rgb = albedo * gain[:, None]
        if rng is not None and app.pixel_noise_sigma > 0:
            rgb += self._noise(rng, rgb.shape) * np.float32(app.pixel_noise_sigma)
        return np.clip(np.rint(rgb), 0, 255).astype(np.uint8)

    def _noise(self, rng: np.random.Generator, shape: tuple[int, ...]) -> NDArray[np.float32]:
        """Unit Gaussian noise: a random window of a fixed pool (drawing fresh noise per frame costs 30 ms)."""
        size = int(np.prod(shape))
        if self._noise_pool is None or len(self._noise_pool) < 2 * size:
            self._noise_pool = np.random.default_rng(0x5EED).standard_normal(2 * size, dtype=np.float32)
        start = int(rng.integers(0, len(self._noise_pool) - size))
        return self._noise_pool[start : start + size].reshape(shape)


@functools.lru_cache(maxsize=4)
def renderer_for(camera: CameraModel, mount: CameraMount) -> Renderer:
    """A shared renderer per (camera, mount): its ray table costs ~0.2 s to build."""
    return Renderer(camera, mount)


def render_frame(
    scene: Scene,
    map_T_base: NDArray[np.float64],
    camera: CameraModel = DEFAULT_CAMERA,
    mount: CameraMount | None = None,
    rng: np.random.Generator | None = None,
) -> NDArray[np.uint8]:
    """The (H, W, 3) uint8 RGB image seen from robot pose map_T_base (x, y, theta in the scene frame).

    ``rng`` adds exposure jitter and pixel noise; None renders a noiseless image.
    """
    return renderer_for(camera, mount or CameraMount()).render(scene, np.asarray(map_T_base, float), rng).image_rgb
