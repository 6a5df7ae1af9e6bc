"""``objslam echo TOPIC``: print messages as YAML, like ``ros2 topic echo``."""

from __future__ import annotations

import argparse
import sys
import time

import yaml

from objslam_tools.errors import UserError
from objslam_tools.ros_util import import_message_type, message_to_plain, qos_matching_publishers, ros_node

NOT_RECEIVED_EXIT = 1


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("echo", help="print a topic's messages as YAML (latched ones too)")
    parser.add_argument("topic", help="topic name, e.g. /objslam/map/markers")
    parser.add_argument("--once", action="store_true", help="print one message and exit")
    parser.add_argument("--timeout", type=float, default=None, metavar="S", help="give up after S seconds")
    parser.add_argument("--type", default=None, help="message type (pkg/msg/Type) if no publisher is up yet")
    parser.add_argument(
        "--truncate-length", type=int, default=128, help="cut sequences and strings longer than this (0: never)"
    )
    parser.set_defaults(func=run)


def _resolve_type(node, topic: str, explicit: str | None, deadline: float | None) -> str:
    if explicit:
        return explicit
    while True:
        for name, types in node.get_topic_names_and_types():
            if name == topic and types:
                return types[0]
        if deadline is not None and time.monotonic() > deadline:
            raise UserError(f"no publisher of {topic} appeared (give --type to wait for one)")
        time.sleep(0.1)


def run(args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException

    topic = args.topic if args.topic.startswith("/") else "/" + args.topic
    deadline = None if args.timeout is None else time.monotonic() + args.timeout
    truncate = args.truncate_length or None
    received = 0
    with ros_node("objslam_echo") as node:
        type_name = _resolve_type(node, topic, args.type, deadline)
        msg_type = import_message_type(type_name)
        # Let discovery settle so the QoS we pick matches every publisher.
        time.sleep(0.2)
        qos = qos_matching_publishers(node, topic)

        def on_message(msg) -> None:
            nonlocal received
            received += 1
            if args.once and received > 1:
                return
            sys.stdout.write(yaml.safe_dump(message_to_plain(msg, truncate), sort_keys=False, width=120))
            sys.stdout.write("---\n")
            sys.stdout.flush()

        node.create_subscription(msg_type, topic, on_message, qos)
        try:
            while rclpy.ok() and not (args.once and received):
                if deadline is not None and time.monotonic() > deadline:
                    break
                rclpy.spin_once(node, timeout_sec=0.1)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
    if args.once and not received:
        print(f"objslam echo: no message on {topic} within {args.timeout} s", file=sys.stderr)
        return NOT_RECEIVED_EXIT
    return 0
