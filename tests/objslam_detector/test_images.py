"""Bad input is refused with one clear DetectorInputError; compressed images decode."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from objslam_common.cameras.unified import DEFAULT_CAMERA
from objslam_detector import Detector, DetectorInputError, decode_compressed, image_from_buffer
from objslam_detector.errors import CORRUPT_COMPRESSED, EMPTY_IMAGE, SIZE_MISMATCH, UNSUPPORTED_ENCODING
from tests.objslam_detector.conftest import place, render, scene_of

DETECTOR = Detector()


@pytest.fixture(scope="module")
def frame() -> np.ndarray:
    return render(scene_of((place(0, "blue", 2.5, 60.0), place(1, "red", 3.0, -100.0))))


@pytest.mark.parametrize(
    ("image", "encoding", "message", "reason"),
    [
        (np.zeros((640, 640, 3), np.uint8), "yuv422", "unsupported image encoding 'yuv422'", UNSUPPORTED_ENCODING),
        (np.zeros((640, 640, 3), np.uint16), "rgb8", "must be 8-bit", UNSUPPORTED_ENCODING),
        (np.zeros((640, 640, 4), np.uint8), "rgb8", "does not hold rgb8 pixels", SIZE_MISMATCH),
        (np.zeros((640, 640), np.uint8), "bgr8", "does not hold bgr8 pixels", SIZE_MISMATCH),
        (np.zeros((0, 640, 3), np.uint8), "rgb8", "empty image", EMPTY_IMAGE),
        (
            np.zeros((480, 640, 3), np.uint8),
            "rgb8",
            "image is 640x480 px but the camera calibration is 640x640 px",
            SIZE_MISMATCH,
        ),
    ],
)
def test_unusable_images_raise_one_clear_error(image, encoding, message, reason):
    with pytest.raises(DetectorInputError, match=message) as info:
        DETECTOR.detect(image, DEFAULT_CAMERA, encoding)
    assert "\n" not in str(info.value)
    assert info.value.reason == reason  # what the node counts and rate-limits by


def test_four_channel_encodings_are_accepted(frame):
    rgba = np.dstack([frame, np.full(frame.shape[:2], 255, np.uint8)])
    bgra = np.ascontiguousarray(rgba[:, :, [2, 1, 0, 3]])
    expected = DETECTOR.detect(frame, DEFAULT_CAMERA)
    assert DETECTOR.detect(rgba, DEFAULT_CAMERA, "rgba8") == expected
    assert DETECTOR.detect(bgra, DEFAULT_CAMERA, "bgra8") == expected


def test_image_from_buffer_honours_row_padding(frame):
    step = 640 * 3 + 16
    padded = np.zeros((640, step), np.uint8)
    padded[:, : 640 * 3] = frame.reshape(640, -1)
    pixels = image_from_buffer(padded.tobytes(), 640, 640, "rgb8", step)
    assert np.array_equal(pixels, frame)


@pytest.mark.parametrize(
    ("size", "step", "message"),
    [(100, 640 * 3, "image data holds 100 bytes"), (640 * 640 * 3, 100, "row step 100 is shorter")],
)
def test_image_from_buffer_refuses_inconsistent_messages(size, step, message):
    with pytest.raises(DetectorInputError, match=message) as info:
        image_from_buffer(bytes(size), 640, 640, "rgb8", step)
    assert info.value.reason == SIZE_MISMATCH


def test_png_decodes_exactly(frame):
    ok, data = cv2.imencode(".png", cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    assert ok
    pixels, encoding = decode_compressed(data.tobytes(), "rgb8; png compressed bgr8")
    assert encoding == "bgr8" and np.array_equal(pixels[:, :, ::-1], frame)
    assert DETECTOR.detect(pixels, DEFAULT_CAMERA, encoding) == DETECTOR.detect(frame, DEFAULT_CAMERA)


def test_jpeg_decodes_and_still_detects(frame):
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(frame, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert ok
    pixels, encoding = decode_compressed(bytes(data), "jpeg")
    from_jpeg = sorted(DETECTOR.detect(pixels, DEFAULT_CAMERA, encoding), key=lambda s: s.label)
    from_raw = sorted(DETECTOR.detect(frame, DEFAULT_CAMERA), key=lambda s: s.label)
    assert [s.label for s in from_jpeg] == [s.label for s in from_raw]
    for a, b in zip(from_jpeg, from_raw, strict=True):
        assert abs(a.bearing_rad - b.bearing_rad) < np.radians(0.2)


def test_mono_png_decodes_as_mono8():
    _ok, data = cv2.imencode(".png", np.full((8, 8), 7, np.uint8))
    pixels, encoding = decode_compressed(data, "png")
    assert encoding == "mono8" and pixels.shape == (8, 8)


@pytest.mark.parametrize(
    ("data", "fmt", "message", "reason"),
    [
        (b"\x89PNG\r\n\x1a\n" + b"\x00" * 40, "png", "cannot decode compressed image \\(png\\)", CORRUPT_COMPRESSED),
        (b"not an image at all", "jpeg", "cannot decode compressed image \\(jpeg\\)", CORRUPT_COMPRESSED),
        (b"", "png", "empty compressed image", EMPTY_IMAGE),
        (b"\x00" * 10, "tiff", "unsupported compressed format 'tiff'", UNSUPPORTED_ENCODING),
    ],
)
def test_corrupt_compressed_data_raises(data, fmt, message, reason):
    with pytest.raises(DetectorInputError, match=message) as info:
        decode_compressed(data, fmt)
    assert info.value.reason == reason


def test_truncated_jpeg_is_refused_or_decodes_to_an_image(frame):
    _ok, data = cv2.imencode(".jpg", frame)
    # A cut JPEG either fails to decode or decodes (grey-filled): it must never crash.
    try:
        pixels, _ = decode_compressed(bytes(data[: len(data) // 3]), "jpeg")
    except DetectorInputError:
        return
    assert pixels.shape[:2] == frame.shape[:2]
