"""A bag as the mapper's inputs: odometry samples from ``/odom`` and slices from the detector.

This is what the detector and mapper nodes exchange over the graph, computed in one
process; the conversions match the messages' (the confidence travels as float32), so a
map built here equals the nodes' map for the same inputs and seed.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from objslam_common.records import ImageSlices, OdometrySample, SliceMeasurement

from objslam_detector.detector import Detector
from objslam_detector.slices import DetectedSlice
from objslam_tools.bag import ODOM_TOPIC, Bag
from objslam_tools.detector_eval import frame_pixels


def to_measurement(detected: DetectedSlice) -> SliceMeasurement:
    return SliceMeasurement(
        label=detected.label,
        confidence=float(np.float32(detected.confidence)),  # objslam_msgs/Slice carries float32
        bearing_rad=float(detected.bearing_rad),
        angular_width_rad=float(detected.angular_width_rad),
        elevation_bottom_rad=float(detected.elevation_bottom_rad),
        elevation_top_rad=float(detected.elevation_top_rad),
    )


def odometry_samples(bag: Bag, topic: str = ODOM_TOPIC) -> tuple[OdometrySample, ...]:
    track = bag.read_odometry(topic)
    return tuple(
        OdometrySample(int(t), float(x), float(y), float(theta))
        for t, (x, y, theta) in zip(track.stamps_ns, track.poses, strict=True)
    )


def detect_bag(
    bag: Bag, detector: Detector, progress: Callable[[int, int], None] | None = None
) -> tuple[ImageSlices, ...]:
    """Run the detector over every image of the bag, in stamp order."""
    camera = bag.read_camera()
    topic = bag.image_topic()
    total = bag.topics[topic].count
    images = []
    for k, frame in enumerate(bag.images(topic), start=1):
        pixels, encoding = frame_pixels(frame)
        slices = detector.detect(pixels, camera, encoding)
        images.append(ImageSlices(frame.stamp_ns, tuple(to_measurement(s) for s in slices)))
        if progress is not None:
            progress(k, total)
    return tuple(sorted(images, key=lambda i: i.stamp_ns))
