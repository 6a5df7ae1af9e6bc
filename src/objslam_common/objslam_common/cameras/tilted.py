"""A camera seen from its level frame: the mount's roll and pitch taken out of the directions.

The detector measures slices in the **level frame** of the camera: the camera's position,
turned by the mount's yaw only (x forward, z up). There a vertical cylinder's silhouette
edges are lines of constant azimuth, whatever the camera's roll and pitch, and the mapper's
slice model (position, height and yaw of the mount) needs no tilt at all. A
:class:`TiltedCamera` wraps any lens model and offers the same interface with directions of
the level frame: ``ray_level = level_R_camera @ ray_camera``, with
``level_R_camera = Ry(pitch) Rx(roll)`` (ROS fixed axes; positive pitch looks down).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.cameras.rays import project_directions, unproject_directions
from objslam_common.geometry import rotation_from_rpy


@dataclass(frozen=True)
class TiltedCamera:
    """``lens`` (any camera model) mounted with ``roll_rad`` and ``pitch_rad``; directions in the level frame."""

    lens: Any  # a UnifiedCamera, PinholeCamera or FisheyeCamera
    roll_rad: float
    pitch_rad: float
    level_R_camera: NDArray[np.float64] = field(init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "level_R_camera", rotation_from_rpy(self.roll_rad, self.pitch_rad))

    @property
    def width_px(self) -> int:
        return int(self.lens.width_px)

    @property
    def height_px(self) -> int:
        return int(self.lens.height_px)

    @property
    def distortion_model(self) -> str:
        return str(getattr(self.lens, "distortion_model", "unified"))

    def project_rays(self, rays: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """(N, 2) pixels of level-frame rays, and whether each is seen."""
        r = np.atleast_2d(np.asarray(rays, dtype=float))
        return self.lens.project_rays(r @ self.level_R_camera)  # row-wise camera_R_level @ ray

    def unproject_pixels(self, uv: ArrayLike) -> NDArray[np.float64]:
        """(N, 3) unit level-frame rays seen at pixels."""
        return self.lens.unproject_pixels(uv) @ self.level_R_camera.T

    def project(self, azimuth_rad: ArrayLike, elevation_rad: ArrayLike) -> tuple[NDArray, NDArray]:
        """Pixel (u, v) of level-frame directions (broadcast); NaN where a direction is not seen."""
        return project_directions(self.project_rays, azimuth_rad, elevation_rad)

    def unproject(self, u_px: ArrayLike, v_px: ArrayLike) -> tuple[NDArray, NDArray]:
        """Level-frame direction (azimuth, elevation) seen at pixels (u, v) (broadcast)."""
        return unproject_directions(self.unproject_pixels, u_px, v_px)


def level_view(lens: Any, roll_rad: float, pitch_rad: float) -> Any:
    """The camera as the detector sees it from the level frame: ``lens`` itself when the mount
    is level (so level rigs run exactly the lens's own code), else a :class:`TiltedCamera`."""
    if roll_rad == 0.0 and pitch_rad == 0.0:
        return lens
    return TiltedCamera(lens, float(roll_rad), float(pitch_rad))
