"""A bag as the mapper's inputs: odometry samples from ``/odom`` and slices from the detector.

This is what the detector and mapper nodes exchange over the graph, computed in one
process: odometry goes through the nodes' own conversion, and slices are the records the
detector node would publish (the record rounds what the message carries as float32), so
a map built here equals the nodes' map for the same inputs and seed.
"""

from __future__ import annotations

from collections.abc import Callable

from objslam_common.records import ImageSlices, OdometrySample
from objslam_common.ros.conversions import odometry_sample
from objslam_detector.detector import Detector
from objslam_tools.bag import ODOM_TOPIC, ODOMETRY_TYPE, Bag
from objslam_tools.detector_eval import frame_pixels
from objslam_tools.errors import UserError


def odometry_samples(bag: Bag, topic: str = ODOM_TOPIC) -> tuple[OdometrySample, ...]:
    """The odometry of ``topic`` as records, sorted by stamp."""
    samples = [odometry_sample(msg) for _, msg in bag.typed_messages(topic, ODOMETRY_TYPE)]
    if not samples:
        raise UserError(f"bag {bag.path}: topic {topic} has no messages")
    return tuple(sorted(samples, key=lambda s: s.stamp_ns))


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
        images.append(ImageSlices(frame.stamp_ns, tuple(detector.detect(pixels, camera, encoding))))
        if progress is not None:
            progress(k, total)
    return tuple(sorted(images, key=lambda i: i.stamp_ns))
