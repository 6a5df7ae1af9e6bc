"""Copies of a bag with chosen messages damaged, for the bad-input tests of both paths."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)

Damage = Callable[[object], None]  # changes a deserialized message in place


def damage_bag(src: Path, dst: Path, damages: dict[str, dict[int, Damage]]) -> Path:
    """``src`` rewritten to ``dst`` with ``damages[topic][k]`` applied to that topic's k-th message.
    ground_truth.yaml comes along."""
    seen: dict[str, int] = {}
    with (
        AnyReader([src], default_typestore=TS) as reader,
        Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as writer,
    ):
        out = {c.topic: writer.add_connection(c.topic, c.msgtype, typestore=TS) for c in reader.connections}
        for connection, bag_ns, data in reader.messages():
            k = seen.get(connection.topic, 0)
            seen[connection.topic] = k + 1
            damage = damages.get(connection.topic, {}).get(k)
            if damage is not None:
                msg = reader.deserialize(data, connection.msgtype)
                damage(msg)
                data = TS.serialize_cdr(msg, connection.msgtype)
            writer.write(out[connection.topic], bag_ns, data)
    if (src / "ground_truth.yaml").is_file():
        shutil.copy(src / "ground_truth.yaml", dst / "ground_truth.yaml")
    return dst


def nan_position(msg) -> None:
    msg.pose.pose.position.x = float("nan")


def scaled_quaternion(msg) -> None:
    q = msg.pose.pose.orientation
    q.x, q.y, q.z, q.w = 2 * q.x, 2 * q.y, 2 * q.z, 2 * q.w


def zero_quaternion(msg) -> None:
    q = msg.pose.pose.orientation
    q.x = q.y = q.z = q.w = 0.0


def truncated_data(msg) -> None:
    """A compressed image cut short: the file header survives, the picture does not decode."""
    msg.data = np.asarray(msg.data[:64], dtype=np.uint8)


def smaller_image(msg) -> None:
    """A valid compressed image of another size than the calibration's."""
    import cv2

    ok, buf = cv2.imencode(".png", np.zeros((20, 30, 3), np.uint8))
    assert ok
    msg.data, msg.format = np.asarray(buf, dtype=np.uint8).reshape(-1), "png"


# The damaged bag of the tests: three bad odometry messages and two unusable frames.
ODOMETRY_DAMAGES = {100: nan_position, 300: scaled_quaternion, 500: zero_quaternion}
IMAGE_DAMAGES = {10: truncated_data, 40: smaller_image}


def damaged_small(bags: Path, dst: Path) -> Path:
    return damage_bag(
        bags / "small",
        dst,
        {"/odom": ODOMETRY_DAMAGES, "/camera/image_raw/compressed": IMAGE_DAMAGES},
    )
