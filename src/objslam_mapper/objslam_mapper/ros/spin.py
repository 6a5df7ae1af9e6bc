"""Run a node the way ros2/demos do, shared by the detector and mapper mains."""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from objslam_mapper.config import ConfigError


def run_node(
    name: str,
    make_node: Callable[[], Node],
    args: list[str] | None = None,
    make_executor: Callable[[], Executor] = SingleThreadedExecutor,
) -> int:
    """Init, spin until shutdown, clean up. A bad parameter is one line and exit code 2."""
    rclpy.init(args=args)
    node = None
    try:
        node = make_node()
        executor = make_executor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ConfigError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except rclpy.exceptions.RCLError:
        # A signal shut the context down while a callback was publishing: that is a
        # normal stop, not an error. Anything else is.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            summary = getattr(node, "summary", None)
            if summary is not None:
                # After a signal the context is gone and the ROS logger cannot reach rosout.
                print(f"[{name}] {summary()}", file=sys.stderr)
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
