"""The ``mapper`` node: buffers ``/odom`` and ``/objslam/slices``; ``/objslam/build_map`` builds the map.

A thin wrapper over :func:`objslam_mapper.pipeline.build_map`. The build runs in its own
reentrant callback group under a multi-threaded executor, so the node keeps buffering
and answering while it works; a second build request during a build is refused. Results
are published with transient-local, reliable QoS so that a late subscriber still gets
them: markers (DELETEALL, then a CYLINDER and a TEXT per object), the trajectory and the
structured ObjectMap. A failed build leaves the previous map published; a map that was
built but could not be written to ``ros.output_dir`` is still published (with a warning).
No user-caused fault (bad input, bad request, unwritable output) raises out of a callback:
the multi-threaded executor would keep the exception in a future nobody reads, and the
caller would wait for an answer forever (a single-threaded one would stop the node).
"""

from __future__ import annotations

import dataclasses
import sys
import threading
import time
import traceback
from pathlib import Path

from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from objslam_common.catalog import load_catalog
from objslam_common.config import to_mapping
from objslam_common.ros import liveliness
from objslam_common.ros.conversions import time_from_ns
from objslam_common.ros.params import declare_config
from objslam_common.ros.spin import run_node
from objslam_mapper.buffer import BufferCounters, InputBuffer, NothingToBuildError
from objslam_mapper.config import MapperConfig
from objslam_mapper.inference.chains import ChainRunner
from objslam_mapper.map_file import BuiltMap, MapFileError, write_map
from objslam_mapper.parallel import RayRunner, chain_runner
from objslam_mapper.pipeline import build_map
from objslam_mapper.ros.intake import input_diagnostics, take_odometry, take_slice_array
from objslam_mapper.ros.map_messages import chain_agreement, to_marker_array, to_object_map, to_path
from objslam_msgs.msg import BuildProgress, ObjectMap, SliceArray
from objslam_msgs.srv import BuildMap

BUILD_SERVICE = "/objslam/build_map"
RESET_SERVICE = "/objslam/reset"
MARKERS_TOPIC = "/objslam/map/markers"
TRAJECTORY_TOPIC = "/objslam/map/trajectory"
OBJECTS_TOPIC = "/objslam/map/objects"
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
        self._ray_runner: RayRunner | None = None
        self._stopping = threading.Event()

        inputs = MutuallyExclusiveCallbackGroup()
        deep = QoSProfile(depth=ros.subscription_depth, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(Odometry, ros.odom_topic, self.on_odometry, deep, callback_group=inputs)
        self.create_subscription(SliceArray, ros.slices_topic, self.on_slices, deep, callback_group=inputs)

        self.markers_pub = self.create_publisher(MarkerArray, MARKERS_TOPIC, LATCHED)
        self.trajectory_pub = self.create_publisher(PathMsg, TRAJECTORY_TOPIC, LATCHED)
        self.objects_pub = self.create_publisher(ObjectMap, OBJECTS_TOPIC, LATCHED)
        # A short liveliness lease: a caller notices a mapper killed mid-build (objslam_common.ros.liveliness).
        self.progress_pub = self.create_publisher(BuildProgress, liveliness.PROGRESS_TOPIC, liveliness.offered())

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
        with self._buffer_lock:
            before = dataclasses.replace(self.buffer.counters)
            problem = take_odometry(self.buffer, msg)
            if problem is not None:
                count = self.buffer.counters.invalid_odometry
                self._warn(problem.kind, f"rejected an odometry message ({count} so far): {problem}")
                return
            self._report_buffer_events(before, "odometry", "odometry_overflow")

    def on_slices(self, msg: SliceArray) -> None:
        with self._buffer_lock:
            before = dataclasses.replace(self.buffer.counters)
            if take_slice_array(self.buffer, msg):
                self._warn("slices", f"left out {self.buffer.counters.invalid_slices} invalid slice(s) so far")
            self._report_buffer_events(before, "slice", "slices_overflow")

    def _report_buffer_events(self, before: BufferCounters, what: str, overflow_field: str) -> None:
        now = self.buffer.counters
        if now.time_resets != before.time_resets:
            self.get_logger().warn("time jumped backwards (bag played in a loop?): buffers cleared")
        if now.old_lap_after_reset != before.old_lap_after_reset:
            self._warn(
                "old-lap",
                f"dropped a {what} message of the lap before the time reset, still in flight "
                f"({now.old_lap_after_reset} so far)",
            )
        overflow = getattr(now, overflow_field)
        if overflow != getattr(before, overflow_field):
            self._warn(f"overflow-{what}", f"{what} buffer full: dropping the oldest ({overflow} dropped so far)")

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
        except Exception as exc:
            # Last resort, for a fault nothing below anticipated: an exception leaving the
            # callback would leave the caller without an answer (see the module docstring).
            self._fail(response, f"build failed: {type(exc).__name__}: {exc}")
            self.get_logger().error(traceback.format_exc())
        finally:
            self._build_lock.release()
        response.elapsed_sec = time.monotonic() - self._build_started
        return response

    def _fail(self, response: BuildMap.Response, message: str) -> None:
        response.success = False
        response.message = message
        self.get_logger().error(message)
        self._progress("failed", 0, 0)

    def _request_config(self, request: BuildMap.Request) -> MapperConfig:
        """The config of this build; ValueError for a request that cannot run (burn-in >= samples)."""
        sampler = self.config.sampler
        sampler = dataclasses.replace(
            sampler,
            samples=request.samples or sampler.samples,
            burn_in=request.burn_in or sampler.burn_in,
            seed=request.seed or sampler.seed,
            chains=request.chains or sampler.chains,
        )
        return dataclasses.replace(self.config, sampler=sampler)

    def _build(self, request: BuildMap.Request, response: BuildMap.Response) -> None:
        try:
            config = self._request_config(request)
        except ValueError as exc:
            # e.g. `--samples 50` with the default burn-in of 2500
            defaults = self.config.sampler
            response.success = False
            response.message = (
                f"invalid request: {exc} (0 in the request means the parameter: "
                f"samples {defaults.samples}, burn_in {defaults.burn_in})"
            )
            self.get_logger().warn(response.message)
            return
        with self._buffer_lock:
            try:
                odometry, images = self.buffer.snapshot()
            except NothingToBuildError as exc:
                rejected = self.buffer.counters.describe()
                response.success = False
                response.message = f"cannot build: {exc}" + (f"; so far: {rejected}" if rejected else "")
                self.get_logger().warn(response.message)
                return
            counters = dataclasses.replace(self.buffer.counters)
        sampler = config.sampler
        self.get_logger().info(
            f"building from {len(odometry)} odometry messages and {len(images)} slice arrays "
            f"({sampler.chains} chains of {sampler.samples} samples, burn-in {sampler.burn_in}, seed {sampler.seed})"
        )
        try:
            built = build_map(
                odometry, images, config, self.catalog, progress=self._progress, runner=self._runner(config)
            )
            mount = {"source": "camera_mount parameters", **to_mapping(self.config.camera_mount)}
            extra = {**input_diagnostics(counters), "camera_mount": mount}
            built = dataclasses.replace(built, diagnostics={**built.diagnostics, **extra})
            # All three messages before publishing any, so that a failure leaves the previous map whole.
            messages = self._map_messages(built)
        except BuildCancelledError:
            self._fail(response, "build cancelled: the mapper is shutting down (start it again and call again)")
            return
        except Exception as exc:
            self._fail(response, f"build failed: {type(exc).__name__}: {exc}")
            return
        self._publish(messages)
        not_written = self._write_outputs(built)
        self._progress("done", 1, 1)
        response.success = True
        response.object_count = len(built.objects)
        response.chains, response.converged, response.rhat_max = chain_agreement(built)
        dropped = counters.dropped()
        response.message = (
            f"built a map of {len(built.objects)} objects ({len(built.rejected)} rejected) from {len(images)} images"
            + _agreement(response)
            + (
                f"; {dropped} messages were dropped before the build ({counters.describe()})"
                if dropped
                else "; no message was dropped"
            )
            + (f"; WARNING: {not_written}" if not_written else "")
        )
        if not_written:
            self.get_logger().warn(response.message)
        else:
            self.get_logger().info(response.message)

    def _progress(self, phase: str, done: int, total: int) -> None:
        # Every phase of a build reports progress now and then: the place to notice a stop.
        if self._stopping.is_set() and phase not in ("done", "failed"):
            raise BuildCancelledError
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

    def _map_messages(self, built: BuiltMap) -> tuple[MarkerArray, PathMsg, ObjectMap]:
        stamp = self.get_clock().now().to_msg()
        if built.trajectory:
            stamp = time_from_ns(built.trajectory[-1].stamp_ns)
        return to_marker_array(built, self.catalog, stamp), to_path(built, stamp), to_object_map(built, stamp)

    def _publish(self, messages: tuple[MarkerArray, PathMsg, ObjectMap]) -> None:
        markers, path, objects = messages
        self.markers_pub.publish(markers)
        self.trajectory_pub.publish(path)
        self.objects_pub.publish(objects)

    def _write_outputs(self, built: BuiltMap) -> str:
        """Write map.yaml to ``ros.output_dir``; '' or what was not written, and why.

        A write failure does not fail the build: by then the map is built and published,
        which is what BuildMap promises ("success: false when nothing could be built"). A
        ROS user keeps the map (`objslam echo /objslam/map/objects`) and is told in the
        response and the log that the file is missing. Failing the build instead would
        throw away minutes of sampling, and ``output_dir`` cannot be changed without
        restarting the node, which would lose the buffers too. Pictures of a written map
        are ``objslam figures``'s job.
        """
        out_dir = self.config.ros.output_dir
        if not out_dir:
            return ""
        try:
            path = write_map(Path(out_dir) / "map.yaml", built)
        except Exception as exc:
            return f"the map file was not written: {_reason(exc)}"
        self.get_logger().info(f"map written to {path}")
        return ""

    def _runner(self, config: MapperConfig) -> ChainRunner:
        """The chains' runner of a build; a Ray runner is kept for the next builds (its Ray stays up)."""
        runner = chain_runner(config.parallel, config.sampler.chains)
        if isinstance(runner, RayRunner):
            if self._ray_runner is None:
                self._ray_runner = runner
            return self._ray_runner
        return runner

    def request_stop(self) -> None:
        """Cancel a build in progress (called from the signal handler: only sets a flag)."""
        self._stopping.set()

    def busy(self) -> bool:
        return self._build_lock.locked()

    def destroy_node(self) -> None:
        if self._ray_runner is not None:
            self._ray_runner.close()
        super().destroy_node()

    def summary(self) -> str:
        c = self.buffer.counters
        buffered = f"buffered {len(self.buffer.odometry)} odometry, {len(self.buffer.images)} slice arrays"
        return f"{buffered}; dropped {c.dropped()}"


class BuildCancelledError(Exception):
    """Raised through the build by its progress callback when the node is asked to stop."""


def _agreement(response: BuildMap.Response) -> str:
    if response.chains < 2:
        return "; one chain (its convergence cannot be judged)"
    verdict = "converged" if response.converged else "NOT converged"
    return f"; {response.chains} chains, {verdict} (R-hat max {response.rhat_max:.3f})"


def _reason(exc: Exception) -> str:
    # A map file error already reads as one line for a user; anything else gets its type.
    return str(exc) if isinstance(exc, (MapFileError, OSError)) else f"{type(exc).__name__}: {exc}"


def main(args: list[str] | None = None) -> int:
    return run_node("mapper", MapperNode, args, make_executor=lambda: MultiThreadedExecutor(num_threads=4))


if __name__ == "__main__":
    sys.exit(main())
