"""``objslam play BAG``: publish a bag with its recorded timing and ``/clock``.

A whole bag without a camera image topic is refused as bad input: the pipeline would
have nothing to detect in it. ``--topics`` plays chosen topics of any bag. Played whole, a
topic whose message type this install lacks (e.g. /tf_static: tf2_msgs is not on PyPI) is
left out with one warning: the nodes read the mount from their parameters, not from tf.
"""

from __future__ import annotations

import argparse
import logging
from typing import TYPE_CHECKING

from objslam_tools.errors import UserError

if TYPE_CHECKING:
    from objslam_tools.bag import Bag, RawMessage

logger = logging.getLogger(__name__)

# Reliable delivery still loses what falls out of the publisher's history while a busy
# subscriber lags; 1000 messages is 10 s of odometry at 100 Hz.
PUBLISHER_DEPTH = 1000
ACK_TIMEOUT_S = 5.0  # at the end, how long to wait for subscribers to acknowledge the last messages


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "play",
        help="publish a bag's topics with recorded timing and /clock",
        description=(
            "Publish a bag's topics with their recorded timing, and /clock. Played whole, a bag must hold a "
            "camera image topic (sensor_msgs/msg/Image or CompressedImage), since the detector needs one; "
            "a bag without is refused. With --topics, only the listed topics must exist."
        ),
    )
    parser.add_argument("bag", help="rosbag2 directory (MCAP or sqlite3)")
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    parser.add_argument("--loop", action="store_true", help="start again at the end (time jumps back)")
    parser.add_argument(
        "--topics",
        nargs="+",
        default=None,
        metavar="TOPIC",
        help="only these topics; each must be in the bag, and no image topic is required",
    )
    parser.add_argument("--delay", type=float, default=1.0, metavar="S", help="wait S s before the first message")
    parser.add_argument("--clock-hz", type=float, default=100.0, help="/clock rate in wall Hz (0: with messages)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import time

    import rclpy
    from rclpy.duration import Duration
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile

    # The bag reader's type store loads in a third of a second: only for this verb.
    from objslam_tools.bag import open_bag
    from objslam_tools.player import PlayOptions, make_clock_publisher, play
    from objslam_tools.ros_util import import_message_type, ros_node

    if args.rate <= 0:
        raise UserError(f"--rate must be > 0, got {args.rate}")
    bag = open_bag(args.bag)
    if args.topics is None:
        _require_image_topic(bag)
    topics = args.topics or sorted(bag.topics)
    for topic in topics:
        bag.require_topic(topic)
    types = {}
    for topic in topics:
        try:
            types[topic] = import_message_type(bag.topics[topic].msgtype)
        except UserError as exc:
            if args.topics is not None:
                raise
            logger.warning("not playing %s: %s", topic, exc)
    topics = [t for t in topics if t in types]
    if not any(bag.topics[t].count for t in topics):
        raise UserError(f"bag {bag.path} has no messages on {', '.join(topics)}")
    options = PlayOptions(rate=args.rate, loop=args.loop, clock_hz=args.clock_hz, delay_s=args.delay)

    with ros_node("objslam_player") as node:
        publishers = {
            topic: node.create_publisher(types[topic], topic, QoSProfile(depth=PUBLISHER_DEPTH)) for topic in topics
        }
        publish_clock = make_clock_publisher(node)

        def publish(message: RawMessage) -> None:
            publishers[message.topic].publish(message.data)

        def messages():
            return bag.raw_messages(topics)

        logger.info(
            "playing %s: %d topics, %.1f s at rate %g%s",
            bag.path,
            len(topics),
            bag.duration_s,
            args.rate,
            " (looping)" if args.loop else "",
        )
        try:
            time.sleep(options.delay_s)  # let subscribers discover the publishers first
            count = play(messages, publish, publish_clock, options, keep_going=rclpy.ok)
            # Leaving at once would drop what reliable subscribers have not acknowledged yet
            # (the bag's last messages), as `ros2 bag play --wait-for-all-acked` avoids.
            for publisher in publishers.values():
                publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
        except (KeyboardInterrupt, ExternalShutdownException):
            return 0
        logger.info("published %d messages", count)
    return 0


def _require_image_topic(bag: Bag) -> None:
    """UserError unless the bag holds an image topic of either type.

    Any name counts (like ``Bag.image_topic``, which ``objslam map`` uses), but several
    are fine here: playing needs no choice between them, only something to see.
    """
    from objslam_tools.bag import COMPRESSED_IMAGE_TYPE, IMAGE_TYPE

    if not (bag.topics_of_type(IMAGE_TYPE) or bag.topics_of_type(COMPRESSED_IMAGE_TYPE)):
        raise UserError(
            f"bag {bag.path} has no camera image topic ({IMAGE_TYPE} or {COMPRESSED_IMAGE_TYPE}); "
            "to play it anyway, name the topics with --topics"
        )
