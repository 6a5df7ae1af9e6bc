"""Errors of the detector library."""

from objslam_common.errors import ObjslamError

# Why a frame cannot be used, short and fixed: the node counts and rate-limits skipped
# frames by these. The message says the details, which vary from frame to frame.
UNSUPPORTED_ENCODING = "unsupported encoding"  # pixel encoding, compressed format or bit depth
SIZE_MISMATCH = "size mismatch"  # data vs the size the message declares, or image vs calibration
CORRUPT_COMPRESSED = "corrupt compressed data"
EMPTY_IMAGE = "empty image"


class DetectorError(ObjslamError):
    """Settings or inputs the detector cannot work with."""


class DetectorInputError(DetectorError, ValueError):
    """An image the detector cannot use (bad encoding, size, corrupt data); the node skips it.

    ``reason`` is one of the constants above; ``str(error)`` is the one-line detail.
    """

    def __init__(self, message: str, *, reason: str) -> None:
        super().__init__(message)
        self.reason = reason
