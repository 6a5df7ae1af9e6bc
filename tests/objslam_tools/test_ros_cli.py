"""`objslam play`, `echo` and `call` over a real ROS graph (subprocesses, isolated domain)."""

from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest
import yaml

from tests.conftest import BAGS, objslam_cmd
from tests.objslam_tools.synthetic_bag import image_msg, odometry_records, write_bag

pytestmark = pytest.mark.ros

LATCHED_PUBLISHER = textwrap.dedent(
    """
    import rclpy, time
    from rclpy.qos import QoSProfile, DurabilityPolicy, ReliabilityPolicy
    from std_msgs.msg import String
    rclpy.init()
    node = rclpy.create_node("latched_talker")
    qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(String, "/objslam_test/latched", qos)
    pub.publish(String(data="hello late subscriber"))
    print("published", flush=True)
    try:
        rclpy.spin(node)
    except BaseException:
        pass
    """
)


def test_late_subscriber_receives_latched_message(processes):
    talker = processes.start([sys.executable, "-c", LATCHED_PUBLISHER])
    assert talker.stdout.readline().strip() == "published"
    # The message was published before echo existed: only transient-local delivery gets it there.
    result = processes.run(objslam_cmd("echo", "/objslam_test/latched", "--once", "--timeout", "20"), timeout=40)
    assert result.returncode == 0, result.stderr
    first = result.stdout.split("---")[0]
    assert yaml.safe_load(first) == {"data": "hello late subscriber"}


def test_play_small_bag_reaches_echo(processes):
    player = processes.start(objslam_cmd("play", str(BAGS / "small"), "--delay", "0.5", "--loop"))
    result = processes.run(objslam_cmd("echo", "/odom", "--once", "--timeout", "30"), timeout=60)
    assert player.poll() is None, player.stderr.read()
    assert result.returncode == 0, result.stderr
    odom = yaml.safe_load(result.stdout.split("---")[0])
    assert odom["header"]["frame_id"] == "odom"
    assert odom["child_frame_id"] == "base_link"
    clock = processes.run(objslam_cmd("echo", "/clock", "--once", "--timeout", "30"), timeout=60)
    assert clock.returncode == 0, clock.stderr
    assert yaml.safe_load(clock.stdout.split("---")[0])["clock"]["sec"] > 0


def test_call_without_mapper_says_no_service(processes):
    result = processes.run(objslam_cmd("call", "build-map", "--wait", "1"), timeout=30)
    assert result.returncode == 1
    assert "no service answered at /objslam/build_map" in result.stderr
    assert "Traceback" not in result.stderr


SILENT_PUBLISHER = textwrap.dedent(
    """
    import rclpy
    from std_msgs.msg import String
    rclpy.init()
    node = rclpy.create_node("silent_talker")
    node.create_publisher(String, "/objslam_test/silent", 10)
    print("ready", flush=True)
    try:
        rclpy.spin(node)
    except BaseException:
        pass
    """
)


def test_echo_once_gives_up_on_a_publisher_that_sends_nothing(processes):
    talker = processes.start([sys.executable, "-c", SILENT_PUBLISHER])
    assert talker.stdout.readline().strip() == "ready"
    # The publisher exists, so the type resolves; only the message never comes.
    result = processes.run(objslam_cmd("echo", "/objslam_test/silent", "--once", "--timeout", "4"), timeout=30)
    assert result.returncode == 1, result.stderr
    assert result.stderr.strip().splitlines() == ["objslam echo: no message on /objslam_test/silent within 4.0 s"]
    assert result.stdout == ""


S = 1_000_000_000
ODOM_X = [0.25 * (i + 1) for i in range(10)]  # distinct values, to recognise what was played


def _odometry(topic: str, offset_m: float = 0.0) -> list:
    poses = np.array([[x + offset_m, 0.0, 0.0] for x in ODOM_X])
    return odometry_records(topic, [S + i * S // 10 for i in range(len(ODOM_X))], poses)


def _assert_echoed_written_odometry(echo_stdout: str) -> None:
    """The first echoed Odometry is one of those written: its x is one of ODOM_X."""
    odom = yaml.safe_load(echo_stdout.split("---")[0])
    assert odom["child_frame_id"] == "base_link"
    x = odom["pose"]["pose"]["position"]["x"]
    assert min(abs(x - v) for v in ODOM_X) < 1e-9, x


PLAYER_PUBLICATIONS = textwrap.dedent(
    """
    import time, rclpy
    from rclpy.node import NodeNameNonExistentError
    rclpy.init()
    node = rclpy.create_node("graph_probe")
    def published():
        try:
            return {name for name, _ in node.get_publisher_names_and_types_by_node("objslam_player", "/")}
        except NodeNameNonExistentError:
            return set()
    deadline = time.monotonic() + 30
    while "/clock" not in published() and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(1.0)  # /clock is created last, but discovery may report the others later
    print(" ".join(sorted(published() - {"/rosout", "/parameter_events"})), flush=True)
    """
)


def test_play_topics_publishes_only_the_listed_topics(processes, tmp_path):
    # No image topic: --topics also lifts the rule that a whole bag must hold one.
    bag = write_bag(tmp_path / "odom", _odometry("/odom") + _odometry("/ground_truth/odom", 100.0))
    player = processes.start(objslam_cmd("play", str(bag), "--topics", "/odom", "--delay", "0.5", "--loop"))
    probe = processes.run([sys.executable, "-c", PLAYER_PUBLICATIONS], timeout=60)
    assert probe.returncode == 0, probe.stderr
    assert probe.stdout.split() == ["/clock", "/odom"]
    result = processes.run(objslam_cmd("echo", "/odom", "--once", "--timeout", "20"), timeout=40)
    assert player.poll() is None, player.stderr.read()
    assert result.returncode == 0, result.stderr
    _assert_echoed_written_odometry(result.stdout)  # from /odom: /ground_truth/odom is 100 m off


def test_play_sqlite3_bag_reaches_echo(processes, tmp_path):
    image = ("/camera/image_raw", S, image_msg(S, np.zeros((6, 8, 3), np.uint8)))
    bag = write_bag(tmp_path / "db3", [image, *_odometry("/odom")], storage="sqlite3")
    assert (bag / "db3.db3").is_file()  # really the sqlite3 storage
    player = processes.start(objslam_cmd("play", str(bag), "--delay", "0.5", "--loop"))
    result = processes.run(objslam_cmd("echo", "/odom", "--once", "--timeout", "20"), timeout=40)
    assert player.poll() is None, player.stderr.read()
    assert result.returncode == 0, result.stderr
    _assert_echoed_written_odometry(result.stdout)


@pytest.mark.parametrize("verb", ["mapper", "detector"])
def test_node_help_prints_usage_and_starts_nothing(processes, verb):
    done = processes.run(objslam_cmd(verb, "--help"), timeout=30)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"usage: objslam {verb} [--ros-args")
    assert f"objslam params {verb}" in done.stdout
    assert "call /objslam/build_map" not in done.stderr and "detecting" not in done.stderr  # no node ran


@pytest.mark.parametrize("verb", ["mapper", "detector"])
def test_a_missing_parameter_file_is_one_line(processes, verb, tmp_path):
    done = processes.run(objslam_cmd(verb, "--ros-args", "--params-file", str(tmp_path / "missing.yaml")), timeout=30)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert done.stderr.strip() == f"objslam {verb}: error: --params-file {tmp_path / 'missing.yaml'}: no such file"
