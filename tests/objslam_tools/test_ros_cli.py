"""`objslam play`, `echo` and `call` over a real ROS graph (subprocesses, isolated domain)."""

from __future__ import annotations

import sys
import textwrap

import pytest
import yaml

from tests.conftest import BAGS, objslam_cmd

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
