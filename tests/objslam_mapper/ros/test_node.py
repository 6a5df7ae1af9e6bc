"""The mapper node over a real ROS graph: playback, detector, mapper, service, latched markers.

Subprocesses in an isolated domain. The end-to-end test checks that the nodes' map equals
the one-process ``objslam map`` for the same bag, seed and settings when no message was
dropped on the way.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable

import pytest
import yaml

from objslam_mapper.map_file import read_map
from tests.conftest import REPO, objslam_cmd

CONFIG_DIR = REPO / "config"

pytestmark = pytest.mark.ros

SAMPLES, BURN_IN, SEED = 300, 100, 7


def _wait_for_line(proc, needle: str, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if needle in line:
            return
        if not line and proc.poll() is not None:
            break
    raise AssertionError(f"'{needle}' not seen from {proc.args}")


def _call(processes, *extra: str) -> tuple[int, dict]:
    result = processes.run(objslam_cmd("call", "build-map", "--wait", "20", *extra), timeout=300)
    return result.returncode, yaml.safe_load(result.stdout) if result.stdout else {}


def _start_mapper(processes, output_dir) -> subprocess.Popen:
    proc = processes.start(objslam_cmd("mapper", "--ros-args", "-p", f"ros.output_dir:={output_dir}"))
    _wait_for_line(proc, "call /objslam/build_map")
    return proc


@pytest.fixture
def mapper(processes, tmp_path):
    return _start_mapper(processes, tmp_path)


def _stop(proc) -> str:
    """Stop a node that must still be running; it must end cleanly on SIGTERM. Its stderr."""
    assert proc.poll() is None, "the node died"
    proc.terminate()
    _out, err = proc.communicate(timeout=15)
    assert "Traceback" not in err
    return err


def test_build_with_nothing_buffered_says_what_is_missing(processes, mapper):
    code, response = _call(processes)
    assert code == 1
    assert response["success"] is False
    assert "no odometry and no slices" in response["message"]
    assert mapper.poll() is None


@pytest.fixture(scope="module")
def perspective_bag(tmp_path_factory):
    """A forward-looking pinhole camera, pitched down, with /tf_static (``objslam sim --camera pinhole``)."""
    out = tmp_path_factory.mktemp("perspective") / "small_pinhole"
    done = subprocess.run(
        objslam_cmd("sim", "small", "--camera", "pinhole", "--frames", "40", "--out", str(out)),
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return out


def _mount_file(path, bag) -> str:
    """The bag's /tf_static mount as the shared camera_mount parameter file both nodes take."""
    from objslam_common.config import to_mapping
    from objslam_common.mount import CameraMountConfig
    from objslam_tools.bag import open_bag

    reading = open_bag(bag).read_mount()
    assert reading is not None
    path.write_text(
        yaml.safe_dump({"/**": {"ros__parameters": {"camera_mount": to_mapping(CameraMountConfig.of(reading.mount))}}})
    )
    return str(path)


def test_bag_through_the_nodes_gives_the_one_process_map(processes, tmp_path, damaged_small_bag):
    # The bag is bags/small with three bad odometry messages and two unusable frames: both
    # paths skip and count them alike (one policy), so the maps are still the same.
    node_map, expected = _through_the_nodes_and_in_one_process(processes, tmp_path, damaged_small_bag, [], chains=2)
    lost = {k: (node_map.diagnostics[k], expected.diagnostics[k]) for k in ("dropped_messages", "invalid_odometry")}
    assert lost == {"dropped_messages": (3, 3), "invalid_odometry": (3, 3)}


def test_a_perspective_bag_through_the_nodes_gives_the_one_process_map(processes, tmp_path, perspective_bag):
    # The nodes take the mount from the shared parameter file; objslam map from the bag's /tf_static.
    mount = _mount_file(tmp_path / "camera_mount.yaml", perspective_bag)
    node_map, expected = _through_the_nodes_and_in_one_process(processes, tmp_path, perspective_bag, [mount], chains=1)
    assert expected.diagnostics["camera_mount"]["source"] == "/tf_static base_link -> camera"
    assert expected.diagnostics["camera_mount"]["pitch_rad"] == pytest.approx(0.1)
    assert len(node_map.objects) >= 2


def _through_the_nodes_and_in_one_process(processes, tmp_path, bag, extra_params: list[str], chains: int):
    """The maps of ``bag`` built by the nodes (as a user runs them: parameter files, the bag's
    /clock as time) and by ``objslam map``; asserted equal object by object. (node, one-process)."""
    params = [arg for file in extra_params for arg in ("--params-file", file)]
    mapper = processes.start(
        objslam_cmd(
            "mapper", "--ros-args", "--params-file", str(CONFIG_DIR / "mapper.yaml"), *params,
            "-p", "use_sim_time:=true", "-p", f"ros.output_dir:={tmp_path}",
        )
    )  # fmt: skip
    _wait_for_line(mapper, "call /objslam/build_map")
    processes.start(
        objslam_cmd(
            "detector", "--ros-args", "--params-file", str(CONFIG_DIR / "detector.yaml"), *params,
            "-p", "reliable_images:=true", "-p", "use_sim_time:=true",
        )
    )  # fmt: skip
    time.sleep(3.0)  # discovery before the first message, so nothing is lost
    # A late discovery loses the first messages (then the maps may differ and the test skips).
    player = processes.start(objslam_cmd("play", str(bag), "--delay", "5.0", "--rate", "1.0"))
    assert player.wait(timeout=120) == 0
    time.sleep(3.0)  # let the detector finish the last frames
    chain_args = ("--chains", str(chains))  # 2: on the node's Ray, as a user's build runs
    code, response = _call(
        processes, "--samples", str(SAMPLES), "--burn-in", str(BURN_IN), "--seed", str(SEED), *chain_args
    )
    assert code == 0, response
    assert response["success"] is True

    markers = processes.run(objslam_cmd("echo", "/objslam/map/markers", "--once", "--timeout", "30"), timeout=60)
    assert markers.returncode == 0, markers.stderr
    array = yaml.safe_load(markers.stdout.split("---")[0])
    assert array["markers"][0]["action"] == 3  # DELETEALL
    cylinders = [m for m in array["markers"] if m["ns"] == "objects" and m["type"] == 3]
    assert len(cylinders) == response["object_count"]
    for m in cylinders:
        assert 0.5 < m["color"]["a"] <= 1.0  # alpha = existence probability of a mapped object

    node_map = read_map(tmp_path / "map.yaml")
    reference = tmp_path / "reference.yaml"
    one_process = processes.run(
        objslam_cmd(
            "map", str(bag), "--out", str(reference),
            "--samples", str(SAMPLES), "--burn-in", str(BURN_IN), "--seed", str(SEED), *chain_args,
        ),
        timeout=300,
    )  # fmt: skip
    assert one_process.returncode == 0, one_process.stderr
    expected = read_map(reference)
    received = {k: node_map.diagnostics[k] for k in ("odometry_messages", "slice_arrays")}
    recorded = {k: expected.diagnostics[k] for k in ("odometry_messages", "slice_arrays")}
    if node_map.diagnostics["dropped_messages"] != expected.diagnostics["dropped_messages"] or received != recorded:
        pytest.skip(f"messages were lost on the way (received {received}, recorded {recorded}): maps may differ")
    assert len(node_map.objects) == len(expected.objects)
    for got, want in zip(node_map.objects, expected.objects, strict=True):
        assert got.label == want.label
        assert got.position_m == pytest.approx(want.position_m, abs=1e-6)
        assert got.size_m == pytest.approx(want.size_m, abs=1e-6)
        assert got.existence_probability == pytest.approx(want.existence_probability, abs=1e-9)
        assert got.existence_by_chain == pytest.approx(want.existence_by_chain, abs=1e-9)
    assert node_map.diagnostics["convergence"]["chains"] == chains
    assert node_map.trajectory_array() == pytest.approx(expected.trajectory_array(), abs=1e-6)
    return node_map, expected


BAD_ODOMETRY = textwrap.dedent(
    """
    import time, rclpy
    from nav_msgs.msg import Odometry
    from objslam_msgs.msg import SliceArray, Slice
    rclpy.init()
    node = rclpy.create_node("bad_inputs")
    odom = node.create_publisher(Odometry, "/odom", 10)
    slices = node.create_publisher(SliceArray, "/objslam/slices", 10)
    while odom.get_subscription_count() == 0 or slices.get_subscription_count() == 0:
        time.sleep(0.1)
    time.sleep(0.5)
    def odometry(sec, x=0.0, w=1.0):
        msg = Odometry()
        msg.header.stamp.sec = sec
        msg.pose.pose.position.x = x
        msg.pose.pose.orientation.w = w
        return msg
    def slice_array(sec):
        msg = SliceArray()
        msg.header.stamp.sec = sec
        msg.slices = [Slice(label="red", bearing=0.1, angular_width=0.1, elevation_bottom=-0.3, elevation_top=0.1)]
        return msg
    slices.publish(slice_array(5))      # older than the first odometry
    odom.publish(odometry(10, x=float("nan")))
    odom.publish(odometry(10, w=2.0))   # not a unit quaternion
    for sec in (10, 11, 12):
        odom.publish(odometry(sec))
    odom.publish(odometry(3))          # time jumps back: buffers reset
    time.sleep(1.0)
    print("done", flush=True)
    """
)


def test_bad_inputs_are_counted_and_the_node_survives(processes, mapper, start_driver):
    talker = processes.start([sys.executable, "-c", BAD_ODOMETRY])
    assert talker.stdout.readline().strip() == "done"
    response = start_driver()("build")["response"]  # the driver: `objslam call` cuts long messages
    assert response["success"] is False
    assert "no slices received" in response["message"]  # the reset dropped the early slice array
    # The refusal says what was rejected, with the counts: the NaN pose and the bad quaternion.
    assert "2 invalid odometry messages" in response["message"]
    assert "1 buffer resets" in response["message"]
    err = _stop(mapper)
    assert "rejected an odometry message (1 so far): odometry pose is not finite" in err
    assert "rejected an odometry message (2 so far): odometry orientation is not a unit quaternion" in err
    assert "time jumped backwards" in err


# A test's hands on the graph: one process for all its steps, since each rclpy process
# costs seconds to start and discover. JSON commands in, one JSON answer per line out.
DRIVER = textwrap.dedent(
    """
    import json, sys, time
    import numpy as np
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from nav_msgs.msg import Odometry, Path
    from std_srvs.srv import Trigger
    from visualization_msgs.msg import MarkerArray
    from objslam_msgs.msg import BuildProgress, ObjectMap, Slice, SliceArray
    from objslam_msgs.srv import BuildMap
    from objslam_common.catalog import load_catalog
    from objslam_common.geometry import quaternion_from_yaw
    from objslam_common.records import SliceMeasurement
    from objslam_mapper.synthetic import SyntheticObject, ellipse_trajectory, simulate_run

    rclpy.init()
    node = rclpy.create_node("mapper_test_driver")
    reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
    odom_pub = node.create_publisher(Odometry, "/odom", reliable)
    slices_pub = node.create_publisher(SliceArray, "/objslam/slices", reliable)
    build_client = node.create_client(BuildMap, "/objslam/build_map")
    reset_client = node.create_client(Trigger, "/objslam/reset")
    progress = []
    node.create_subscription(BuildProgress, "/objslam/map/progress", progress.append, reliable)

    def spin_until(done, timeout=60.0):
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline:
                raise TimeoutError("no answer in time")
            rclpy.spin_once(node, timeout_sec=0.02)

    def odometry(stamp_ns, x=0.0, y=0.0, theta=0.0):
        msg = Odometry()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
        msg.header.frame_id = "odom"
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
        q = msg.pose.pose.orientation
        q.x, q.y, q.z, q.w = quaternion_from_yaw(theta)
        return msg

    def slice_array(stamp_ns, slices):
        msg = SliceArray()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
        msg.slices = [
            Slice(label=s.label, confidence=1.0, bearing=s.bearing_rad, angular_width=s.angular_width_rad,
                  elevation_bottom=s.elevation_bottom_rad, elevation_top=s.elevation_top_rad)
            for s in slices
        ]
        return msg

    def publish(odometry_msgs, slice_msgs):
        for msg in odometry_msgs:
            odom_pub.publish(msg)
        for msg in slice_msgs:
            slices_pub.publish(msg)
        # Local and reliable, so delivered at once; this leaves the node time to take them all
        # (waiting for the acknowledgements would cost a DDS heartbeat period, seconds).
        time.sleep(0.5)
        return {"odometry": len(odometry_msgs), "slices": len(slice_msgs)}

    def run(start_sec=1.0):
        # A red and a blue object seen from 40 poses on an ellipse: a map of two objects.
        n = 40
        objects = (SyntheticObject("red", (0.0, 0.0, 0.0), (0.3, 0.6)),
                   SyntheticObject("blue", (3.0, 0.5, 0.0), (0.2, 0.9)))
        stamps = [int(start_sec * 1e9) + k * 200_000_000 for k in range(n)]
        sim = simulate_run(ellipse_trajectory(n, (2.0, 1.5)), stamps, objects, load_catalog(), np.random.default_rng(0))
        return publish([odometry(o.stamp_ns, o.x_m, o.y_m, o.theta_rad) for o in sim.odometry],
                       [slice_array(i.stamp_ns, i.slices) for i in sim.images])

    def answer_of(client, future, timeout=30.0):
        # An exception in a callback leaves a request unanswered (the multi-threaded executor
        # keeps it in a future nobody reads); a node that died is gone: fail, do not hang.
        spin_until(lambda: future.done() or not client.service_is_ready(), timeout)
        if not future.done():
            raise RuntimeError(f"{client.srv_name} went away without answering (did the node die?)")
        return plain(future.result())

    def plain(response):
        return {f: getattr(response, f) for f in response.get_fields_and_field_types()}

    def build(samples=0, burn_in=0, seed=0, chains=0, second_while_running=False):
        request = BuildMap.Request(samples=samples, burn_in=burn_in, seed=seed, chains=chains)
        progress.clear()
        started = time.monotonic()
        first = build_client.call_async(request)
        answer = {}
        if second_while_running:
            spin_until(lambda: progress or first.done())  # progress: the build has the lock
            assert not first.done(), "the first build ended before the second call"
            answer["second"] = answer_of(build_client, build_client.call_async(request))
            answer["first_running_after_second"] = not first.done()
        # A build starts the node's Ray on first use and samples every chain: on a loaded
        # machine (pytest workers beside other jobs) that took over 30 s once.
        answer["response"] = answer_of(build_client, first, timeout=120.0)
        answer["round_trip_sec"] = time.monotonic() - started
        return answer

    def reset():
        return answer_of(reset_client, reset_client.call_async(Trigger.Request()))

    def received_map():
        # A late subscriber: new subscriptions, after the map was published.
        got = {}
        subs = [
            node.create_subscription(t, topic, lambda m, k=k: got.setdefault(k, m), latched)
            for k, t, topic in (("markers", MarkerArray, "/objslam/map/markers"),
                                ("trajectory", Path, "/objslam/map/trajectory"),
                                ("objects", ObjectMap, "/objslam/map/objects"))
        ]
        try:
            spin_until(lambda: len(got) == 3, timeout=10.0)
        finally:
            for sub in subs:
                node.destroy_subscription(sub)
        markers = [
            {"ns": m.ns, "type": m.type, "action": m.action, "alpha": m.color.a}
            for m in got["markers"].markers
        ]
        path = got["trajectory"]
        objects = got["objects"]
        return {
            "markers": markers,
            "trajectory": {"frame_id": path.header.frame_id, "poses": len(path.poses)},
            "objects": {"frame_id": objects.header.frame_id, "labels": sorted(o.label for o in objects.objects),
                        "samples": objects.samples, "burn_in": objects.burn_in, "chains": objects.chains,
                        "converged": objects.converged, "rhat_max": objects.rhat_max,
                        "by_chain": [list(o.existence_probability_by_chain) for o in objects.objects]},
        }

    ops = {
        "run": run,
        "odometry": lambda stamps_sec: publish([odometry(s * 1e9) for s in stamps_sec], []),
        "slices": lambda stamps_sec: publish(
            [], [slice_array(s * 1e9, [SliceMeasurement("red", 1.0, 0.1, 0.1, -0.3, 0.1)]) for s in stamps_sec]
        ),
        "build": build,
        "reset": reset,
        "received_map": received_map,
    }
    for client in (build_client, reset_client):
        assert client.wait_for_service(timeout_sec=20.0)
    spin_until(lambda: odom_pub.get_subscription_count() and slices_pub.get_subscription_count(), 20.0)
    spin_until(lambda: node.count_publishers("/objslam/map/progress"), 20.0)
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        command = json.loads(line)
        try:
            answer = ops[command.pop("op")](**command)
        except Exception as exc:
            answer = {"error": f"{type(exc).__name__}: {exc}"}
        print(json.dumps(answer), flush=True)
    """
)


class Driver:
    def __init__(self, processes):
        self.proc = processes.start([sys.executable, "-c", DRIVER], stdin=subprocess.PIPE)
        assert self._answer() == {"ready": True}

    def close(self) -> None:
        # End of commands ends the driver (it reads stdin, so a SIGTERM alone would not).
        if self.proc.stdin and not self.proc.stdin.closed:
            self.proc.stdin.close()

    def _answer(self) -> dict:
        line = self.proc.stdout.readline()
        if not line:
            raise AssertionError(f"the test driver died: {self.proc.stderr.read()}")
        return json.loads(line)

    def __call__(self, op: str, **args) -> dict:
        self.proc.stdin.write(json.dumps({"op": op, **args}) + "\n")
        self.proc.stdin.flush()
        answer = self._answer()
        assert "error" not in answer, answer["error"]
        return answer


@pytest.fixture
def start_driver(processes):
    drivers: list[Driver] = []

    def start() -> Driver:
        drivers.append(Driver(processes))
        return drivers[-1]

    yield start
    for d in drivers:
        d.close()


@pytest.fixture
def driver(mapper, start_driver):
    return start_driver()


def _build_until(driver, until: str | Callable[[dict], bool], timeout_s: float = 20.0, **request) -> dict:
    """The response of a build whose message holds ``until`` (or for which ``until(response)``
    holds): the messages published just before may still be on their way to the node, or in
    its queue, on a busy machine, so build again until then."""
    done = until if callable(until) else (lambda response: until in response["message"])
    deadline = time.monotonic() + timeout_s
    while True:
        response = driver("build", **request)["response"]
        if done(response) or time.monotonic() > deadline:
            return response
        time.sleep(0.2)


def _run_and_take(driver) -> dict:
    """Publish the run and build until the map holds all of it: the node's executor may answer
    the build before it has taken the last messages from its queue (on a busy machine the first
    build once held 35 of the 40 poses). Returns the response of the build that held them all."""
    assert driver("run") == {"odometry": 40, "slices": 40}

    def whole(response: dict) -> bool:
        return "from 40 images" in response["message"] and driver("received_map")["trajectory"]["poses"] == 40

    response = _build_until(driver, whole, timeout_s=30.0, samples=50, burn_in=10)
    assert whole(response), f"the node did not take the whole run within 30 s: {response['message']}"
    return response


def _cylinders(received: dict) -> list[dict]:
    return [m for m in received["markers"] if m["ns"] == "objects" and m["type"] == 3]


def test_a_build_answers_with_its_time_and_count_refuses_a_second_and_latches_all_maps(mapper, driver):
    _run_and_take(driver)
    answer = driver("build", samples=1000, burn_in=200, seed=3, chains=2, second_while_running=True)
    second = answer["second"]
    assert second["success"] is False
    assert "a build is already running" in second["message"]
    assert answer["first_running_after_second"]  # refused at once, not queued behind the build
    response = answer["response"]
    assert response["success"] is True, response["message"]
    assert 0.0 < response["elapsed_sec"] <= answer["round_trip_sec"]
    assert f"built a map of {response['object_count']} objects" in response["message"]
    assert response["chains"] == 2 and response["rhat_max"] >= 1.0
    verdict = "converged" if response["converged"] else "NOT converged"
    assert f"from 40 images; 2 chains, {verdict} (R-hat max " in response["message"]
    assert response["message"].endswith("no message was dropped")

    # A late subscriber gets all three maps of this build (1000 samples), the count matching.
    received = driver("received_map")
    assert received["markers"][0]["action"] == 3  # DELETEALL
    assert len(_cylinders(received)) == response["object_count"]
    assert len(received["objects"]["labels"]) == response["object_count"]
    assert received["trajectory"] == {"frame_id": "odom", "poses": 40}
    assert {k: received["objects"][k] for k in ("frame_id", "samples", "burn_in", "chains", "converged")} == {
        "frame_id": "odom",
        "samples": 1000,
        "burn_in": 200,
        "chains": 2,
        "converged": response["converged"],
    }
    assert received["objects"]["rhat_max"] == pytest.approx(response["rhat_max"])
    assert all(len(p) == 2 and all(0.0 <= x <= 1.0 for x in p) for p in received["objects"]["by_chain"])

    # Still answering after the refusal: the refused call did not leave the build lock taken.
    assert driver("build", samples=50, burn_in=10)["response"]["success"] is True
    _stop(mapper)


def test_failed_builds_say_why_keep_the_node_and_the_previous_map(mapper, driver):
    first = _run_and_take(driver)
    assert first["success"] is True, first["message"]
    before = driver("received_map")

    # A request that cannot run: the burn-in defaults to the parameter (2500).
    bad = driver("build", samples=50)["response"]
    assert bad["success"] is False
    assert "invalid request: burn_in (2500) must be smaller than samples (50)" in bad["message"]

    assert driver("reset") == {"success": True, "message": "buffers cleared"}
    empty = driver("build", samples=50, burn_in=10)["response"]
    assert empty["success"] is False and "nothing buffered yet" in empty["message"]

    driver("slices", stamps_sec=[100, 101, 102])
    no_odometry = _build_until(driver, "(3 slice arrays", samples=50, burn_in=10)
    assert no_odometry["success"] is False
    assert "no odometry received (3 slice arrays are waiting for it)" in no_odometry["message"]

    # Odometry that ends before every image: the build itself fails (odometry stopped?).
    driver("odometry", stamps_sec=[10, 11, 12])
    failed = _build_until(driver, "build failed", samples=60, burn_in=10)
    assert failed["success"] is False
    assert failed["message"].startswith("build failed: ")
    assert "none of the 3 image stamps lies within the odometry span" in failed["message"]

    assert driver("received_map") == before  # still the first map (50 samples, 40 poses)
    assert before["objects"]["samples"] == 50 and before["trajectory"]["poses"] == 40
    _stop(mapper)


def test_an_unwritable_output_dir_still_publishes_the_map_and_says_so(processes, start_driver, tmp_path):
    not_a_dir = tmp_path / "map-here"
    not_a_dir.write_text("a file where the output folder should be\n")
    mapper = _start_mapper(processes, not_a_dir)
    driver = start_driver()
    driver("run")
    response = driver("build", samples=50, burn_in=10)["response"]
    # The map was built: success, with a warning that names the file and the reason.
    assert response["success"] is True, response["message"]
    expected = f"WARNING: the map file was not written: cannot write map file {not_a_dir / 'map.yaml'}"
    assert expected in response["message"]
    assert len(_cylinders(driver("received_map"))) == response["object_count"]
    assert not_a_dir.read_text() == "a file where the output folder should be\n"
    err = _stop(mapper)
    assert "the map file was not written" in err


def _long_build(processes, chains: int) -> subprocess.Popen:
    """`objslam call build-map` of a build far longer than the test waits for it."""
    return processes.start(
        objslam_cmd(
            "call", "build-map", "--wait", "20", "--samples", "5000000", "--burn-in", "10", "--chains", str(chains)
        )
    )


def test_an_interrupted_build_answers_its_caller_and_the_mapper_ends_cleanly(mapper, driver, processes):
    # Ctrl-C during a build of 2 chains on Ray: cancelling must free its workers too, and
    # Ray's own crash handler must not turn the signal into an abort. (SIGTERM takes the
    # same path in run_node; the other tests stop the mapper with it.)
    driver("run")
    call = _long_build(processes, 2)
    _wait_for_line(mapper, "sampling:", timeout=90)
    mapper.send_signal(signal.SIGINT)
    out, err = call.communicate(timeout=60)
    response = yaml.safe_load(out)
    assert response, err + mapper.communicate(timeout=30)[1]
    assert call.returncode == 1, err
    assert response["success"] is False
    assert response["message"] == "build cancelled: the mapper is shutting down (start it again and call again)"
    _out, mapper_err = mapper.communicate(timeout=30)
    assert mapper.returncode == 0, mapper_err[-3000:]
    for trouble in ("Traceback", "InvalidHandle", "never retrieved"):
        assert trouble not in mapper_err


def test_call_reports_a_mapper_that_died_during_the_build(mapper, driver, processes):
    driver("run")
    call = _long_build(processes, 1)
    _wait_for_line(mapper, "sampling:", timeout=90)
    mapper.kill()  # no chance to answer
    started = time.monotonic()
    out, err = call.communicate(timeout=90)
    assert call.returncode == 1
    assert out == ""
    noticed_s = time.monotonic() - started
    assert err.strip() == (
        "objslam call: the mapper went away during the build (see its log, start it again and call again)"
    )
    # By the progress topic's liveliness (a 2 s lease), not by discovery, which notices the
    # service gone only when the participant's lease ends (about 22 s with Fast DDS).
    assert noticed_s < 12.0, f"noticed after {noticed_s:.1f} s"


def test_call_gives_up_after_its_timeout(mapper, driver, processes):
    driver("run")
    result = processes.run(
        objslam_cmd(
            "call",
            "build-map",
            "--wait",
            "20",
            "--samples",
            "5000000",
            "--burn-in",
            "10",
            "--chains",
            "1",
            "--timeout",
            "3",
        ),
        timeout=60,
    )
    assert result.returncode == 1
    assert result.stderr.strip() == (
        "objslam call: no answer within 3 s (the build may still run: watch /objslam/map/progress, "
        "or give a longer --timeout)"
    )
    _stop(mapper)  # still running its build, and still stops cleanly
