"""Where the camera sits on the robot: its pose on ``base_link``.

The mount is an offset from the rotation axis, a height, and roll, pitch and yaw (ROS fixed
axes). The detector takes roll and pitch out of its directions (it measures in the camera's
level frame, :mod:`objslam_common.cameras.tilted`), so the mapper's slice model needs only
the planar pose, the height and the yaw. :class:`CameraMountConfig` is its one definition as
settings, shared by the detector and the mapper.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.cameras import CameraModel, level_view
from objslam_common.config import setting
from objslam_common.geometry import rotation, wrap_angle


@dataclass(frozen=True)
class CameraMount:
    """Where the camera sits on the robot: base_T_camera (x, y, height; roll, pitch, yaw).

    Default: on the robot's rotation axis, 0.5 m above the floor, level, looking forward.
    """

    height_m: float = 0.5
    offset_x_m: float = 0.0
    offset_y_m: float = 0.0
    yaw_rad: float = 0.0
    roll_rad: float = 0.0
    pitch_rad: float = 0.0

    def level_view(self, lens: CameraModel) -> CameraModel:
        """``lens`` seen from the camera's level frame (the lens itself on a level mount)."""
        return level_view(lens, self.roll_rad, self.pitch_rad)

    def camera_pose(self, map_T_base: ArrayLike) -> NDArray[np.float64]:
        """map_T_camera (x, y, yaw) of the camera for a robot pose map_T_base."""
        p = np.asarray(map_T_base, dtype=float)
        xy = p[:2] + rotation(p[2]) @ np.array([self.offset_x_m, self.offset_y_m])
        return np.array([xy[0], xy[1], wrap_angle(p[2] + self.yaw_rad)])

    def direction_to(self, map_T_base: ArrayLike, map_points_xyz: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
        """Azimuth, elevation (camera frame, rad) and horizontal range (m) of map points."""
        cam = self.camera_pose(map_T_base)
        pts = np.atleast_2d(np.asarray(map_points_xyz, dtype=float))
        dx = pts[:, 0] - cam[0]
        dy = pts[:, 1] - cam[1]
        rng = np.hypot(dx, dy)
        azimuth = wrap_angle(np.arctan2(dy, dx) - cam[2])
        elevation = np.arctan2(pts[:, 2] - self.height_m, rng)
        return azimuth, elevation, rng


@dataclass(frozen=True, eq=False)
class CameraMounts:
    """One camera mount per measurement: ``CameraMount``'s fields, the planar ones as (M,) arrays.

    A slice seen from an image that is not a graph pose (``objslam_mapper.graph.keyframes``)
    is predicted from the graph pose before it: the camera then sits at
    ``graph_T_image ∘ base_T_camera`` relative to that pose. The slice model takes this
    wherever it takes a ``CameraMount`` (the fields broadcast over measurements).
    """

    height_m: float
    offset_x_m: NDArray[np.float64]
    offset_y_m: NDArray[np.float64]
    yaw_rad: NDArray[np.float64]

    @classmethod
    def behind(cls, mount: CameraMount, graph_T_base: ArrayLike) -> CameraMounts:
        """The mounts of cameras on robots at (M, 3) poses ``graph_T_base`` relative to the graph poses."""
        pose = np.atleast_2d(np.asarray(graph_T_base, dtype=float))
        cos_t, sin_t = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        return cls(
            height_m=mount.height_m,
            offset_x_m=pose[:, 0] + cos_t * mount.offset_x_m - sin_t * mount.offset_y_m,
            offset_y_m=pose[:, 1] + sin_t * mount.offset_x_m + cos_t * mount.offset_y_m,
            yaw_rad=pose[:, 2] + mount.yaw_rad,
        )

    def take(self, index: NDArray[np.int64]) -> CameraMounts:
        """The mounts of measurements ``index``."""
        return CameraMounts(self.height_m, self.offset_x_m[index], self.offset_y_m[index], self.yaw_rad[index])


@dataclass(frozen=True)
class CameraMountConfig:
    """Where the camera sits on the robot (base_link frame)."""

    height_m: float = setting(0.5, "camera height above the floor (m)", minimum=0.0)
    offset_x_m: float = setting(0.0, "camera position ahead of the rotation axis (m)")
    offset_y_m: float = setting(0.0, "camera position left of the rotation axis (m)")
    yaw_rad: float = setting(0.0, "camera forward axis relative to the robot's (rad, counter-clockwise)")
    roll_rad: float = setting(
        0.0, "camera roll about its forward axis (rad, ROS fixed axes)", minimum=-1.6, maximum=1.6
    )
    pitch_rad: float = setting(
        0.0, "camera pitch (rad, ROS fixed axes: positive tilts the forward axis down)", minimum=-1.6, maximum=1.6
    )

    def to_mount(self) -> CameraMount:
        return CameraMount(
            height_m=self.height_m,
            offset_x_m=self.offset_x_m,
            offset_y_m=self.offset_y_m,
            yaw_rad=self.yaw_rad,
            roll_rad=self.roll_rad,
            pitch_rad=self.pitch_rad,
        )

    @classmethod
    def of(cls, mount: CameraMount) -> CameraMountConfig:
        """The settings of a mount."""
        return cls(
            height_m=mount.height_m,
            offset_x_m=mount.offset_x_m,
            offset_y_m=mount.offset_y_m,
            yaw_rad=mount.yaw_rad,
            roll_rad=mount.roll_rad,
            pitch_rad=mount.pitch_rad,
        )
