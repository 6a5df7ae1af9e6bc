"""The ``detector`` node: images (raw or compressed) + camera info -> ``/objslam/slices``.

A thin wrapper over :class:`objslam_detector.detector.Detector`. A frame that cannot be
used (unsupported encoding, size not matching the calibration, corrupt compressed data,
empty image) is skipped with a warning saying why, at most one per reason every
``WARN_PERIOD_S``, and counted per reason. Until the camera info comes the latest few
images are held (one warning); older ones are counted as skipped for "no camera info".
The counts are in :meth:`DetectorNode.summary`, printed at shutdown.

``image_transport: auto`` (the default) subscribes to ``image_topic`` and its
``/compressed`` and keeps whichever brings an image first, so a bag of either kind works
without flags; while no image has arrived, a warning every ``NO_IMAGE_WARN_S`` (wall
time: a paused bag stops sim time too) names the image topics the graph does have.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter, deque
from collections.abc import Callable
from typing import Any

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from objslam_common.cameras import CameraModel
from objslam_common.catalog import load_catalog
from objslam_common.errors import CameraModelError
from objslam_common.records import ImageSlices, SliceMeasurement
from objslam_common.ros.conversions import camera_from_info, slice_array_to_msg, stamp_ns
from objslam_common.ros.params import declare_config
from objslam_common.ros.spin import run_node
from objslam_detector.config import DetectorConfig
from objslam_detector.detector import Detector
from objslam_detector.errors import DetectorInputError
from objslam_detector.images import decode_image_message
from objslam_detector.overlay import draw_slices
from objslam_msgs.msg import SliceArray

SLICES_TOPIC = "/objslam/slices"
DEBUG_IMAGE_TOPIC = "/objslam/detector/debug_image"
WARN_PERIOD_S = 5.0
NO_IMAGE_WARN_S = 5.0  # warn (again every so often) while no image has arrived
PENDING_IMAGES = 10
NO_CAMERA_INFO = "no camera info"  # beside the reasons of objslam_detector.errors


class DetectorNode(Node):
    def __init__(self) -> None:
        super().__init__("detector")
        self.config = declare_config(self, DetectorConfig)
        catalog = load_catalog(self.config.catalog_file or None)
        self.detector = Detector(self.config, catalog)
        self.class_rgb = {c.label: c.color_rgb for c in catalog}
        self.camera: CameraModel | None = None
        self.skipped: Counter[str] = Counter()  # reason -> frames skipped
        self.processed = 0
        self._frames_seen = 0
        self._last_warned: dict[str, float] = {}  # reason -> monotonic time of its last warning
        # Camera info and the first images arrive together, in an order the executor picks:
        # hold the latest few images until the calibration is known instead of losing them.
        self._pending: deque[tuple[Any, Callable[[], tuple[np.ndarray, str]]]] = deque()

        self.slices_pub = self.create_publisher(SliceArray, SLICES_TOPIC, QoSProfile(depth=100))
        self.debug_pub = (
            self.create_publisher(Image, DEBUG_IMAGE_TOPIC, qos_profile_sensor_data)
            if self.config.publish_debug_image
            else None
        )
        self.create_subscription(
            CameraInfo, self.config.camera_info_topic, self.on_camera_info, qos_profile_sensor_data
        )
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        image_qos = reliable if self.config.reliable_images else qos_profile_sensor_data
        raw_topic = self.config.image_topic
        compressed_topic = raw_topic.rstrip("/") + "/compressed"
        transport = self.config.image_transport
        # auto: listen on both and keep the one that brings an image first (a camera driver
        # may publish both; taking both would detect every frame twice).
        self._image_subs: dict[str, Any] = {}
        if transport in ("auto", "raw"):
            self._image_subs[raw_topic] = self.create_subscription(
                Image, raw_topic, lambda msg: self.on_image(msg, raw_topic), image_qos
            )
        if transport in ("auto", "compressed"):
            self._image_subs[compressed_topic] = self.create_subscription(
                CompressedImage, compressed_topic, lambda msg: self.on_image(msg, compressed_topic), image_qos
            )
        self._image_topic: str | None = None if transport == "auto" else next(iter(self._image_subs))
        self._started = time.monotonic()
        self._no_image_timer = self.create_timer(
            NO_IMAGE_WARN_S, self._warn_no_image, clock=Clock(clock_type=ClockType.STEADY_TIME)
        )
        self.get_logger().info(
            f"detecting {', '.join(catalog.labels)} on {' or '.join(self._image_subs)}; slices on {SLICES_TOPIC}"
            + (f", debug image on {DEBUG_IMAGE_TOPIC}" if self.debug_pub else "")
        )

    def on_camera_info(self, msg: CameraInfo) -> None:
        try:
            camera = camera_from_info(msg)
        except CameraModelError as exc:
            self.get_logger().warn(f"ignoring camera info: {exc}", throttle_duration_sec=WARN_PERIOD_S)
            return
        self.camera = camera
        while self._pending:
            self._process(*self._pending.popleft())

    def on_image(self, msg: Image | CompressedImage, topic: str) -> None:
        if self._image_topic is None:
            self._image_topic = topic
            for other in [t for t in self._image_subs if t != topic]:
                self.destroy_subscription(self._image_subs.pop(other))
            self.get_logger().info(f"images arrive on {topic}: detecting on it ({type(msg).__name__})")
        elif topic != self._image_topic:
            return  # queued on the other transport before it was dropped
        self._frames_seen += 1
        self._process(msg.header, lambda: decode_image_message(msg))

    def _warn_no_image(self) -> None:
        if self._frames_seen:
            self._no_image_timer.cancel()
            return
        # Topics someone publishes images on (our own subscriptions put topics on the graph too).
        with_images = sorted(
            name
            for name, types in self.get_topic_names_and_types()
            if {"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"} & set(types)
            and name != DEBUG_IMAGE_TOPIC
            and self.count_publishers(name) > 0
        )
        self.get_logger().warn(
            f"no image has arrived on {' or '.join(self._image_subs)} in {time.monotonic() - self._started:.0f} s"
            + (
                f"; image topics on the graph: {', '.join(with_images)} (set image_topic)"
                if with_images
                else "; no image topic is on the graph (is the bag playing?)"
            )
        )

    def summary(self) -> str:
        """E.g. ``processed 90 frames, skipped {'no camera info': 3, 'size mismatch': 5}``."""
        skipped = f", skipped {dict(sorted(self.skipped.items()))}" if self.skipped else ""
        return f"processed {self.processed} frames{skipped}"

    def _skip(self, reason: str, detail: str) -> None:
        self.skipped[reason] += 1
        # Rate-limited per reason, not per detail: details vary from frame to frame (sizes,
        # byte counts) and would let a stream of bad frames warn for every one, while a
        # second, different problem is still reported at once.
        now = time.monotonic()
        if now - self._last_warned.get(reason, -math.inf) >= WARN_PERIOD_S:
            self._last_warned[reason] = now
            self.get_logger().warn(
                f"skipped a frame ({reason}: {self.skipped[reason]} so far, "
                f"warning at most every {WARN_PERIOD_S:g} s): {detail}"
            )

    def _process(self, header, decode) -> None:
        if self.camera is None:
            self.get_logger().warn(
                f"waiting for camera info on {self.config.camera_info_topic}; holding the latest "
                f"{PENDING_IMAGES} images and skipping older ones until it arrives",
                once=True,
            )
            if len(self._pending) == PENDING_IMAGES:
                self._pending.popleft()
                self.skipped[NO_CAMERA_INFO] += 1
            self._pending.append((header, decode))
            return
        try:
            image, encoding = decode()
            slices = self.detector.detect(image, self.camera, encoding)
        except DetectorInputError as exc:
            self._skip(exc.reason, str(exc))
            return
        self.processed += 1
        image_slices = ImageSlices(stamp_ns(header), tuple(slices))
        self.slices_pub.publish(slice_array_to_msg(image_slices, header.frame_id))
        if self.debug_pub is not None:
            self._publish_debug(header, image, encoding, slices)

    def _publish_debug(self, header, image: np.ndarray, encoding: str, slices: list[SliceMeasurement]) -> None:
        if self.camera is None or self.debug_pub is None:
            return
        drawn = draw_slices(image, slices, self.detector.view(self.camera), encoding, self.class_rgb)
        msg = Image(
            header=header, height=drawn.shape[0], width=drawn.shape[1], encoding="rgb8", step=drawn.shape[1] * 3
        )
        msg.data = drawn.tobytes()
        self.debug_pub.publish(msg)


def main(args: list[str] | None = None) -> int:
    return run_node("detector", DetectorNode, args)


if __name__ == "__main__":
    sys.exit(main())
