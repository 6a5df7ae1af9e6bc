"""The ``mapper`` node: buffers ``/odom`` and ``/objslam/slices``; ``/objslam/build_map`` builds the map.

A thin wrapper over :func:`objslam_mapper.pipeline.build_map`. The build runs in its own
reentrant callback group under a multi-threaded executor, so the node keeps buffering
and answering while it works; a second build request during a build is refused. Results
are published with transient-local, reliable QoS so that a late subscriber still gets
them: markers (DELETEALL, then a CYLINDER and a TEXT per object), the trajectory and the
structured ObjectMap. A failed build leaves the previous map published.
"""

from __future__ import annotations

import dataclasses
import sys
import threading
import time
from pathlib import Path

from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from objslam_mapper.buffer import InputBuffer, NothingToBuildError
from objslam_mapper.catalog import load_catalog
from objslam_mapper.map_file import BuiltMap, write_map
from objslam_mapper.pipeline import MapperConfig, build_map
from objslam_mapper.ros.conversions import MessageError, image_slices, odometry_sample
from objslam_mapper.ros.map_messages import time_from_ns, to_marker_array, to_object_map, to_path
from objslam_mapper.ros.params import declare_config
from objslam_mapper.ros.spin import run_node
from objslam_msgs.msg import BuildProgress, ObjectMap, SliceArray
from objslam_msgs.srv import BuildMap

BUILD_SERVICE = "/objslam/build_map"
RESET_SERVICE = "/objslam/reset"
MARKERS_TOPIC = "/objslam/map/markers"
TRAJECTORY_TOPIC = "/objslam/map/trajectory"
OBJECTS_TOPIC = "/objslam/map/objects"
PROGRESS_TOPIC = "/objslam/map/progress"
WARN_PERIOD_S = 5.0
PROGRESS_PERIOD_S = 0.5

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)


class MapperNode(Node):
    def __init__(self) -> None:
        super().__init__("mapper")
        self.config = declare_config(self, MapperConfig)
        self.catalog = load_catalog(self.config.catalog_file or None)
        ros = self.config.ros
        self.buffer = InputBuffer(ros.max_buffered_odometry, ros.max_buffered_images)
        self._buffer_lock = threading.Lock()
        self._build_lock = threading.Lock()
        self._build_started = 0.0
        self._last_warned: dict[str, float] = {}
        self._last_progress = 0.0

        inputs = MutuallyExclusiveCallbackGroup()
        deep = QoSProfile(depth=ros.subscription_depth, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(Odometry, ros.odom_topic, self.on_odometry, deep, callback_group=inputs)
        self.create_subscription(SliceArray, ros.slices_topic, self.on_slices, deep, callback_group=inputs)

        self.markers_pub = self.create_publisher(MarkerArray, MARKERS_TOPIC, LATCHED)
        self.trajectory_pub = self.create_publisher(PathMsg, TRAJECTORY_TOPIC, LATCHED)
        self.objects_pub = self.create_publisher(ObjectMap, OBJECTS_TOPIC, LATCHED)
        self.progress_pub = self.create_publisher(BuildProgress, PROGRESS_TOPIC, QoSProfile(depth=10))

        self.create_service(BuildMap, BUILD_SERVICE, self.on_build_map, callback_group=ReentrantCallbackGroup())
        self.create_service(Trigger, RESET_SERVICE, self.on_reset, callback_group=MutuallyExclusiveCallbackGroup())
        self.get_logger().info(
            f"buffering {ros.odom_topic} and {ros.slices_topic}; call {BUILD_SERVICE} to build the map"
        )

    # -- inputs ----------------------------------------------------------------------------

    def _warn(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last_warned.get(key, -WARN_PERIOD_S) >= WARN_PERIOD_S:
            self._last_warned[key] = now
            self.get_logger().warn(text)

    def on_odometry(self, msg: Odometry) -> None:
        try:
            sample = odometry_sample(msg)
        except MessageError as exc:
            with self._buffer_lock:
                self.buffer.counters.invalid_odometry += 1
                count = self.buffer.counters.invalid_odometry
            self._warn(exc.kind, f"rejected an odometry message ({count} so far): {exc}")
            return
        with self._buffer_lock:
            resets = self.buffer.counters.time_resets
            overflow = self.buffer.counters.odometry_overflow
            self.buffer.add_odometry(sample)
            self._report_buffer_events(resets, overflow, "odometry", self.buffer.counters.odometry_overflow)

    def on_slices(self, msg: SliceArray) -> None:
        image, invalid = image_slices(msg)
        with self._buffer_lock:
            if invalid:
                self.buffer.counters.invalid_slices += invalid
                self._warn("slices", f"left out {invalid} invalid slice(s) of one image")
            resets = self.buffer.counters.time_resets
            overflow = self.buffer.counters.slices_overflow
            self.buffer.add_slices(image)
            self._report_buffer_events(resets, overflow, "slice", self.buffer.counters.slices_overflow)

    def _report_buffer_events(self, resets_before: int, overflow_before: int, what: str, overflow_now: int) -> None:
        if self.buffer.counters.time_resets != resets_before:
            self.get_logger().warn("time jumped backwards (bag played in a loop?): buffers cleared")
        if overflow_now != overflow_before:
            self._warn(f"overflow-{what}", f"{what} buffer full: dropping the oldest ({overflow_now} dropped so far)")

    def on_reset(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self._buffer_lock:
            self.buffer.clear()
        response.success = True
        response.message = "buffers cleared"
        self.get_logger().info("buffers cleared on request")
        return response

    # -- building --------------------------------------------------------------------------

    def on_build_map(self, request: BuildMap.Request, response: BuildMap.Response) -> BuildMap.Response:
        if not self._build_lock.acquire(blocking=False):
            response.success = False
            response.message = (
                f"a build is already running (for {time.monotonic() - self._build_started:.1f} s); try again later"
            )
            return response
        try:
            self._build_started = time.monotonic()
            self._build(request, response)
        finally:
            self._build_lock.release()
        response.elapsed_sec = time.monotonic() - self._build_started
        return response

    def _build(self, request: BuildMap.Request, response: BuildMap.Response) -> None:
        with self._buffer_lock:
            try:
                odometry, images = self.buffer.snapshot()
            except NothingToBuildError as exc:
                response.success = False
                response.message = f"cannot build: {exc}"
                self.get_logger().warn(response.message)
                return
            counters = dataclasses.replace(self.buffer.counters)
        sampler = self.config.sampler
        sampler = dataclasses.replace(
            sampler,
            samples=request.samples or sampler.samples,
            burn_in=request.burn_in or sampler.burn_in,
            seed=request.seed or sampler.seed,
        )
        config = dataclasses.replace(self.config, sampler=sampler)
        self.get_logger().info(
            f"building from {len(odometry)} odometry messages and {len(images)} slice arrays "
            f"({sampler.samples} samples, burn-in {sampler.burn_in}, seed {sampler.seed})"
        )
        try:
            built = build_map(odometry, images, config, self.catalog, progress=self._progress)
        except Exception as exc:
            response.success = False
            response.message = f"build failed: {type(exc).__name__}: {exc}"
            self.get_logger().error(response.message)
            self._progress("failed", 0, 0)
            return
        built = dataclasses.replace(
            built, diagnostics={**built.diagnostics, "dropped_messages": counters.dropped(), **vars(counters)}
        )
        self._publish(built)
        self._write_outputs(built)
        self._progress("done", 1, 1)
        response.success = True
        response.object_count = len(built.objects)
        dropped = counters.dropped()
        response.message = (
            f"built a map of {len(built.objects)} objects ({len(built.rejected)} rejected) from {len(images)} images"
            + (f"; {dropped} messages were dropped before the build" if dropped else "; no message was dropped")
        )
        self.get_logger().info(response.message)

    def _progress(self, phase: str, done: int, total: int) -> None:
        now = time.monotonic()
        final = phase in ("done", "failed") or done == total
        if not final and now - self._last_progress < PROGRESS_PERIOD_S:
            return
        self._last_progress = now
        elapsed = now - self._build_started
        msg = BuildProgress(phase=phase, done=int(done), total=int(total), elapsed_sec=float(elapsed))
        msg.header.stamp = self.get_clock().now().to_msg()
        self.progress_pub.publish(msg)
        if phase == "sampling" and total:
            self.get_logger().info(f"sampling: {done}/{total} ({elapsed:.1f} s)", throttle_duration_sec=5.0)

    def _publish(self, built: BuiltMap) -> None:
        stamp = self.get_clock().now().to_msg()
        if built.trajectory:
            stamp = time_from_ns(built.trajectory[-1].stamp_ns)
        self.markers_pub.publish(to_marker_array(built, self.catalog, stamp))
        self.trajectory_pub.publish(to_path(built, stamp))
        self.objects_pub.publish(to_object_map(built, stamp))

    def _write_outputs(self, built: BuiltMap) -> None:
        out_dir = self.config.ros.output_dir
        if not out_dir:
            return
        path = write_map(Path(out_dir) / "map.yaml", built)
        self.get_logger().info(f"map written to {path}")
        if not self.config.ros.write_figures:
            return
        try:
            from objslam_tools.figures import write_figures  # optional: figures need objslam_tools
        except ImportError:
            self.get_logger().warn("write_figures is set but objslam_tools is not installed; no figures")
            return
        paths = write_figures(built, Path(out_dir), catalog=self.catalog, mount=self.config.camera_mount.to_mount())
        self.get_logger().info(f"figures written: {', '.join(str(p) for p in paths)}")

    def summary(self) -> str:
        c = self.buffer.counters
        buffered = f"buffered {len(self.buffer.odometry)} odometry, {len(self.buffer.images)} slice arrays"
        return f"{buffered}; dropped {c.dropped()}"


def main(args: list[str] | None = None) -> int:
    return run_node("mapper", MapperNode, args, make_executor=lambda: MultiThreadedExecutor(num_threads=4))


if __name__ == "__main__":
    sys.exit(main())
