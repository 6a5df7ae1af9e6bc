"""The mapper's one policy for incoming messages, shared by the node and ``objslam map``.

A message that cannot become a record is skipped and counted, never fatal: odometry with
a pose that is not finite or an orientation that is not a unit quaternion, a slice with
impossible values. Every record then goes through the :class:`InputBuffer`'s rules (time
going back clears the buffers, slice arrays older than the first odometry are left out),
and the counts end up in the map's diagnostics (:func:`input_diagnostics`) and in the
BuildMap response (``BufferCounters.describe``). Both paths taking their messages through
this module is what keeps "same bag, same map" true for damaged bags as well.
"""

from __future__ import annotations

from typing import Any

from objslam_common.errors import MessageError
from objslam_common.ros.conversions import image_slices, odometry_sample
from objslam_mapper.buffer import BufferCounters, InputBuffer


def take_odometry(buffer: InputBuffer, msg: Any) -> MessageError | None:
    """Buffer a nav_msgs/Odometry; the reason it was rejected (and counted), or None."""
    try:
        sample = odometry_sample(msg)
    except MessageError as exc:
        buffer.counters.invalid_odometry += 1
        return exc
    buffer.add_odometry(sample)
    return None


def take_slice_array(buffer: InputBuffer, msg: Any) -> int:
    """Buffer an objslam_msgs/SliceArray without its invalid slices; how many were left out (counted)."""
    image, invalid = image_slices(msg)
    buffer.counters.invalid_slices += invalid
    buffer.add_slices(image)
    return invalid


def input_diagnostics(counters: BufferCounters) -> dict[str, int]:
    """What the map's diagnostics say of its inputs: every count, and how many messages it lost."""
    return {"dropped_messages": counters.dropped(), **vars(counters)}
