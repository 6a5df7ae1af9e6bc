"""Run a node the way ros2/demos do, shared by the detector and mapper mains."""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node

from objslam_common.errors import ConfigError

SHUTDOWN_POLL_S = 0.5  # longest a shutdown by signal may go unnoticed


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
        # Not executor.spin(): rclpy's signal thread wakes the executor and only then shuts
        # the context down, so a wait that starts in between never ends (seen as a node
        # that now and then ignores SIGTERM until killed). A bounded wait looks again.
        while executor.context.ok():
            executor.spin_once(timeout_sec=SHUTDOWN_POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ConfigError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except _rclpy.RCLError:  # not in rclpy.exceptions: naming it there raised AttributeError here
        # A signal shut the context down while the executor was waiting or a callback was
        # publishing: that is a normal stop, not an error. Anything else is.
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
