"""Reading rosbag2 bags (MCAP or sqlite3) without a ROS install, via ``rosbags``.

Everything returned is plain data (NamedTuples, dataclasses, numpy arrays); message
classes stay inside this module. Usage::

    bag = open_bag("bags/office")               # UserError with one line if it is not a bag
    bag.topics                                  # {name: TopicSummary(name, msgtype, count)}
    for msg in bag.raw_messages(["/odom"]):     # RawMessage(topic, stamp_ns, data, msgtype), time order
        ...
    odom = bag.read_odometry()                  # PoseTrack: stamps_ns (N,) int64, poses (N, 3)
    camera = bag.read_camera()                  # an objslam_common.cameras model
    mount = bag.read_mount()                    # MountReading from /tf_static, or None
    for frame in bag.images():                  # ImageFrame(stamp_ns, encoding, data)
        rgb = decode_rgb(frame)                 # (H, W, 3) uint8

A :class:`Bag` holds no open file: each call opens the bag, reads and closes it, so
iterators can be abandoned freely and a Bag can be shared.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import ReaderError
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore

from objslam_common.cameras import CameraModel
from objslam_common.errors import CameraModelError
from objslam_common.geometry import rpy_from_quaternion, yaw_from_quaternion
from objslam_common.mount import CameraMount
from objslam_common.ros.conversions import camera_from_info
from objslam_tools.errors import UserError
from objslam_tools.trajectory import PoseTrack

logger = logging.getLogger(__name__)

ODOM_TOPIC = "/odom"
GROUND_TRUTH_ODOM_TOPIC = "/ground_truth/odom"
CAMERA_INFO_TOPIC = "/camera/camera_info"
IMAGE_TOPIC = "/camera/image_raw"
COMPRESSED_IMAGE_TOPIC = "/camera/image_raw/compressed"
TF_STATIC_TOPIC = "/tf_static"
BASE_FRAME = "base_link"

ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
IMAGE_TYPE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE_TYPE = "sensor_msgs/msg/CompressedImage"
TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"

STORAGE_SUFFIXES = (".mcap", ".db3")
_RAW_CHANNELS = {"mono8": 1, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4}
_READER_ERRORS = (AnyReaderError, ReaderError, SerdeError, OSError)
# What the reader raises on damaged bytes is not only its own errors (seen: OverflowError from
# an overwritten chunk header, ValueError, KeyError, struct.error): anything raised while
# parsing a file is a damaged file, so all of it becomes one line (see _read_failure).
_READ_ERRORS = (Exception,)


def _read_failure(exc: Exception) -> str:
    detail = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if isinstance(exc, _READER_ERRORS):
        return detail or type(exc).__name__
    return (
        f"the file is damaged ({type(exc).__name__}: {detail})"
        if detail
        else f"the file is damaged ({type(exc).__name__})"
    )


# Bags written by rosbag2 embed their message definitions; this store is only the fallback.
_JAZZY = get_typestore(Stores.ROS2_JAZZY)


class TopicSummary(NamedTuple):
    name: str
    msgtype: str  # e.g. "nav_msgs/msg/Odometry"
    count: int


class RawMessage(NamedTuple):
    """One record as stored: ``stamp_ns`` is the bag's receive time, ``data`` the CDR bytes."""

    topic: str
    stamp_ns: int
    data: bytes
    msgtype: str


class ImageFrame(NamedTuple):
    """An image at its header stamp.

    ``encoding`` is the raw encoding (``rgb8``, ``bgr8``, ``mono8``, ``rgba8``, ``bgra8``)
    with ``data`` of shape (H, W[, C]) uint8, or for a compressed image ``png``/``jpeg``
    with ``data`` the 1-D uint8 file bytes. :func:`decode_rgb` turns either into RGB.
    """

    stamp_ns: int
    encoding: str
    data: NDArray[np.uint8]

    @property
    def compressed(self) -> bool:
        return self.encoding in ("png", "jpeg")


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _plain(value: Any) -> Any:
    """A deserialized message as nested dicts/lists/scalars."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {
            f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value) if not f.name.startswith("__")
        }
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


class MountReading(NamedTuple):
    """The camera mount a bag carries on /tf_static, and where it came from."""

    mount: CameraMount
    source: str  # e.g. "/tf_static base_link -> camera"


@dataclass(frozen=True)
class Bag:
    """A validated rosbag2 bag; see the module docstring."""

    path: Path  # the bag directory (or storage file)
    topics: dict[str, TopicSummary]
    start_ns: int
    end_ns: int
    message_count: int

    @property
    def directory(self) -> Path:
        """Where ``metadata.yaml`` and ``ground_truth.yaml`` live."""
        return self.path if self.path.is_dir() else self.path.parent

    @property
    def duration_s(self) -> float:
        return max(0, self.end_ns - self.start_ns) * 1e-9

    def has_topic(self, topic: str) -> bool:
        return topic in self.topics

    def topics_of_type(self, msgtype: str) -> list[str]:
        return sorted(name for name, t in self.topics.items() if t.msgtype == msgtype)

    def require_topic(self, topic: str, msgtype: str | None = None) -> TopicSummary:
        """The topic's summary; UserError if the bag lacks it or it has another type."""
        summary = self.topics.get(topic)
        if summary is None:
            have = ", ".join(sorted(self.topics)) or "none"
            raise UserError(f"bag {self.path} has no topic {topic} (topics: {have})")
        if msgtype is not None and summary.msgtype != msgtype:
            raise UserError(f"bag {self.path}: topic {topic} is {summary.msgtype}, expected {msgtype}")
        return summary

    def _reader(self) -> AnyReader:
        return AnyReader([self.path], default_typestore=_JAZZY)

    def _iterate(self, topics: Iterable[str] | None) -> Iterator[tuple[Any, RawMessage]]:
        """(deserializer-owning reader, raw message) in time order; wraps read errors as UserError."""
        wanted = None if topics is None else set(topics)
        if wanted is not None:
            for topic in wanted:
                self.require_topic(topic)
        try:
            with self._reader() as reader:
                connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
                if not connections:
                    return
                for conn, stamp_ns, data in reader.messages(connections=connections):
                    yield reader, RawMessage(conn.topic, int(stamp_ns), bytes(data), conn.msgtype)
        except _READ_ERRORS as exc:
            raise UserError(f"cannot read bag {self.path}: {_read_failure(exc)}") from exc

    def raw_messages(self, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
        """Records of the given topics (all if None) in bag time order, undeserialized."""
        for _, raw in self._iterate(topics):
            yield raw

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[tuple[RawMessage, dict[str, Any]]]:
        """Records with their content as nested dicts/lists (for printing, e.g. ``objslam echo``)."""
        for reader, raw in self._iterate(topics):
            yield raw, _plain(self._deserialize(reader, raw))

    def _deserialize(self, reader: AnyReader, raw: RawMessage) -> Any:
        try:
            return reader.deserialize(raw.data, raw.msgtype)
        except _READ_ERRORS as exc:
            raise UserError(
                f"bag {self.path}: cannot decode a {raw.msgtype} on {raw.topic}: {_read_failure(exc)}"
            ) from exc

    def typed_messages(self, topic: str, msgtype: str) -> Iterator[tuple[RawMessage, Any]]:
        """Records of one topic with their deserialized messages (for the message conversions)."""
        self.require_topic(topic, msgtype)
        for reader, raw in self._iterate([topic]):
            yield raw, self._deserialize(reader, raw)

    def read_odometry(self, topic: str = ODOM_TOPIC) -> PoseTrack:
        """All nav_msgs/Odometry poses of a topic at their header stamps, sorted by stamp."""
        stamps: list[int] = []
        poses: list[tuple[float, float, float]] = []
        for _, msg in self.typed_messages(topic, ODOMETRY_TYPE):
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            stamps.append(_stamp_ns(msg.header))
            poses.append((float(p.x), float(p.y), yaw_from_quaternion(q.x, q.y, q.z, q.w)))
        if not stamps:
            raise UserError(f"bag {self.path}: topic {topic} has no messages")
        return PoseTrack(np.array(stamps, dtype=np.int64), np.array(poses, dtype=float))

    def read_camera(self, topic: str | None = None) -> CameraModel:
        """The camera model from the first CameraInfo (default topic: /camera/camera_info or the only one)."""
        topic = topic or self._pick_topic([CAMERA_INFO_TOPIC], [CAMERA_INFO_TYPE], "camera info")
        for _, msg in self.typed_messages(topic, CAMERA_INFO_TYPE):
            try:
                return camera_from_info(msg)
            except CameraModelError as exc:
                raise UserError(f"bag {self.path}: {topic}: {exc}") from exc
        raise UserError(f"bag {self.path}: topic {topic} has no messages")

    def read_mount(self) -> MountReading | None:
        """The mount (base_link -> camera) from /tf_static, or None if the bag has no /tf_static.

        The transform taken is the one from ``base_link`` to the CameraInfo's frame; a bag
        whose /tf_static holds exactly one transform from ``base_link`` may name its camera
        frame otherwise. Anything else is one clear UserError: a mount guessed is a map wrong.
        """
        if not self.has_topic(TF_STATIC_TOPIC):
            return None
        camera_frame = self._camera_frame()
        from_base = {}
        for _, msg in self.typed_messages(TF_STATIC_TOPIC, TF_MESSAGE_TYPE):
            for t in msg.transforms:
                if t.header.frame_id.lstrip("/") == BASE_FRAME:
                    from_base[t.child_frame_id.lstrip("/")] = t.transform
        if camera_frame in from_base:
            child = camera_frame
        elif len(from_base) == 1:
            (child,) = from_base
        else:
            found = ", ".join(sorted(from_base)) or "none"
            raise UserError(
                f"bag {self.path}: {TF_STATIC_TOPIC} has no transform {BASE_FRAME} -> {camera_frame!r} "
                f"(the camera info's frame); transforms from {BASE_FRAME}: {found}"
            )
        tr, q = from_base[child].translation, from_base[child].rotation
        values = [tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w]
        norm = float(np.linalg.norm(values[3:]))
        if not np.all(np.isfinite(values)) or abs(norm - 1.0) > 1e-3:
            raise UserError(f"bag {self.path}: {TF_STATIC_TOPIC} {BASE_FRAME} -> {child}: not a valid transform")
        roll, pitch, yaw = rpy_from_quaternion(*(v / norm for v in values[3:]))
        mount = CameraMount(
            height_m=float(tr.z), offset_x_m=float(tr.x), offset_y_m=float(tr.y),
            yaw_rad=yaw, roll_rad=roll, pitch_rad=pitch,
        )  # fmt: skip
        return MountReading(mount, f"{TF_STATIC_TOPIC} {BASE_FRAME} -> {child}")

    def _camera_frame(self) -> str:
        topic = self._pick_topic([CAMERA_INFO_TOPIC], [CAMERA_INFO_TYPE], "camera info")
        for _, msg in self.typed_messages(topic, CAMERA_INFO_TYPE):
            return str(msg.header.frame_id).lstrip("/")
        return ""

    def image_topic(self) -> str:
        """The camera image topic: /camera/image_raw, else its /compressed, else the only image topic."""
        return self._pick_topic(
            [IMAGE_TOPIC, COMPRESSED_IMAGE_TOPIC], [IMAGE_TYPE, COMPRESSED_IMAGE_TYPE], "camera image"
        )

    def images(self, topic: str | None = None) -> Iterator[ImageFrame]:
        """Images (sensor_msgs/Image or CompressedImage) in bag order, at their header stamps."""
        topic = topic or self.image_topic()
        msgtype = self.require_topic(topic).msgtype
        if msgtype not in (IMAGE_TYPE, COMPRESSED_IMAGE_TYPE):
            raise UserError(f"bag {self.path}: topic {topic} is {msgtype}, not an image")
        for raw, msg in self.typed_messages(topic, msgtype):
            stamp_ns = _stamp_ns(msg.header) or raw.stamp_ns  # an unstamped header falls back to bag time
            if msgtype == IMAGE_TYPE:
                yield ImageFrame(stamp_ns, msg.encoding, self._raw_pixels(msg, topic))
            else:
                yield ImageFrame(stamp_ns, self._compressed_format(msg.format, topic), np.asarray(msg.data, np.uint8))

    def _raw_pixels(self, msg: Any, topic: str) -> NDArray[np.uint8]:
        channels = _RAW_CHANNELS.get(msg.encoding)
        if channels is None:
            raise UserError(
                f"bag {self.path}: {topic}: unsupported encoding {msg.encoding!r} ({', '.join(_RAW_CHANNELS)})"
            )
        row_bytes = msg.width * channels
        data = np.asarray(msg.data, dtype=np.uint8)
        if msg.step < row_bytes or data.size < msg.step * msg.height:
            raise UserError(
                f"bag {self.path}: {topic}: image data does not match {msg.width}x{msg.height} {msg.encoding}"
            )
        rows = data[: msg.step * msg.height].reshape(msg.height, msg.step)[:, :row_bytes]
        shape = (msg.height, msg.width) if channels == 1 else (msg.height, msg.width, channels)
        return np.ascontiguousarray(rows).reshape(shape)

    def _compressed_format(self, fmt: str, topic: str) -> str:
        # image_transport writes e.g. "rgb8; png compressed bgr8"; plain producers write "png" / "jpeg".
        f = fmt.lower()
        if "png" in f:
            return "png"
        if "jpeg" in f or "jpg" in f:
            return "jpeg"
        raise UserError(f"bag {self.path}: {topic}: unsupported compressed format {fmt!r} (png or jpeg)")

    def _pick_topic(self, preferred: list[str], msgtypes: list[str], what: str) -> str:
        for topic in preferred:
            if topic in self.topics and self.topics[topic].msgtype in msgtypes:
                return topic
        candidates = sorted(n for n, t in self.topics.items() if t.msgtype in msgtypes)
        if len(candidates) == 1:
            return candidates[0]
        if not candidates:
            raise UserError(f"bag {self.path} has no {what} topic ({' or '.join(msgtypes)})")
        raise UserError(f"bag {self.path} has several {what} topics ({', '.join(candidates)}); name one")


def decode_rgb(frame: ImageFrame) -> NDArray[np.uint8]:
    """(H, W, 3) uint8 RGB of any ImageFrame."""
    import cv2  # only image consumers pay for OpenCV

    data = frame.data
    if frame.compressed:
        decoded = cv2.imdecode(data, cv2.IMREAD_COLOR)
        if decoded is None:
            raise UserError(f"cannot decode a {frame.encoding} image at stamp {frame.stamp_ns}")
        return cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)
    if frame.encoding == "mono8":
        return np.repeat(data[:, :, None], 3, axis=2)
    rgb = data[:, :, :3]
    return np.ascontiguousarray(rgb[:, :, ::-1] if frame.encoding.startswith("bgr") else rgb)


def open_bag(path: str | os.PathLike[str]) -> Bag:
    """Open and validate a rosbag2 directory (or a single .mcap/.db3 file).

    Raises UserError with one line for a missing path, a folder that is not a bag, an
    unreadable bag.
    """
    path = Path(path)
    if not path.exists():
        raise UserError(f"bag not found: {path}")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise UserError(f"{path} is not a rosbag2 bag (no metadata.yaml)")
    elif path.suffix not in STORAGE_SUFFIXES:
        raise UserError(f"{path} is not a rosbag2 bag (expected a bag directory or a .mcap/.db3 file)")
    try:
        with AnyReader([path], default_typestore=_JAZZY) as reader:
            topics = {
                name: TopicSummary(name, info.msgtype or "?", int(info.msgcount))
                for name, info in reader.topics.items()
            }
            count = int(reader.message_count)
            start_ns, end_ns = (int(reader.start_time), int(reader.end_time)) if count else (0, 0)
    except _READ_ERRORS as exc:
        raise UserError(f"cannot read bag {path}: {_read_failure(exc)}") from exc
    logger.debug("opened bag %s: %d topics, %d messages", path, len(topics), count)
    return Bag(path=path, topics=topics, start_ns=start_ns, end_ns=end_ns, message_count=count)
