"""Run a node the way ros2/demos do, shared by the detector and mapper mains."""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Callable

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from objslam_common.errors import ConfigError

SHUTDOWN_POLL_S = 0.5  # longest a shutdown by signal may go unnoticed
STOP_GRACE_S = 15.0  # how long a callback in flight (a build) gets to answer after a signal
ANSWER_TAIL_S = 0.3  # a service's answer leaves just after its callback returns


def run_node(
    name: str,
    make_node: Callable[[], Node],
    args: list[str] | None = None,
    make_executor: Callable[[], Executor] = SingleThreadedExecutor,
) -> int:
    """Init, spin until SIGINT/SIGTERM, let callbacks in flight answer, clean up.

    A bad parameter is one line and exit code 2. rclpy's own signal handler is not used: it
    shuts the context down at once, and a callback still running (a build) then fails on
    destroyed handles and its caller never gets an answer. Here a signal calls the node's
    ``request_stop()`` (if it has one: the mapper cancels its build) and the executor keeps
    spinning while the node says it is ``busy()``, up to STOP_GRACE_S, so that the answer
    goes out before the node and the context go. (``Executor.shutdown`` does not wait for
    callbacks in flight in this rclpy, whatever its docstring says.)
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    node = None
    executor = None

    def on_signal(_signum: int, _frame: object) -> None:
        stop.set()
        request_stop = getattr(node, "request_stop", None)
        if request_stop is not None:
            request_stop()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        node = make_node()
        executor = make_executor()
        executor.add_node(node)
        # Not executor.spin(): a bounded wait looks at the stop flag again.
        while not stop.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=SHUTDOWN_POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ConfigError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except _rclpy.RCLError:  # not in rclpy.exceptions: naming it there raised AttributeError here
        # The context shut down (by another thread) while the executor was waiting or a
        # callback was publishing: that is a normal stop, not an error. Anything else is.
        if rclpy.ok():
            raise
    finally:
        if executor is not None:
            _finish_callbacks(node, executor)
            executor.shutdown(timeout_sec=0)
        if node is not None:
            summary = getattr(node, "summary", None)
            if summary is not None:
                print(f"[{name}] {summary()}", file=sys.stderr)
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0


def _finish_callbacks(node: Node | None, executor: Executor) -> None:
    busy = getattr(node, "busy", None)
    if busy is None or not busy():
        return
    deadline = time.monotonic() + STOP_GRACE_S
    try:
        while busy() and time.monotonic() < deadline and executor.context.ok():
            executor.spin_once(timeout_sec=0.1)
        tail = time.monotonic() + ANSWER_TAIL_S
        while time.monotonic() < tail and executor.context.ok():
            executor.spin_once(timeout_sec=0.05)
    except (KeyboardInterrupt, ExternalShutdownException, _rclpy.RCLError):
        pass
