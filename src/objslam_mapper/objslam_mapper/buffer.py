"""What the mapper node has received so far: bounded odometry and slice buffers.

ROS-free so that its rules are tested directly: bounded (the oldest entries go first,
counted), reset when time jumps backwards (a bag played in a loop), and able to say
exactly what is missing before a build.

Each stream is checked against its own latest stamp, so a reset must also deal with the
other stream's messages of the previous lap that are still in flight (the detector lags
the odometry): after a reset, a message at or after its stream's last stamp before the
reset, and ahead of everything buffered since, belongs to the old lap and is dropped and
counted. Appending it instead would make the new lap's next message on that stream look
like time going back again, and that second reset would wipe the new lap's first odometry.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

from objslam_common.records import ImageSlices, OdometrySample
from objslam_mapper.errors import MapperError

logger = logging.getLogger(__name__)

ODOMETRY = "odometry"
SLICES = "slices"


class NothingToBuildError(MapperError, ValueError):
    """The buffers do not hold what a map build needs; the message says what is missing."""


@dataclass
class BufferCounters:
    odometry_overflow: int = 0  # oldest odometry dropped because the buffer was full
    slices_overflow: int = 0
    time_resets: int = 0  # buffers cleared because time went backwards
    slices_before_odometry: int = 0  # slice arrays older than the first odometry, left out of builds
    invalid_odometry: int = 0  # counted by the node: NaN, non-unit quaternions
    invalid_slices: int = 0
    old_lap_after_reset: int = 0  # previous-lap messages that arrived after a time reset, dropped

    def dropped(self) -> int:
        """Messages lost to the map; 0 means a build saw everything that arrived."""
        return (
            self.odometry_overflow
            + self.slices_overflow
            + self.slices_before_odometry
            + self.invalid_odometry
            + self.invalid_slices
            + self.old_lap_after_reset
        )

    def describe(self) -> str:
        """The nonzero counts in words ('' if none), so that a refused build also says what was rejected."""
        counts = (
            (self.invalid_odometry, "invalid odometry messages (NaN or non-unit quaternion)"),
            (self.invalid_slices, "invalid slices"),
            (self.odometry_overflow, "odometry messages over the buffer bound"),
            (self.slices_overflow, "slice arrays over the buffer bound"),
            (self.slices_before_odometry, "slice arrays older than the first odometry"),
            (self.old_lap_after_reset, "messages of the previous lap after a time reset"),
            (self.time_resets, "buffer resets (time went backwards)"),
        )
        return ", ".join(f"{n} {what}" for n, what in counts if n)


@dataclass
class InputBuffer:
    max_odometry: int
    max_images: int
    odometry: deque[OdometrySample] = field(init=False)
    images: deque[ImageSlices] = field(init=False)
    counters: BufferCounters = field(default_factory=BufferCounters)
    # After a time reset: per stream (not the one that went back), its last stamp before the reset.
    _old_lap_end_ns: dict[str, int] = field(init=False, default_factory=dict)

    def __post_init__(self) -> None:
        self.odometry = deque(maxlen=self.max_odometry)
        self.images = deque(maxlen=self.max_images)

    def clear(self) -> None:
        self.odometry.clear()
        self.images.clear()
        self._old_lap_end_ns.clear()

    def _went_back(self, stream: str, stamp_ns: int, latest: deque) -> bool:
        if latest and stamp_ns < latest[-1].stamp_ns:
            logger.warning(
                "time jumped back by %.3f s (bag replayed?): clearing the buffers",
                (latest[-1].stamp_ns - stamp_ns) * 1e-9,
            )
            # The stream that went back is delivered in order, so only the other one can
            # still bring messages of the old lap.
            streams: dict[str, Sequence[OdometrySample] | Sequence[ImageSlices]] = {
                ODOMETRY: self.odometry,
                SLICES: self.images,
            }
            old_lap_end = {s: d[-1].stamp_ns for s, d in streams.items() if s != stream and d}
            self.clear()
            self._old_lap_end_ns = old_lap_end
            self.counters.time_resets += 1
            return True
        return False

    def _from_old_lap(self, stream: str, stamp_ns: int) -> bool:
        """True (and counted) for a message of the lap before the last time reset."""
        old_lap_end = self._old_lap_end_ns.get(stream)
        if old_lap_end is None:
            return False
        buffered = [d[-1].stamp_ns for d in (self.odometry, self.images) if d]
        # "Ahead of everything buffered since the reset" keeps a one-off glitch (a single
        # odometry a little back in time) from dropping the slices that follow it: the
        # odometry soon passes them and they are accepted again.
        if stamp_ns >= old_lap_end and (not buffered or stamp_ns > max(buffered)):
            self.counters.old_lap_after_reset += 1
            return True
        # This stream has reached the new lap: from here on its stamps are judged as usual.
        del self._old_lap_end_ns[stream]
        return False

    def add_odometry(self, sample: OdometrySample) -> None:
        if self._from_old_lap(ODOMETRY, sample.stamp_ns):
            return
        self._went_back(ODOMETRY, sample.stamp_ns, self.odometry)
        if len(self.odometry) == self.odometry.maxlen:
            self.counters.odometry_overflow += 1
        self.odometry.append(sample)

    def add_slices(self, image: ImageSlices) -> None:
        if self._from_old_lap(SLICES, image.stamp_ns):
            return
        self._went_back(SLICES, image.stamp_ns, self.images)
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
