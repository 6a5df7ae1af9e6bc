"""Tiny rosbag2 bags written with rosbags' Writer, for tests of bag reading and evaluation."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from objslam_common.cameras.unified import UnifiedCamera
from objslam_common.geometry import quaternion_from_yaw

TS = get_typestore(Stores.ROS2_JAZZY)
_T = TS.types


def _header(stamp_ns: int, frame_id: str):
    return _T["std_msgs/msg/Header"](
        stamp=_T["builtin_interfaces/msg/Time"](
            sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000)
        ),
        frame_id=frame_id,
    )


def odometry_msg(stamp_ns: int, pose_xytheta: Sequence[float], frame_id: str = "odom"):
    x, y, theta = (float(v) for v in pose_xytheta)
    qx, qy, qz, qw = quaternion_from_yaw(theta)
    g = _T
    pose = g["geometry_msgs/msg/PoseWithCovariance"](
        pose=g["geometry_msgs/msg/Pose"](
            position=g["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
            orientation=g["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
        ),
        covariance=np.zeros(36),
    )
    vec = g["geometry_msgs/msg/Vector3"]
    twist = g["geometry_msgs/msg/TwistWithCovariance"](
        twist=g["geometry_msgs/msg/Twist"](linear=vec(x=0.0, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)),
        covariance=np.zeros(36),
    )
    return g["nav_msgs/msg/Odometry"](
        header=_header(stamp_ns, frame_id), child_frame_id="base_link", pose=pose, twist=twist
    )


def camera_info_msg(stamp_ns: int, camera: UnifiedCamera):
    c = camera
    return _T["sensor_msgs/msg/CameraInfo"](
        header=_header(stamp_ns, "camera"),
        height=c.height_px,
        width=c.width_px,
        distortion_model="unified",
        d=np.array([c.xi]),
        k=np.array([c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0]),
        r=np.eye(3).reshape(-1),
        p=np.zeros(12),
        binning_x=0,
        binning_y=0,
        roi=_T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


def image_msg(stamp_ns: int, rgb: np.ndarray, encoding: str = "rgb8"):
    pixels = rgb[:, :, ::-1] if encoding == "bgr8" else rgb
    h, w = pixels.shape[:2]
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    return _T["sensor_msgs/msg/Image"](
        header=_header(stamp_ns, "camera"),
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=0,
        step=w * channels,
        data=np.ascontiguousarray(pixels, dtype=np.uint8).reshape(-1),
    )


def compressed_msg(stamp_ns: int, rgb: np.ndarray, fmt: str = "png"):
    import cv2

    ok, buf = cv2.imencode("." + fmt, np.ascontiguousarray(rgb[:, :, ::-1]))
    assert ok
    return _T["sensor_msgs/msg/CompressedImage"](
        header=_header(stamp_ns, "camera"), format=fmt, data=np.asarray(buf, dtype=np.uint8).reshape(-1)
    )


def write_bag(
    path: Path,
    messages: Sequence[tuple[str, int, object]],
    storage: str = "mcap",
    ground_truth: dict | None = None,
) -> Path:
    """Write (topic, bag stamp ns, message) records; message types come from the messages."""
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections = {}
        for topic, stamp_ns, msg in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=TS)
            writer.write(connections[topic], int(stamp_ns), TS.serialize_cdr(msg, msg.__msgtype__))
    if ground_truth is not None:
        (path / "ground_truth.yaml").write_text(yaml.safe_dump(ground_truth, sort_keys=False))
    return path


def odometry_records(topic: str, stamps_ns: Sequence[int], poses: np.ndarray, frame_id: str = "odom") -> list:
    return [(topic, int(s), odometry_msg(int(s), p, frame_id)) for s, p in zip(stamps_ns, poses, strict=True)]
