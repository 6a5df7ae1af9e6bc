"""Directions in the camera frame (REP 103: x forward, y left, z up) as unit rays or angles.

Every camera model maps pixels to unit rays of this frame and back; azimuth (counter-
clockwise from x) and elevation (above the x-y plane) are the same directions as angles,
the form the slices are measured in.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.geometry import wrap_angle


def rays_from_directions(azimuth_rad: ArrayLike, elevation_rad: ArrayLike) -> NDArray[np.float64]:
    """(N, 3) unit rays of the camera frame for azimuths and elevations."""
    a = np.asarray(azimuth_rad, dtype=float).reshape(-1)
    e = np.asarray(elevation_rad, dtype=float).reshape(-1)
    ce = np.cos(e)
    return np.stack([ce * np.cos(a), ce * np.sin(a), np.sin(e)], axis=1)


def directions_from_rays(rays: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Azimuth and elevation (rad) of (N, 3) rays of the camera frame (any length)."""
    r = np.atleast_2d(np.asarray(rays, dtype=float))
    return wrap_angle(np.arctan2(r[:, 1], r[:, 0])), np.arctan2(r[:, 2], np.hypot(r[:, 0], r[:, 1]))


def optical_from_camera(rays: ArrayLike) -> NDArray[np.float64]:
    """Rays of the camera frame in OpenCV's optical frame, (X, Y, Z) = (-y, -z, x): the optical
    axis is the camera frame's x axis (docs/design.md, "Cameras and the mount")."""
    r = np.atleast_2d(np.asarray(rays, dtype=float))
    return np.stack([-r[:, 1], -r[:, 2], r[:, 0]], axis=1)


def camera_from_optical(rays: ArrayLike) -> NDArray[np.float64]:
    """The inverse of :func:`optical_from_camera`."""
    r = np.atleast_2d(np.asarray(rays, dtype=float))
    return np.stack([r[:, 2], -r[:, 0], -r[:, 1]], axis=1)


def normalized(rays: NDArray[np.float64]) -> NDArray[np.float64]:
    with np.errstate(invalid="ignore", divide="ignore"):
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def project_directions(project_rays, azimuth_rad: ArrayLike, elevation_rad: ArrayLike) -> tuple[NDArray, NDArray]:
    """Pixel (u, v) of directions (broadcast) through a model's ``project_rays``; NaN where not seen."""
    a, e = np.broadcast_arrays(np.asarray(azimuth_rad, dtype=float), np.asarray(elevation_rad, dtype=float))
    uv, valid = project_rays(rays_from_directions(a, e))
    uv = np.where(valid[:, None], uv, np.nan)
    return uv[:, 0].reshape(a.shape), uv[:, 1].reshape(a.shape)


def unproject_directions(unproject_pixels, u_px: ArrayLike, v_px: ArrayLike) -> tuple[NDArray, NDArray]:
    """Direction (azimuth, elevation) seen at pixels (u, v) (broadcast) through a model's ``unproject_pixels``."""
    u, v = np.broadcast_arrays(np.asarray(u_px, dtype=float), np.asarray(v_px, dtype=float))
    azimuth, elevation = directions_from_rays(unproject_pixels(np.stack([u.ravel(), v.ravel()], axis=1)))
    return azimuth.reshape(u.shape), elevation.reshape(u.shape)
