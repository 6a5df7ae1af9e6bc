"""Camera models: pixels to unit rays in the camera frame and back.

Every model has ``distortion_model``, ``width_px``, ``height_px``, ``project_rays(rays) ->
(uv, valid)`` and ``unproject_pixels(uv) -> rays``; :func:`camera_from_calibration` picks
one by ``CameraInfo.distortion_model``. The mapper measures directions, not pixels, so it
needs no camera Jacobian: only the detector touches pixels.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from objslam_common.cameras.perspective import FisheyeCamera, PinholeCamera
from objslam_common.cameras.tilted import TiltedCamera, level_view
from objslam_common.cameras.unified import DEFAULT_CAMERA, UnifiedCamera
from objslam_common.errors import CameraModelError

CameraModel = UnifiedCamera | PinholeCamera | FisheyeCamera | TiltedCamera
DISTORTION_MODELS = ("unified", "plumb_bob", "rational_polynomial", "equidistant")


def camera_from_calibration(
    width_px: int, height_px: int, distortion_model: str, d: Sequence[float], k: Sequence[float]
) -> CameraModel:
    """The model of a sensor_msgs/CameraInfo's fields; CameraModelError in one line if none fits."""
    try:
        d_values = tuple(float(v) for v in np.asarray(d, dtype=float).reshape(-1))
        k_values = [float(v) for v in np.asarray(k, dtype=float).reshape(-1)]
    except (TypeError, ValueError) as exc:
        raise CameraModelError(f"camera info: d and k must be numbers ({exc})") from exc
    if distortion_model not in DISTORTION_MODELS:
        raise CameraModelError(
            f"unknown distortion_model {distortion_model!r} (supported: {', '.join(DISTORTION_MODELS)})"
        )
    if len(k_values) != 9:
        raise CameraModelError(f"{distortion_model}: k must hold 9 values, got {len(k_values)}")
    if distortion_model == "unified":
        return UnifiedCamera.from_camera_info(width_px, height_px, distortion_model, d_values, k_values)
    w, h = int(width_px), int(height_px)
    fx, fy, cx, cy = k_values[0], k_values[4], k_values[2], k_values[5]
    if distortion_model == "equidistant":
        return FisheyeCamera(width_px=w, height_px=h, fx=fx, fy=fy, cx=cx, cy=cy, d=d_values)
    return PinholeCamera(
        distortion_model=distortion_model, width_px=w, height_px=h, fx=fx, fy=fy, cx=cx, cy=cy, d=d_values
    )


def camera_info_fields(camera: CameraModel) -> tuple[str, tuple[float, ...]]:
    """(distortion_model, d) of a model as sensor_msgs/CameraInfo carries them."""
    if isinstance(camera, TiltedCamera):
        return camera_info_fields(camera.lens)
    if isinstance(camera, UnifiedCamera):
        return "unified", (camera.xi,)
    return camera.distortion_model, tuple(camera.d)


# The simulator's cameras (`objslam sim --camera`): the bundled omnidirectional one, a
# common 640x480 perspective camera about 90 degrees across with a little barrel
# distortion, and a fisheye of about 180 degrees.
PRESET_CAMERAS: dict[str, CameraModel] = {
    "omni": DEFAULT_CAMERA,
    "pinhole": PinholeCamera(
        distortion_model="plumb_bob", width_px=640, height_px=480, fx=320.0, fy=320.0, cx=319.5, cy=239.5,
        d=(-0.05, 0.01, 0.0, 0.0, 0.0),
    ),
    "fisheye": FisheyeCamera(
        width_px=640, height_px=640, fx=200.0, fy=200.0, cx=319.5, cy=319.5, d=(0.02, -0.005, 0.0, 0.0)
    ),
}  # fmt: skip


__all__ = [
    "DEFAULT_CAMERA",
    "DISTORTION_MODELS",
    "PRESET_CAMERAS",
    "CameraModel",
    "CameraModelError",
    "FisheyeCamera",
    "PinholeCamera",
    "TiltedCamera",
    "UnifiedCamera",
    "camera_from_calibration",
    "camera_info_fields",
    "level_view",
]
