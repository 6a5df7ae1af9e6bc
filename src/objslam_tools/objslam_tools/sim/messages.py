"""ROS 2 Jazzy messages of the data contract, built with the ``rosbags`` typestore (no rclpy).

This is the edge where plain arrays become message types; nothing else in the simulator
knows about them.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from rosbags.typesys import Stores, get_typestore

from objslam_common.cameras import CameraModel, camera_info_fields
from objslam_common.geometry import quaternion_from_rpy, quaternion_from_yaw
from objslam_common.mount import CameraMount

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
CAMERA_FRAME = "camera"
ODOM_FRAME = "odom"
BASE_FRAME = "base_link"
# For a planar robot z, roll and pitch are not measured: a huge variance says so.
_UNMEASURED_VARIANCE = 1e6

_T = TYPESTORE.types


def _header(stamp_ns: int, frame_id: str) -> Any:
    stamp = _T["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000))
    return _T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


def image(stamp_ns: int, rgb: NDArray[np.uint8]) -> Any:
    h, w, _ = rgb.shape
    return _T[IMAGE](
        header=_header(stamp_ns, CAMERA_FRAME),
        height=h,
        width=w,
        encoding="rgb8",
        is_bigendian=0,
        step=w * 3,
        data=np.ascontiguousarray(rgb).reshape(-1),
    )


def encode(rgb: NDArray[np.uint8], image_format: str, jpeg_quality: int) -> NDArray[np.uint8]:
    """PNG or JPEG bytes of an RGB image (OpenCV wants BGR)."""
    bgr = np.ascontiguousarray(rgb[:, :, ::-1])
    if image_format == "png":
        ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, 6])
    else:
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
    if not ok:
        raise RuntimeError(f"OpenCV could not encode a {image_format} image")
    return buf.reshape(-1)


def compressed_image(stamp_ns: int, data: NDArray[np.uint8], image_format: str) -> Any:
    return _T[COMPRESSED_IMAGE](header=_header(stamp_ns, CAMERA_FRAME), format=image_format, data=data)


def camera_info(stamp_ns: int, camera: CameraModel) -> Any:
    """CameraInfo of a camera model (unified: d = [xi]; the others their coefficients)."""
    model, d = camera_info_fields(camera)
    k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
    p = [camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    return _T[CAMERA_INFO](
        header=_header(stamp_ns, CAMERA_FRAME),
        height=camera.height_px,
        width=camera.width_px,
        distortion_model=model,
        d=np.array(d, dtype=np.float64),
        k=np.array(k, dtype=np.float64),
        r=np.eye(3).reshape(-1),
        p=np.array(p, dtype=np.float64),
        binning_x=0,
        binning_y=0,
        roi=_T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


def mount_transform(stamp_ns: int, mount: CameraMount) -> Any:
    """/tf_static's TFMessage of the mount: base_link -> the camera frame (REP 103 axes)."""
    x, y, z, w = quaternion_from_rpy(mount.roll_rad, mount.pitch_rad, mount.yaw_rad)
    transform = _T["geometry_msgs/msg/Transform"](
        translation=_T["geometry_msgs/msg/Vector3"](x=mount.offset_x_m, y=mount.offset_y_m, z=mount.height_m),
        rotation=_T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
    )
    stamped = _T["geometry_msgs/msg/TransformStamped"](
        header=_header(stamp_ns, BASE_FRAME), child_frame_id=CAMERA_FRAME, transform=transform
    )
    return _T[TF_MESSAGE](transforms=[stamped])


def odometry(
    stamp_ns: int,
    frame_id: str,
    pose: NDArray[np.float64],
    speed_mps: float,
    yaw_rate_rps: float,
    *,
    pose_variance: tuple[float, float, float] = (0.0, 0.0, 0.0),
    twist_variance: tuple[float, float] = (0.0, 0.0),
) -> Any:
    """Odometry of a planar pose (x, y, theta) with forward speed and yaw rate in the base frame.

    Variances are (x, y, yaw) of the pose and (forward speed, yaw rate) of the twist.
    """
    qx, qy, qz, qw = quaternion_from_yaw(float(pose[2]))
    geo = "geometry_msgs/msg/"
    pose_cov = np.zeros(36)
    pose_cov[[0, 7, 35]] = pose_variance
    twist_cov = np.zeros(36)
    twist_cov[[0, 35]] = twist_variance
    if any(pose_variance):
        pose_cov[[14, 21, 28]] = _UNMEASURED_VARIANCE
        twist_cov[[7, 14, 21, 28]] = _UNMEASURED_VARIANCE
    return _T[ODOMETRY](
        header=_header(stamp_ns, frame_id),
        child_frame_id=BASE_FRAME,
        pose=_T[geo + "PoseWithCovariance"](
            pose=_T[geo + "Pose"](
                position=_T[geo + "Point"](x=float(pose[0]), y=float(pose[1]), z=0.0),
                orientation=_T[geo + "Quaternion"](x=qx, y=qy, z=qz, w=qw),
            ),
            covariance=pose_cov,
        ),
        twist=_T[geo + "TwistWithCovariance"](
            twist=_T[geo + "Twist"](
                linear=_T[geo + "Vector3"](x=float(speed_mps), y=0.0, z=0.0),
                angular=_T[geo + "Vector3"](x=0.0, y=0.0, z=float(yaw_rate_rps)),
            ),
            covariance=twist_cov,
        ),
    )


def serialize(message: Any) -> bytes:
    return TYPESTORE.serialize_cdr(message, message.__msgtype__)
