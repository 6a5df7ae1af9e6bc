"""Unwarping a camera's image into an azimuth x elevation panorama (any camera model).

Columns are azimuth (left edge of column 0 at -pi, increasing counter-clockwise), rows
are elevation (top row highest). A vertical cylinder's silhouette edges are vertical
lines in space, hence columns of the panorama: its angular width and edge elevations
are read off a blob's extreme columns and rows. The remap tables are built once per
calibration. The panorama always spans every azimuth: a perspective or fisheye camera
fills the part it sees (``inside``) and leaves the rest black, which the detector reads as
the edge of the view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from objslam_common.cameras import CameraModel, UnifiedCamera
from objslam_common.geometry import wrap_angle
from objslam_detector.config import PanoramaConfig

# Stay this far below the model's limit elevation asin(xi), where radii blow up.
_LIMIT_MARGIN_RAD = math.radians(1.0)


@dataclass(frozen=True, eq=False)
class Panorama:
    """Sampling grid and remap tables of one calibration."""

    camera: CameraModel
    azimuth_step_rad: float
    elevation_step_rad: float
    top_elevation_rad: float  # upper edge of row 0
    rows: int
    cols: int
    map1: NDArray = field(repr=False)
    map2: NDArray = field(repr=False)
    inside: NDArray[np.bool_] = field(repr=False)  # panorama pixels that sample the image

    @classmethod
    def build(cls, camera: CameraModel, config: PanoramaConfig) -> Panorama:
        cols = max(8, round(360.0 / config.azimuth_resolution_deg))
        az_step = 2.0 * math.pi / cols
        el_step = math.radians(config.elevation_resolution_deg)
        bottom = math.radians(config.min_elevation_deg)
        top = min(math.radians(config.max_elevation_deg), highest_visible_elevation(camera))
        rows = max(1, math.ceil((top - bottom) / el_step))
        top = bottom + rows * el_step
        azimuth = -math.pi + (np.arange(cols) + 0.5) * az_step
        elevation = top - (np.arange(rows) + 0.5) * el_step
        u, v = camera.project(azimuth[None, :], elevation[:, None])
        inside = np.isfinite(u) & (u >= 0) & (v >= 0) & (u <= camera.width_px - 1) & (v <= camera.height_px - 1)
        # Outside pixels sample far off the image and come out black (no class).
        u = np.where(inside, u, -10.0).astype(np.float32)
        v = np.where(inside, v, -10.0).astype(np.float32)
        map1, map2 = cv2.convertMaps(u, v, cv2.CV_16SC2)
        return cls(
            camera=camera,
            azimuth_step_rad=az_step,
            elevation_step_rad=el_step,
            top_elevation_rad=top,
            rows=rows,
            cols=cols,
            map1=map1,
            map2=map2,
            inside=inside,
        )

    def unwarp(self, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The panorama of an image of this calibration (any channel count)."""
        return cv2.remap(image, self.map1, self.map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def column_azimuth(self, col_edge: float | NDArray) -> float | NDArray:
        """Azimuth of a column edge coordinate (0 = left edge of column 0), unwrapped."""
        return -math.pi + np.asarray(col_edge, dtype=float) * self.azimuth_step_rad

    def row_elevation(self, row_edge: float | NDArray) -> float | NDArray:
        """Elevation of a row edge coordinate (0 = top edge of row 0)."""
        return self.top_elevation_rad - np.asarray(row_edge, dtype=float) * self.elevation_step_rad

    def column_of_azimuth(self, azimuth_rad: float | NDArray) -> float | NDArray:
        """Column edge coordinate of an azimuth, in [0, cols)."""
        return (wrap_angle(azimuth_rad) + math.pi) / self.azimuth_step_rad

    def row_of_elevation(self, elevation_rad: float | NDArray) -> NDArray:
        return (self.top_elevation_rad - np.asarray(elevation_rad, dtype=float)) / self.elevation_step_rad


def highest_visible_elevation(camera: CameraModel) -> float:
    """Highest elevation that still lands in the image or projects at all.

    Omnidirectional: at the image's farthest corner, below the model's limit. Other models:
    the highest direction seen along the image's border (their view is a cone around the
    optical axis, so the border holds its extremes).
    """
    if isinstance(camera, UnifiedCamera):
        corners_u = np.array([0.0, camera.width_px - 1.0, 0.0, camera.width_px - 1.0])
        corners_v = np.array([0.0, 0.0, camera.height_px - 1.0, camera.height_px - 1.0])
        _az, elevation = camera.unproject(corners_u, corners_v)
        return float(min(np.max(elevation), camera.max_elevation_rad - _LIMIT_MARGIN_RAD))
    w, h = camera.width_px - 1.0, camera.height_px - 1.0
    t = np.linspace(0.0, 1.0, 200)
    u = np.concatenate([t * w, t * w, np.zeros_like(t), np.full_like(t, w)])
    v = np.concatenate([np.zeros_like(t), np.full_like(t, h), t * h, t * h])
    _az, elevation = camera.unproject(u, v)
    return float(min(np.nanmax(elevation), math.pi / 2 - _LIMIT_MARGIN_RAD))
