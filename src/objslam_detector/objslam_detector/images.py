"""Turning what arrives on an image topic into a checked 8-bit colour array.

Everything that cannot be used raises DetectorInputError with one reason (errors.py):
the node skips that frame, warns and counts it.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from objslam_common.cameras import CameraModel
from objslam_detector.errors import (
    CORRUPT_COMPRESSED,
    EMPTY_IMAGE,
    SIZE_MISMATCH,
    UNSUPPORTED_ENCODING,
    DetectorInputError,
)

# encoding -> (channels, channel order of the colour planes)
ENCODINGS: dict[str, tuple[int, str]] = {
    "rgb8": (3, "rgb"),
    "bgr8": (3, "bgr"),
    "rgba8": (4, "rgb"),
    "bgra8": (4, "bgr"),
    "mono8": (1, "mono"),
}
COMPRESSED_FORMATS = ("png", "jpeg", "jpg")


class ColorImage(NamedTuple):
    """A checked (H, W, 3) uint8 image and the order of its colour planes ("rgb" or "bgr")."""

    pixels: NDArray[np.uint8]
    order: str


def as_color_image(image: NDArray, encoding: str = "rgb8") -> ColorImage:
    """Check an image array against its encoding and make it three 8-bit colour planes.

    Monochrome images are accepted but carry no colour, so no class matches them.
    """
    if encoding not in ENCODINGS:
        raise DetectorInputError(
            f"unsupported image encoding {encoding!r} (supported: {', '.join(ENCODINGS)})", reason=UNSUPPORTED_ENCODING
        )
    image = np.asarray(image)
    if image.size == 0:
        raise DetectorInputError(f"empty image (shape {image.shape})", reason=EMPTY_IMAGE)
    if image.dtype != np.uint8:
        raise DetectorInputError(
            f"image must be 8-bit for {encoding}, got dtype {image.dtype}", reason=UNSUPPORTED_ENCODING
        )
    channels, order = ENCODINGS[encoding]
    shape_ok = image.ndim == 2 if channels == 1 else image.ndim == 3 and image.shape[2] == channels
    if channels == 1 and image.ndim == 3 and image.shape[2] == 1:
        image, shape_ok = image[:, :, 0], True
    if not shape_ok:
        raise DetectorInputError(
            f"image of shape {image.shape} does not hold {encoding} pixels ({channels} channels)", reason=SIZE_MISMATCH
        )
    if channels == 1:
        return ColorImage(cv2.cvtColor(image, cv2.COLOR_GRAY2RGB), "rgb")
    if channels == 4:
        return ColorImage(np.ascontiguousarray(image[:, :, :3]), order)
    return ColorImage(image, order)


def check_size(image: NDArray, camera: CameraModel) -> None:
    """The image must be as large as its calibration says."""
    height, width = image.shape[:2]
    if (width, height) != (camera.width_px, camera.height_px):
        raise DetectorInputError(
            f"image is {width}x{height} px but the camera calibration is {camera.width_px}x{camera.height_px} px",
            reason=SIZE_MISMATCH,
        )


def image_from_buffer(
    data: bytes | bytearray | memoryview | NDArray, width: int, height: int, encoding: str, step: int
) -> NDArray[np.uint8]:
    """View the ``data`` of a sensor_msgs/Image (``step`` bytes per row) as an array."""
    if encoding not in ENCODINGS:
        raise DetectorInputError(
            f"unsupported image encoding {encoding!r} (supported: {', '.join(ENCODINGS)})", reason=UNSUPPORTED_ENCODING
        )
    if width <= 0 or height <= 0:
        raise DetectorInputError(f"empty image ({width}x{height} px)", reason=EMPTY_IMAGE)
    channels = ENCODINGS[encoding][0]
    if step < width * channels:
        raise DetectorInputError(
            f"row step {step} is shorter than {width} px of {encoding} ({width * channels} bytes)",
            reason=SIZE_MISMATCH,
        )
    buffer = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.reshape(-1)
    if buffer.size < step * height:
        raise DetectorInputError(
            f"image data holds {buffer.size} bytes, {width}x{height} {encoding} needs {step * height}",
            reason=SIZE_MISMATCH,
        )
    rows = buffer[: step * height].reshape(height, step)[:, : width * channels]
    return rows.reshape(height, width, channels) if channels > 1 else rows


def decode_compressed(
    data: bytes | bytearray | memoryview | NDArray, compressed_format: str = ""
) -> tuple[NDArray[np.uint8], str]:
    """Decode the ``data`` of a sensor_msgs/CompressedImage; returns (pixels, encoding).

    ``compressed_format`` is the message's ``format`` string (e.g. "png", "jpeg", "rgb8; jpeg compressed bgr8");
    an empty string lets the data decide.
    """
    fmt = compressed_format.lower()
    if fmt and not any(name in fmt for name in COMPRESSED_FORMATS):
        raise DetectorInputError(
            f"unsupported compressed format {compressed_format!r} (supported: png, jpeg)", reason=UNSUPPORTED_ENCODING
        )
    what = compressed_format or "unknown format"
    buffer = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.reshape(-1)
    if buffer.size == 0:
        raise DetectorInputError("empty compressed image", reason=EMPTY_IMAGE)
    try:
        pixels = cv2.imdecode(buffer, cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise DetectorInputError(f"cannot decode compressed image ({what}): {exc}", reason=CORRUPT_COMPRESSED) from exc
    if pixels is None or pixels.size == 0:
        raise DetectorInputError(
            f"cannot decode compressed image ({what}): corrupt or truncated data", reason=CORRUPT_COMPRESSED
        )
    if pixels.dtype != np.uint8:
        raise DetectorInputError(f"compressed image decodes to {pixels.dtype}, need 8-bit", reason=UNSUPPORTED_ENCODING)
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    encoding = {1: "mono8", 3: "bgr8", 4: "bgra8"}.get(channels)
    if encoding is None:
        raise DetectorInputError(
            f"compressed image decodes to {channels} channels, need 1, 3 or 4", reason=UNSUPPORTED_ENCODING
        )
    return (pixels[:, :, 0] if pixels.ndim == 3 and channels == 1 else pixels), encoding


def decode_image_message(msg: Any) -> tuple[NDArray[np.uint8], str]:
    """Pixels and encoding of a sensor_msgs/Image or sensor_msgs/CompressedImage (any object
    with its fields: an rclpy message in the node, a rosbags one in ``objslam map``)."""
    if hasattr(msg, "format"):  # only CompressedImage has it
        return decode_compressed(msg.data, msg.format)
    return image_from_buffer(msg.data, msg.width, msg.height, msg.encoding, msg.step), msg.encoding
