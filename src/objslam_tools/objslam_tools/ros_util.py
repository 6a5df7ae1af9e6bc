"""Small rclpy helpers for the CLI verbs that talk to a live ROS graph.

ros2cli is not available from PyPI, so what it would do for us (resolve a type name,
print a message as YAML, match a publisher's QoS) lives here.
"""

from __future__ import annotations

import array
import contextlib
import importlib
from collections.abc import Iterator
from typing import Any

import numpy as np

from objslam_tools.errors import UserError


def import_message_type(type_name: str) -> Any:
    """The Python class of 'pkg/msg/Type' (or 'pkg/srv/Type', 'pkg/Type')."""
    parts = type_name.split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3:
        raise UserError(f"not a ROS type name: {type_name!r} (expected pkg/msg/Type)")
    pkg, kind, name = parts
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError) as exc:
        raise UserError(f"message type {type_name} is not installed here") from exc


def message_to_plain(msg: Any, truncate_length: int | None = 128) -> Any:
    """A message as nested dicts/lists of plain values, like ``ros2 topic echo`` prints it.

    Sequences and strings longer than ``truncate_length`` are cut and marked with '...'.
    """

    def trunc_seq(values: list[Any]) -> list[Any]:
        if truncate_length is not None and len(values) > truncate_length:
            return [*values[:truncate_length], "..."]
        return values

    if hasattr(msg, "get_fields_and_field_types"):
        return {
            field: message_to_plain(getattr(msg, field), truncate_length) for field in msg.get_fields_and_field_types()
        }
    if isinstance(msg, (bytes, bytearray)):
        return trunc_seq(list(msg))
    if isinstance(msg, (np.ndarray, array.array)):
        return trunc_seq([v.item() if isinstance(v, np.generic) else v for v in list(msg)])
    if isinstance(msg, (list, tuple)):
        return trunc_seq([message_to_plain(v, truncate_length) for v in msg])
    if isinstance(msg, str) and truncate_length is not None and len(msg) > truncate_length:
        return msg[:truncate_length] + "..."
    if isinstance(msg, np.generic):
        return msg.item()
    return msg


@contextlib.contextmanager
def ros_node(name: str, **node_kwargs: Any) -> Iterator[Any]:
    """rclpy context + node for a CLI verb; always shuts down, even on Ctrl-C."""
    import rclpy
    from rclpy.node import Node

    rclpy.init()
    node = Node(name, **node_kwargs)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def qos_matching_publishers(node: Any, topic: str, depth: int = 10) -> Any:
    """A subscription QoS compatible with every current publisher of ``topic``.

    Transient-local when all publishers latch (so a late subscriber still gets their
    last messages), best-effort when any publisher is best-effort.
    """
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    infos = node.get_publishers_info_by_topic(topic)
    profile = QoSProfile(depth=depth)
    if infos and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos):
        profile.durability = DurabilityPolicy.TRANSIENT_LOCAL
    else:
        profile.durability = DurabilityPolicy.VOLATILE
    if any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos):
        profile.reliability = ReliabilityPolicy.BEST_EFFORT
    else:
        profile.reliability = ReliabilityPolicy.RELIABLE
    return profile
