"""The mapper's input buffers: bounds, time jumps, and what is missing before a build."""

from __future__ import annotations

import pytest

from objslam_common.records import ImageSlices, OdometrySample, SliceMeasurement
from objslam_mapper.buffer import BufferCounters, InputBuffer, NothingToBuildError

SLICE = SliceMeasurement("red", 1.0, 0.1, 0.05, -0.2, 0.1)


def odom(t: int) -> OdometrySample:
    return OdometrySample(t, 0.0, 0.0, 0.0)


def test_missing_inputs_are_named():
    buffer = InputBuffer(10, 10)
    with pytest.raises(NothingToBuildError, match="no odometry and no slices"):
        buffer.snapshot()
    buffer.add_slices(ImageSlices(5, (SLICE,)))
    with pytest.raises(NothingToBuildError, match="no odometry received"):
        buffer.snapshot()
    buffer.clear()
    buffer.add_odometry(odom(1))
    with pytest.raises(NothingToBuildError, match="no slices received"):
        buffer.snapshot()


def test_bounded_buffers_drop_the_oldest_and_count():
    buffer = InputBuffer(max_odometry=3, max_images=2)
    for t in range(5):
        buffer.add_odometry(odom(t))
        buffer.add_slices(ImageSlices(t))
    assert [o.stamp_ns for o in buffer.odometry] == [2, 3, 4]
    assert [i.stamp_ns for i in buffer.images] == [3, 4]
    assert buffer.counters.odometry_overflow == 2 and buffer.counters.slices_overflow == 3
    assert buffer.counters.dropped() == 5


def test_time_going_back_clears_everything():
    buffer = InputBuffer(10, 10)
    for t in (10, 20, 30):
        buffer.add_odometry(odom(t))
        buffer.add_slices(ImageSlices(t))
    buffer.add_odometry(odom(5))
    assert [o.stamp_ns for o in buffer.odometry] == [5]
    assert not buffer.images
    assert buffer.counters.time_resets == 1


def test_slices_older_than_the_first_odometry_are_left_out_and_counted():
    buffer = InputBuffer(10, 10)
    buffer.add_slices(ImageSlices(1, (SLICE,)))
    buffer.add_slices(ImageSlices(2, (SLICE,)))
    buffer.add_odometry(odom(2))
    buffer.add_slices(ImageSlices(3, (SLICE,)))
    _odometry, images = buffer.snapshot()
    assert [i.stamp_ns for i in images] == [2, 3]
    assert buffer.counters.slices_before_odometry == 1


def test_old_lap_slices_in_flight_after_a_reset_are_dropped_not_a_second_reset():
    # A bag played with --loop: the odometry goes back first; the detector lags, so a slice
    # array of the previous lap (stamped after the new lap's start) arrives after the reset.
    buffer = InputBuffer(10, 10)
    for t in (10, 20, 30):
        buffer.add_odometry(odom(t))
    for t in (10, 20):
        buffer.add_slices(ImageSlices(t, (SLICE,)))
    buffer.add_odometry(odom(5))  # new lap
    buffer.add_slices(ImageSlices(25, (SLICE,)))  # old lap, still in flight
    buffer.add_odometry(odom(6))
    buffer.add_slices(ImageSlices(6, (SLICE,)))  # new lap: must not look like time going back
    assert buffer.counters.time_resets == 1
    assert buffer.counters.old_lap_after_reset == 1
    assert buffer.counters.dropped() == 1
    odometry, images = buffer.snapshot()
    assert [o.stamp_ns for o in odometry] == [5, 6]  # the new lap's first odometry survived
    assert [i.stamp_ns for i in images] == [6]


def test_old_lap_odometry_in_flight_after_a_slice_reset_is_dropped():
    buffer = InputBuffer(10, 10)
    for t in (10, 20):
        buffer.add_odometry(odom(t))
        buffer.add_slices(ImageSlices(t, (SLICE,)))
    buffer.add_slices(ImageSlices(5, (SLICE,)))  # this time the slices go back first
    buffer.add_odometry(odom(30))  # old lap
    buffer.add_odometry(odom(4))  # new lap
    assert buffer.counters.time_resets == 1 and buffer.counters.old_lap_after_reset == 1
    assert [o.stamp_ns for o in buffer.odometry] == [4]
    assert [i.stamp_ns for i in buffer.images] == [5]


def test_one_odometry_a_little_back_in_time_does_not_drop_the_slices_that_follow():
    # Not a loop but a glitch: the odometry goes on past the slices, which are kept again.
    buffer = InputBuffer(10, 10)
    for t in (10, 20, 30):
        buffer.add_odometry(odom(t))
        buffer.add_slices(ImageSlices(t, (SLICE,)))
    buffer.add_odometry(odom(29))
    buffer.add_odometry(odom(40))
    buffer.add_slices(ImageSlices(35, (SLICE,)))
    buffer.add_slices(ImageSlices(38, (SLICE,)))
    assert buffer.counters.time_resets == 1 and buffer.counters.old_lap_after_reset == 0
    assert [i.stamp_ns for i in buffer.images] == [35, 38]


def test_counters_are_described_for_the_user():
    counters = BufferCounters(invalid_odometry=2, time_resets=1)
    assert counters.describe() == (
        "2 invalid odometry messages (NaN or non-unit quaternion), 1 buffer resets (time went backwards)"
    )
    assert BufferCounters().describe() == ""
