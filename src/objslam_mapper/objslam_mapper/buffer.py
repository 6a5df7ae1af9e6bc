"""What the mapper node has received so far: bounded odometry and slice buffers.

ROS-free so that its rules are tested directly: bounded (the oldest entries go first,
counted), reset when time jumps backwards (a bag played in a loop), and able to say
exactly what is missing before a build.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, field

from objslam_mapper.records import ImageSlices, OdometrySample

logger = logging.getLogger(__name__)


class NothingToBuildError(ValueError):
    """The buffers do not hold what a map build needs; the message says what is missing."""


@dataclass
class BufferCounters:
    odometry_overflow: int = 0  # oldest odometry dropped because the buffer was full
    slices_overflow: int = 0
    time_resets: int = 0  # buffers cleared because time went backwards
    slices_before_odometry: int = 0  # slice arrays older than the first odometry, left out of builds
    invalid_odometry: int = 0  # counted by the node: NaN, non-unit quaternions
    invalid_slices: int = 0

    def dropped(self) -> int:
        """Messages lost to the map; 0 means a build saw everything that arrived."""
        return (
            self.odometry_overflow
            + self.slices_overflow
            + self.slices_before_odometry
            + self.invalid_odometry
            + self.invalid_slices
        )


@dataclass
class InputBuffer:
    max_odometry: int
    max_images: int
    odometry: deque[OdometrySample] = field(init=False)
    images: deque[ImageSlices] = field(init=False)
    counters: BufferCounters = field(default_factory=BufferCounters)

    def __post_init__(self) -> None:
        self.odometry = deque(maxlen=self.max_odometry)
        self.images = deque(maxlen=self.max_images)

    def clear(self) -> None:
        self.odometry.clear()
        self.images.clear()

    def _went_back(self, stamp_ns: int, latest: deque) -> bool:
        if latest and stamp_ns < latest[-1].stamp_ns:
            logger.warning(
                "time jumped back by %.3f s (bag replayed?): clearing the buffers",
                (latest[-1].stamp_ns - stamp_ns) * 1e-9,
            )
            self.clear()
            self.counters.time_resets += 1
            return True
        return False

    def add_odometry(self, sample: OdometrySample) -> None:
        self._went_back(sample.stamp_ns, self.odometry)
        if len(self.odometry) == self.odometry.maxlen:
            self.counters.odometry_overflow += 1
        self.odometry.append(sample)

    def add_slices(self, image: ImageSlices) -> None:
        self._went_back(image.stamp_ns, self.images)
        if len(self.images) == self.images.maxlen:
            self.counters.slices_overflow += 1
        self.images.append(image)

    def snapshot(self) -> tuple[tuple[OdometrySample, ...], tuple[ImageSlices, ...]]:
        """What a build uses; NothingToBuildError says what is missing.

        Slice arrays older than the first odometry cannot be placed and are left out (counted).
        """
        if not self.odometry and not self.images:
            raise NothingToBuildError("nothing buffered yet: no odometry and no slices received")
        if not self.odometry:
            raise NothingToBuildError(f"no odometry received ({len(self.images)} slice arrays are waiting for it)")
        if not self.images:
            raise NothingToBuildError(f"no slices received ({len(self.odometry)} odometry messages buffered)")
        first_odometry_ns = self.odometry[0].stamp_ns
        images = tuple(i for i in self.images if i.stamp_ns >= first_odometry_ns)
        self.counters.slices_before_odometry = len(self.images) - len(images)
        if not images:
            raise NothingToBuildError("every slice array is older than the first odometry message")
        return tuple(self.odometry), images
