"""The central omnidirectional camera: the unified (Mei) sphere model.

Conventions (docs/design.md, "Cameras and the mount"): the optical axis is vertical and
the image centre looks straight down. A direction with azimuth ``a`` (counter-clockwise
from the camera's forward axis) and elevation ``e`` (above the horizontal) is the
unit-sphere point ``(cos e cos a, cos e sin a, -sin e)``; with
``m = (x_s, y_s) / (z_s + xi)`` the pixel is ``u = cx + fx m_x``, ``v = cy - fy m_y``.
Radius grows with elevation and the horizon is the ring ``r = f / xi``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.cameras.rays import directions_from_rays, rays_from_directions
from objslam_common.errors import CameraModelError
from objslam_common.geometry import wrap_angle


@dataclass(frozen=True)
class UnifiedCamera:
    """Intrinsics of the unified sphere model (sensor_msgs/CameraInfo, model "unified")."""

    width_px: int
    height_px: int
    xi: float
    fx: float
    fy: float
    cx: float
    cy: float

    distortion_model: ClassVar[str] = "unified"

    def __post_init__(self) -> None:
        if not all(np.isfinite([self.xi, self.fx, self.fy, self.cx, self.cy])):
            raise CameraModelError("unified: calibration values must be finite")
        if self.width_px <= 0 or self.height_px <= 0:
            raise CameraModelError(f"image size must be positive, got {self.width_px}x{self.height_px}")
        if not (0.0 < self.xi <= 1.0):
            # xi > 1 would make the horizon ring fold back; our rigs are mirrors with xi <= 1.
            raise CameraModelError(f"xi must be in (0, 1], got {self.xi}")
        if self.fx <= 0.0 or self.fy <= 0.0:
            raise CameraModelError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")

    @property
    def max_elevation_rad(self) -> float:
        """Elevation where z_s + xi = 0: directions at or above it do not project."""
        return float(np.arcsin(self.xi))

    @property
    def horizon_radius_px(self) -> float:
        """Radius (in x, with fx) of the ring where elevation is zero."""
        return self.fx / self.xi

    def project(self, azimuth_rad: ArrayLike, elevation_rad: ArrayLike) -> tuple[NDArray, NDArray]:
        """Pixel (u, v) of directions; NaN where a direction does not project."""
        a = np.asarray(azimuth_rad, dtype=float)
        e = np.asarray(elevation_rad, dtype=float)
        ce = np.cos(e)
        denom = -np.sin(e) + self.xi
        with np.errstate(divide="ignore", invalid="ignore"):
            valid = denom > 1e-9
            mx = np.where(valid, ce * np.cos(a) / denom, np.nan)
            my = np.where(valid, ce * np.sin(a) / denom, np.nan)
        return self.cx + self.fx * mx, self.cy - self.fy * my

    def unproject(self, u_px: ArrayLike, v_px: ArrayLike) -> tuple[NDArray, NDArray]:
        """Direction (azimuth, elevation) seen at pixels (u, v)."""
        mx = (np.asarray(u_px, dtype=float) - self.cx) / self.fx
        my = (self.cy - np.asarray(v_px, dtype=float)) / self.fy
        r2 = mx * mx + my * my
        # Lift the normalized point back onto the unit sphere (Mei & Rives, 2007).
        disc = 1.0 + (1.0 - self.xi * self.xi) * r2
        factor = (self.xi + np.sqrt(np.maximum(disc, 0.0))) / (r2 + 1.0)
        xs, ys, zs = factor * mx, factor * my, factor - self.xi
        azimuth = wrap_angle(np.arctan2(ys, xs))
        elevation = np.arctan2(-zs, np.hypot(xs, ys))
        return azimuth, elevation

    def project_rays(self, rays: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """(N, 2) pixels of camera-frame rays and whether each projects (the same interface
        as the perspective and fisheye models)."""
        azimuth, elevation = directions_from_rays(rays)
        u, v = self.project(azimuth, elevation)
        valid = np.isfinite(u) & np.isfinite(v)
        return np.stack([u, v], axis=1), valid

    def unproject_pixels(self, uv: ArrayLike) -> NDArray[np.float64]:
        """(N, 3) unit camera-frame rays seen at pixels (u, v)."""
        p = np.atleast_2d(np.asarray(uv, dtype=float))
        return rays_from_directions(*self.unproject(p[:, 0], p[:, 1]))

    def radius_px(self, elevation_rad: ArrayLike) -> NDArray:
        """Image radius of an elevation, in pixels of fx (fx == fy in our rigs)."""
        e = np.asarray(elevation_rad, dtype=float)
        return self.fx * np.cos(e) / (self.xi - np.sin(e))

    @classmethod
    def from_camera_info(
        cls, width: int, height: int, distortion_model: str, d: ArrayLike, k: ArrayLike
    ) -> UnifiedCamera:
        """Build from the fields of sensor_msgs/CameraInfo (passed as plain values)."""
        if distortion_model != "unified":
            raise CameraModelError(f"distortion_model must be 'unified', got {distortion_model!r}")
        d_values = [float(v) for v in np.asarray(d, dtype=float).reshape(-1)]
        k_values = [float(v) for v in np.asarray(k, dtype=float).reshape(-1)]
        if len(d_values) < 1 or len(k_values) != 9:
            raise CameraModelError(f"expected d=[xi] and 9 values of k, got d={d_values}, k of length {len(k_values)}")
        return cls(
            width_px=int(width),
            height_px=int(height),
            xi=d_values[0],
            fx=k_values[0],
            fy=k_values[4],
            cx=k_values[2],
            cy=k_values[5],
        )


DEFAULT_CAMERA = UnifiedCamera(width_px=640, height_px=640, xi=0.9, fx=170.0, fy=170.0, cx=320.0, cy=320.0)
