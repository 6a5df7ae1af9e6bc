"""Publish a bag's raw messages with their recorded timing, plus ``/clock``.

Like ``ros2 bag play --clock``: messages go out in log-time order, paced by the bag's
timestamps divided by ``rate``; ``/clock`` carries the bag time so nodes with
``use_sim_time`` follow the bag. Messages are published as the CDR bytes stored in
the bag, never deserialized.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from objslam_tools.bag import RawMessage

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlayOptions:
    rate: float = 1.0  # bag seconds per wall second
    loop: bool = False
    clock_hz: float = 100.0  # /clock publications per wall second
    delay_s: float = 1.0  # wall time to wait before the first message, for discovery


class Pacer:
    """Maps bag time to wall time and waits, publishing the clock while it waits."""

    def __init__(self, rate: float, clock_hz: float, publish_clock: Callable[[int], None]):
        self._rate = rate
        self._clock_period_s = 1.0 / clock_hz if clock_hz > 0 else None
        self._publish_clock = publish_clock
        self._bag_start_ns: int | None = None
        self._wall_start = 0.0
        self._last_clock = -1e9

    def restart(self) -> None:
        self._bag_start_ns = None

    def bag_now_ns(self) -> int:
        assert self._bag_start_ns is not None
        return self._bag_start_ns + int((time.monotonic() - self._wall_start) * self._rate * 1e9)

    def wait_until(self, stamp_ns: int, keep_going: Callable[[], bool]) -> None:
        if self._bag_start_ns is None:
            self._bag_start_ns = stamp_ns
            self._wall_start = time.monotonic()
            self._publish_clock(stamp_ns)
            return
        target = self._wall_start + (stamp_ns - self._bag_start_ns) * 1e-9 / self._rate
        while keep_going():
            now = time.monotonic()
            if self._clock_period_s is not None and now - self._last_clock >= self._clock_period_s:
                self._publish_clock(min(self.bag_now_ns(), stamp_ns))
                self._last_clock = now
            remaining = target - now
            if remaining <= 0:
                break
            time.sleep(min(remaining, self._clock_period_s or remaining, 0.05))


def play(
    messages: Callable[[], Iterable[RawMessage]],
    publish: Callable[[RawMessage], None],
    publish_clock: Callable[[int], None],
    options: PlayOptions,
    keep_going: Callable[[], bool] = lambda: True,
) -> int:
    """Play ``messages()`` (called again for each loop); returns how many were published."""
    pacer = Pacer(options.rate, options.clock_hz, publish_clock)
    published = 0
    while keep_going():
        pacer.restart()
        for message in messages():
            if not keep_going():
                break
            pacer.wait_until(message.stamp_ns, keep_going)
            publish(message)
            published += 1
        if not options.loop:
            break
        logger.info("end of bag after %d messages; looping (time jumps back)", published)
    return published


def make_clock_publisher(node: Any) -> Callable[[int], None]:
    from rclpy.qos import QoSProfile
    from rosgraph_msgs.msg import Clock

    pub = node.create_publisher(Clock, "/clock", QoSProfile(depth=10))

    def publish_clock(stamp_ns: int) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(stamp_ns), 1_000_000_000)
        pub.publish(msg)

    return publish_clock
