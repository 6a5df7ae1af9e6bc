"""Messages to records and back, one conversion per message type.

The readers take any object with the message's fields: an rclpy message in the nodes, a
message deserialized by ``rosbags`` in the one-process path (``objslam map``), so both
paths turn the same message into the same record. The writers build rclpy messages.

- nav_msgs/Odometry -> :class:`OdometrySample` (:func:`odometry_sample`)
- objslam_msgs/Slice <-> :class:`SliceMeasurement` (:func:`slice_measurement`, :func:`slice_to_msg`)
- objslam_msgs/SliceArray <-> :class:`ImageSlices` (:func:`image_slices`, :func:`slice_array_to_msg`)
- sensor_msgs/CameraInfo -> a camera model (:func:`camera_from_info`)
"""

from __future__ import annotations

import math
from typing import Any

from builtin_interfaces.msg import Time
from std_msgs.msg import Header

from objslam_common.cameras import CameraModel, camera_from_calibration
from objslam_common.errors import MessageError, RecordError
from objslam_common.geometry import yaw_from_quaternion
from objslam_common.records import ImageSlices, OdometrySample, SliceMeasurement
from objslam_msgs.msg import Slice, SliceArray

QUATERNION_NORM_TOLERANCE = 1e-3


def stamp_ns(header: Any) -> int:
    """A std_msgs/Header's stamp in integer nanoseconds."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def time_from_ns(stamp_ns: int) -> Time:
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def odometry_sample(msg: Any) -> OdometrySample:
    """The pose of a nav_msgs/Odometry; MessageError for a pose that is not finite or an
    orientation that is not a unit quaternion."""
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


def slice_measurement(msg: Any) -> SliceMeasurement:
    """The record of an objslam_msgs/Slice; RecordError for impossible values."""
    return SliceMeasurement(
        label=msg.label,
        confidence=float(msg.confidence),
        bearing_rad=float(msg.bearing),
        angular_width_rad=float(msg.angular_width),
        elevation_bottom_rad=float(msg.elevation_bottom),
        elevation_top_rad=float(msg.elevation_top),
        radius_inner_px=float(msg.radius_inner_px),
        radius_outer_px=float(msg.radius_outer_px),
        angle_start_rad=float(msg.angle_start_rad),
        angle_end_rad=float(msg.angle_end_rad),
        pixel_count=int(msg.pixel_count),
        truncated=bool(msg.truncated),
        cut_edges=int(msg.cut_edges),
    )


def slice_to_msg(record: SliceMeasurement) -> Slice:
    return Slice(
        label=record.label,
        confidence=record.confidence,
        bearing=record.bearing_rad,
        angular_width=record.angular_width_rad,
        elevation_bottom=record.elevation_bottom_rad,
        elevation_top=record.elevation_top_rad,
        radius_inner_px=record.radius_inner_px,
        radius_outer_px=record.radius_outer_px,
        angle_start_rad=record.angle_start_rad,
        angle_end_rad=record.angle_end_rad,
        pixel_count=record.pixel_count,
        truncated=record.truncated,
        cut_edges=record.cut_edges,
    )


def image_slices(msg: Any) -> tuple[ImageSlices, int]:
    """The image's slices from an objslam_msgs/SliceArray, and how many were invalid and left out."""
    slices = []
    invalid = 0
    for s in msg.slices:
        try:
            slices.append(slice_measurement(s))
        except RecordError:
            invalid += 1
    return ImageSlices(stamp_ns(msg.header), tuple(slices)), invalid


def slice_array_to_msg(image: ImageSlices, frame_id: str = "") -> SliceArray:
    header = Header(stamp=time_from_ns(image.stamp_ns), frame_id=frame_id)
    return SliceArray(header=header, slices=[slice_to_msg(s) for s in image.slices])


def camera_from_info(msg: Any) -> CameraModel:
    """The camera model of a sensor_msgs/CameraInfo (by its distortion_model); CameraModelError
    if no model fits it."""
    return camera_from_calibration(msg.width, msg.height, msg.distortion_model, msg.d, msg.k)
