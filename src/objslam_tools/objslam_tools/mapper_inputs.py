"""A bag as the mapper's inputs: odometry samples from ``/odom`` and slices from the detector.

This is what the detector and mapper nodes exchange over the graph, computed in one
process with the nodes' own rules: images are decoded and checked as the detector node
does (a frame it would skip is skipped here, counted per reason), and odometry and slices
go through the mapper node's intake (:mod:`objslam_mapper.ros.intake`: bad messages
skipped and counted, the buffer's rules). Slices are the records the detector node would
publish (the record rounds what the message carries as float32). So a map built here
equals the nodes' map for the same bag and seed, damaged messages included. Unlike the
node, nothing is bounded here: a bag is finite (the node's ``ros.max_buffered_*``).
"""

from __future__ import annotations

import logging
import sys
from collections import Counter
from collections.abc import Callable
from typing import NamedTuple

from objslam_common.records import ImageSlices, OdometrySample
from objslam_common.ros.conversions import stamp_ns
from objslam_detector.detector import Detector
from objslam_detector.errors import DetectorInputError
from objslam_detector.images import decode_image_message
from objslam_mapper.buffer import BufferCounters, InputBuffer, NothingToBuildError
from objslam_mapper.ros.intake import take_odometry
from objslam_tools.bag import ODOM_TOPIC, ODOMETRY_TYPE, Bag
from objslam_tools.errors import UserError

logger = logging.getLogger(__name__)


class MapperInputs(NamedTuple):
    odometry: tuple[OdometrySample, ...]
    images: tuple[ImageSlices, ...]  # in bag order, those the buffer kept
    counters: BufferCounters  # messages skipped or left out, as the mapper node counts them
    skipped_frames: dict[str, int]  # images the detector could not use, per reason

    def skipped_summary(self) -> str:
        """The skipped messages and frames in words ('' if none)."""
        return _skipped_words(self.counters, self.skipped_frames)


def _skipped_words(counters: BufferCounters, skipped_frames: dict[str, int]) -> str:
    frames = ", ".join(f"{n} frames ({reason})" for reason, n in sorted(skipped_frames.items()))
    return ", ".join(part for part in (counters.describe(), frames) if part)


def read_mapper_inputs(
    bag: Bag, detector: Detector, progress: Callable[[int, int], None] | None = None, topic: str = ODOM_TOPIC
) -> MapperInputs:
    """Detect every image of the bag and take its odometry as the nodes would (module docstring)."""
    buffer = InputBuffer(sys.maxsize, sys.maxsize)
    for _, msg in bag.typed_messages(topic, ODOMETRY_TYPE):
        problem = take_odometry(buffer, msg)
        if problem is not None and buffer.counters.invalid_odometry == 1:
            logger.warning("bag %s: skipping an odometry message: %s (all such are counted)", bag.path, problem)
    images, skipped = _detect(bag, detector, progress)
    for image in images:
        buffer.add_slices(image)
    try:
        odometry, kept = buffer.snapshot()
    except NothingToBuildError as exc:
        counts = _skipped_words(buffer.counters, dict(skipped))
        raise UserError(f"bag {bag.path}: nothing to map: {exc}" + (f" (skipped: {counts})" if counts else "")) from exc
    return MapperInputs(odometry, kept, buffer.counters, dict(skipped))


def _detect(
    bag: Bag, detector: Detector, progress: Callable[[int, int], None] | None
) -> tuple[list[ImageSlices], Counter[str]]:
    """The detector's slices of every usable image, in bag order, and the frames skipped per reason."""
    camera = bag.read_camera()
    topic = bag.image_topic()
    msgtype = bag.topics[topic].msgtype
    total = bag.topics[topic].count
    images: list[ImageSlices] = []
    skipped: Counter[str] = Counter()
    for k, (_, msg) in enumerate(bag.typed_messages(topic, msgtype), start=1):
        try:
            pixels, encoding = decode_image_message(msg)
            slices = detector.detect(pixels, camera, encoding)
        except DetectorInputError as exc:
            skipped[exc.reason] += 1
            if skipped[exc.reason] == 1:
                logger.warning("bag %s: skipping a frame: %s (all such are counted)", bag.path, exc)
        else:
            images.append(ImageSlices(stamp_ns(msg.header), tuple(slices)))
        if progress is not None:
            progress(k, total)
    if not images and skipped:
        reasons = ", ".join(f"{reason}: {n}" for reason, n in sorted(skipped.items()))
        raise UserError(f"bag {bag.path}: no image of {topic} could be used ({reasons}); see the warning above")
    return images, skipped
