"""How a caller notices that the mapper died in the middle of a build.

A killed process never says goodbye, and DDS notices a participant gone only when its
lease ends (about 20 s with Fast DDS's defaults), so a service that "went away" tells the
caller late. The mapper's progress publisher offers a short liveliness lease instead
(``AUTOMATIC``: asserted by the middleware's own threads, whatever the build holds), and a
caller that watches the topic with a compatible lease hears "not alive" soon after the
mapper's end (1.05 s after SIGKILL with a 1 s lease on Fast DDS; 4.4 s with this module's
2 s lease in the node tests, where ~22 s passed before the service was seen gone).
"""

from __future__ import annotations

from rclpy.duration import Duration
from rclpy.qos import QoSLivelinessPolicy, QoSProfile

PROGRESS_TOPIC = "/objslam/map/progress"  # the mapper's, whose liveliness a caller watches
LEASE_S = 2.0  # offered by the mapper: long enough that a busy machine does not miss an assertion


def offered(depth: int = 10) -> QoSProfile:
    """The publisher's profile: automatic liveliness with a lease of ``LEASE_S``."""
    return QoSProfile(
        depth=depth, liveliness=QoSLivelinessPolicy.AUTOMATIC, liveliness_lease_duration=Duration(seconds=LEASE_S)
    )


def watched(depth: int = 10) -> QoSProfile:
    """A subscriber's profile that gets the liveliness events of :func:`offered` (a subscriber
    may ask for a lease no shorter than the one offered)."""
    return QoSProfile(
        depth=depth,
        liveliness=QoSLivelinessPolicy.AUTOMATIC,
        liveliness_lease_duration=Duration(seconds=2.0 * LEASE_S),
    )
