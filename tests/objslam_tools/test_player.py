"""The player's pacing and looping, without a ROS graph."""

from __future__ import annotations

import itertools
import time

from objslam_tools.bag import RawMessage
from objslam_tools.player import PlayOptions, play

START_NS = 1_700_000_000_000_000_000


def _messages(n: int, period_ns: int) -> list[RawMessage]:
    return [RawMessage("/t", START_NS + i * period_ns, bytes([i]), "std_msgs/msg/UInt8") for i in range(n)]


def test_messages_keep_order_and_recorded_spacing_scaled_by_rate():
    msgs = _messages(5, 100_000_000)  # 0.4 s of bag time
    seen: list[tuple[float, int]] = []
    clock: list[int] = []
    play(lambda: msgs, lambda m: seen.append((time.monotonic(), m.stamp_ns)), clock.append, PlayOptions(rate=4.0))
    assert [s for _, s in seen] == [m.stamp_ns for m in msgs]
    wall = seen[-1][0] - seen[0][0]
    assert 0.09 <= wall < 0.5  # 0.4 s of bag at 4x is 0.1 s of wall time
    assert clock[0] == START_NS
    assert all(b >= a for a, b in itertools.pairwise(clock))
    assert max(clock) <= msgs[-1].stamp_ns


def test_loop_replays_until_stopped():
    msgs = _messages(3, 1_000_000)
    seen: list[int] = []

    def keep_going() -> bool:
        return len(seen) < 7

    count = play(lambda: msgs, lambda m: seen.append(m.stamp_ns), lambda _t: None, PlayOptions(loop=True), keep_going)
    assert count == 7
    assert seen[:6] == [m.stamp_ns for m in msgs] * 2
