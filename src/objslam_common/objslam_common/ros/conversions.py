"""Messages in: nav_msgs/Odometry and objslam_msgs/SliceArray become core records, once."""

from __future__ import annotations

import math

from nav_msgs.msg import Odometry

from objslam_common.geometry import yaw_from_quaternion
from objslam_common.records import ImageSlices, OdometrySample, RecordError, SliceMeasurement
from objslam_msgs.msg import SliceArray

QUATERNION_NORM_TOLERANCE = 1e-3


class MessageError(ValueError):
    """A message that cannot become a record (the node counts and drops it).

    ``kind`` names the problem without its numbers, so that warnings can be rate-limited
    per kind of problem.
    """

    def __init__(self, kind: str, detail: str = ""):
        super().__init__(f"{kind} ({detail})" if detail else kind)
        self.kind = kind


def stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def odometry_sample(msg: Odometry) -> OdometrySample:
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    values = (p.x, p.y, q.x, q.y, q.z, q.w)
    if not all(math.isfinite(v) for v in values):
        raise MessageError("odometry pose is not finite")
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise MessageError("odometry orientation is not a unit quaternion", f"norm {norm:.4f}")
    try:
        return OdometrySample(stamp_ns(msg.header), float(p.x), float(p.y), yaw_from_quaternion(q.x, q.y, q.z, q.w))
    except RecordError as exc:
        raise MessageError("invalid odometry", str(exc)) from exc


def image_slices(msg: SliceArray) -> tuple[ImageSlices, int]:
    """The image's slices, and how many were invalid and left out."""
    slices = []
    invalid = 0
    for s in msg.slices:
        try:
            slices.append(
                SliceMeasurement(
                    label=s.label,
                    confidence=float(s.confidence),
                    bearing_rad=float(s.bearing),
                    angular_width_rad=float(s.angular_width),
                    elevation_bottom_rad=float(s.elevation_bottom),
                    elevation_top_rad=float(s.elevation_top),
                )
            )
        except RecordError:
            invalid += 1
    return ImageSlices(stamp_ns(msg.header), tuple(slices)), invalid
