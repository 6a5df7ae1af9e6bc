"""Debug overlay: each slice's image sector outlined and labelled on the original image."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import cv2
import numpy as np
from numpy.typing import NDArray

from objslam_common.cameras import CameraModel
from objslam_common.records import SliceMeasurement
from objslam_detector.images import as_color_image

_DEFAULT_RGB = (255, 255, 255)
_ARC_POINTS = 24


def sector_outline(camera: CameraModel, sl: SliceMeasurement, points_per_arc: int = _ARC_POINTS) -> NDArray[np.int32]:
    """Closed outline (N, 2) in pixels: the lower arc, then the upper arc backwards."""
    half = 0.5 * sl.angular_width_rad
    azimuth = np.linspace(sl.bearing_rad - half, sl.bearing_rad + half, points_per_arc)
    u_lo, v_lo = camera.project(azimuth, np.full_like(azimuth, sl.elevation_bottom_rad))
    u_hi, v_hi = camera.project(azimuth[::-1], np.full_like(azimuth, sl.elevation_top_rad))
    points = np.stack([np.concatenate([u_lo, u_hi]), np.concatenate([v_lo, v_hi])], axis=1)
    points = points[np.all(np.isfinite(points), axis=1)]
    # Sub-pixel outline: cv2 draws with 4 fractional bits.
    return np.rint(points * 16.0).astype(np.int32)


def draw_slices(
    image: NDArray,
    slices: Iterable[SliceMeasurement],
    camera: CameraModel,
    encoding: str = "rgb8",
    class_rgb: Mapping[str, tuple[int, int, int]] | None = None,
) -> NDArray[np.uint8]:
    """A copy of the image as (H, W, 3) RGB with each slice outlined in its class colour and labelled.

    Truncated slices (probably cut short by an occluder or the view) get a thin outline.
    """
    color = as_color_image(image, encoding)
    canvas = color.pixels if color.order == "rgb" else cv2.cvtColor(color.pixels, cv2.COLOR_BGR2RGB)
    canvas = np.ascontiguousarray(canvas.copy())
    class_rgb = class_rgb or {}
    scale = max(0.35, min(canvas.shape[:2]) / 1600.0)
    for sl in slices:
        outline = sector_outline(camera, sl)
        if len(outline) < 2:
            continue
        rgb = tuple(int(c) for c in class_rgb.get(sl.label, _DEFAULT_RGB))
        thickness = 1 if sl.truncated else 2
        cv2.polylines(canvas, [outline], True, (0, 0, 0), thickness + 2, cv2.LINE_AA, shift=4)
        cv2.polylines(canvas, [outline], True, rgb, thickness, cv2.LINE_AA, shift=4)
        u, v = camera.project(sl.bearing_rad, sl.elevation_top_rad)
        if np.isfinite(u) and np.isfinite(v):
            text = f"{sl.label} {sl.confidence:.2f}"
            org = (int(u) + 3, int(v) - 3)
            cv2.putText(canvas, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 3, cv2.LINE_AA)
            cv2.putText(canvas, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, rgb, 1, cv2.LINE_AA)
    return canvas
