"""Colour-blob detector: omnidirectional images to slice measurements (no ROS here).

detector = Detector(load_config(DetectorConfig, path, "detector"))
slices = detector.detect(image, camera, encoding="rgb8")   # list[SliceMeasurement]
"""

from objslam_detector.config import BlobConfig, ColorConfig, DetectorConfig, PanoramaConfig
from objslam_detector.detector import Detector
from objslam_detector.errors import DetectorInputError
from objslam_detector.images import as_color_image, decode_compressed, image_from_buffer
from objslam_detector.overlay import draw_slices

__all__ = [
    "BlobConfig",
    "ColorConfig",
    "Detector",
    "DetectorConfig",
    "DetectorInputError",
    "PanoramaConfig",
    "as_color_image",
    "decode_compressed",
    "draw_slices",
    "image_from_buffer",
]
