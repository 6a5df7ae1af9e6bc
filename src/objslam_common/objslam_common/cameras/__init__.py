"""Camera models: pixels to directions in the camera frame and back."""

from objslam_common.cameras.unified import DEFAULT_CAMERA, UnifiedCamera

__all__ = ["DEFAULT_CAMERA", "UnifiedCamera"]
