"""Typed, immutable records that flow between the detector, the mapper and the tools.

Messages become these records at the edge, by one conversion per message type
(:mod:`objslam_common.ros.conversions`); nothing below them knows about ROS. Stamps are
integer nanoseconds; angles are radians in the camera frame (docs/design.md, "Data
contract").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from objslam_common.errors import RecordError


def _require_finite(record: str, **values: float) -> None:
    for name, value in values.items():
        if not math.isfinite(value):
            raise RecordError(f"{record}: {name} must be finite, got {value}")


def _require_stamp(record: str, stamp_ns: int) -> None:
    if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, int):
        raise RecordError(f"{record}: stamp_ns must be an integer number of nanoseconds, got {stamp_ns!r}")


@dataclass(frozen=True)
class OdometrySample:
    """One wheel-odometry pose odom_T_base at a stamp (the pose of ``/odom``)."""

    stamp_ns: int
    x_m: float
    y_m: float
    theta_rad: float

    def __post_init__(self) -> None:
        _require_stamp("OdometrySample", self.stamp_ns)
        _require_finite("OdometrySample", x_m=self.x_m, y_m=self.y_m, theta_rad=self.theta_rad)


def as_float32(value: float) -> float:
    """``value`` as objslam_msgs/Slice carries it (float32), so a record is the same whether
    it came over the graph or straight from the detector. Beyond float32's range it is inf,
    which the record's check then refuses (so numpy's overflow warning is not wanted)."""
    with np.errstate(over="ignore"):
        return float(np.float32(value))


# Edges of a slice that the view cut off (``SliceMeasurement.cut_edges``, objslam_msgs/Slice):
# the image border, the body mask or the field of view hides the object beyond them, so each
# is a bound, not a measurement. Left is the counter-clockwise (larger azimuth) side.
CUT_LEFT, CUT_RIGHT, CUT_TOP, CUT_BOTTOM = 1, 2, 4, 8


@dataclass(frozen=True)
class SliceMeasurement:
    """One detection: the image slice around a blob of class ``label`` (objslam_msgs/Slice).

    ``bearing_rad`` is the azimuth of the slice centre, ``angular_width_rad`` its azimuth
    extent, ``elevation_bottom_rad``/``elevation_top_rad`` the elevations of the blob's
    lower and upper edges, all in the camera frame (azimuth counter-clockwise from the
    camera's forward axis, elevation above the horizontal). The ``*_px`` and ``angle_*``
    fields describe the sector in the original image, for overlays; ``truncated`` says
    the blob touches another class's blob or the edge of the view, so its extent is
    probably cut short (its confidence is lowered too); ``cut_edges`` (``CUT_*`` bits) says
    which edges the view itself cut off. The fields the message carries as
    float32 are rounded to float32 here. The stamp is the image's (:class:`ImageSlices`).
    """

    label: str
    confidence: float
    bearing_rad: float
    angular_width_rad: float
    elevation_bottom_rad: float
    elevation_top_rad: float
    radius_inner_px: float = 0.0
    radius_outer_px: float = 0.0
    angle_start_rad: float = 0.0
    angle_end_rad: float = 0.0
    pixel_count: int = 0
    truncated: bool = False
    cut_edges: int = 0

    def __post_init__(self) -> None:
        _require_finite(
            "SliceMeasurement",
            confidence=self.confidence,
            bearing_rad=self.bearing_rad,
            angular_width_rad=self.angular_width_rad,
            elevation_bottom_rad=self.elevation_bottom_rad,
            elevation_top_rad=self.elevation_top_rad,
        )
        if not self.label:
            raise RecordError("SliceMeasurement: label must not be empty")
        if not 0 <= self.cut_edges <= CUT_LEFT | CUT_RIGHT | CUT_TOP | CUT_BOTTOM:
            raise RecordError(
                f"SliceMeasurement: cut_edges must be a combination of the CUT_* bits, got {self.cut_edges}"
            )
        if self.angular_width_rad <= 0.0:
            raise RecordError(f"SliceMeasurement: angular_width_rad must be > 0, got {self.angular_width_rad}")
        if self.elevation_top_rad < self.elevation_bottom_rad:
            raise RecordError(
                f"SliceMeasurement: elevation_top_rad {self.elevation_top_rad} is below "
                f"elevation_bottom_rad {self.elevation_bottom_rad}"
            )
        for name in ("confidence", "radius_inner_px", "radius_outer_px", "angle_start_rad", "angle_end_rad"):
            object.__setattr__(self, name, as_float32(getattr(self, name)))


@dataclass(frozen=True)
class ImageSlices:
    """All detections of one image (a SliceArray); ``slices`` may be empty."""

    stamp_ns: int
    slices: tuple[SliceMeasurement, ...] = ()

    def __post_init__(self) -> None:
        _require_stamp("ImageSlices", self.stamp_ns)
        if not isinstance(self.slices, tuple):
            object.__setattr__(self, "slices", tuple(self.slices))
