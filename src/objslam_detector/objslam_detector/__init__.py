"""Colour-blob detector: omnidirectional images to slice measurements (no ROS here).

detector = Detector(load_config(DetectorConfig, path, "detector"))
slices = detector.detect(image, camera, encoding="rgb8")   # list[DetectedSlice]
"""

from objslam_detector.config import BlobConfig, ColorConfig, DetectorConfig, PanoramaConfig
from objslam_detector.detector import Detector
from objslam_detector.errors import DetectorInputError
from objslam_detector.images import as_color_image, decode_compressed, image_from_buffer
from objslam_detector.overlay import draw_slices
from objslam_detector.slices import DetectedSlice

__all__ = [
    "BlobConfig",
    "ColorConfig",
    "DetectedSlice",
    "Detector",
    "DetectorConfig",
    "DetectorInputError",
    "PanoramaConfig",
    "as_color_image",
    "decode_compressed",
    "draw_slices",
    "image_from_buffer",
]
