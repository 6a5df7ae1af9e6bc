"""Errors of the detector library."""


class DetectorInputError(ValueError):
    """An image the detector cannot use (bad encoding, size, corrupt data); the node skips it."""
