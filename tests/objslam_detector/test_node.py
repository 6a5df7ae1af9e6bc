"""The detector node over a real ROS graph (subprocesses, isolated domain)."""

from __future__ import annotations

import re
import sys
import textwrap

import pytest
import yaml

from objslam_tools.bag import open_bag
from tests.conftest import BAGS, objslam_cmd

pytestmark = pytest.mark.ros


def _first_message(stdout: str) -> dict:
    return yaml.safe_load(stdout.split("---")[0])


def test_playing_small_yields_slices_stamped_like_the_images(processes):
    bag = open_bag(BAGS / "small")
    image_stamps = {frame.stamp_ns for frame in bag.images()}
    detector = processes.start(
        objslam_cmd("detector", "--ros-args", "-p", "use_compressed:=true", "-p", "publish_debug_image:=true")
    )
    processes.start(objslam_cmd("play", str(BAGS / "small"), "--delay", "1.0", "--loop"))
    result = processes.run(objslam_cmd("echo", "/objslam/slices", "--once", "--timeout", "60"), timeout=90)
    assert detector.poll() is None, detector.stderr.read()
    assert result.returncode == 0, result.stderr
    msg = _first_message(result.stdout)
    stamp_ns = msg["header"]["stamp"]["sec"] * 1_000_000_000 + msg["header"]["stamp"]["nanosec"]
    assert stamp_ns in image_stamps
    for s in msg["slices"]:
        assert s["label"] in {"red", "green", "blue", "yellow", "cyan"}
        assert s["elevation_top"] >= s["elevation_bottom"]
    debug = processes.run(
        objslam_cmd("echo", "/objslam/detector/debug_image", "--once", "--timeout", "30", "--truncate-length", "4"),
        timeout=60,
    )
    assert debug.returncode == 0, debug.stderr
    image = _first_message(debug.stdout)
    assert (image["width"], image["height"], image["encoding"]) == (640, 640, "rgb8")


BAD_THEN_GOOD = textwrap.dedent(
    """
    import time, numpy as np, rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image, CompressedImage
    rclpy.init()
    node = rclpy.create_node("bad_images")
    info_pub = node.create_publisher(CameraInfo, "/camera/camera_info", qos_profile_sensor_data)
    raw_pub = node.create_publisher(Image, "/camera/image_raw", qos_profile_sensor_data)
    while raw_pub.get_subscription_count() == 0 or info_pub.get_subscription_count() == 0:
        time.sleep(0.1)
    time.sleep(0.5)
    def image(encoding, width, height, channels):
        msg = Image(encoding=encoding, width=width, height=height, step=width * channels)
        msg.header.frame_id = "camera"
        msg.data = bytes(width * height * channels)
        return msg
    for _ in range(40):  # before any camera info: more than the node holds (best effort: send plenty)
        raw_pub.publish(image("rgb8", 640, 640, 3))
        time.sleep(0.05)
    info = CameraInfo(width=640, height=640, distortion_model="unified", d=[0.9])
    info.k = [170.0, 0.0, 320.0, 0.0, 170.0, 320.0, 0.0, 0.0, 1.0]
    for _ in range(20):
        info_pub.publish(info)
        time.sleep(0.05)
    for bad in (image("yuv422", 640, 640, 2), image("rgb8", 320, 320, 3), image("rgb8", 0, 0, 3)):
        for _ in range(5):
            raw_pub.publish(bad)
            time.sleep(0.1)
    time.sleep(0.5)
    print("bad frames sent", flush=True)
    for _ in range(100):
        info_pub.publish(info)
        raw_pub.publish(image("rgb8", 640, 640, 3))
        time.sleep(0.1)
    """
)


def test_bad_frames_are_skipped_with_a_warning_and_the_node_keeps_running(processes):
    detector = processes.start(objslam_cmd("detector"))
    talker = processes.start([sys.executable, "-c", BAD_THEN_GOOD])
    result = processes.run(objslam_cmd("echo", "/objslam/slices", "--once", "--timeout", "60"), timeout=90)
    assert result.returncode == 0, result.stderr
    assert _first_message(result.stdout)["slices"] == []  # a black image has no objects
    assert talker.stdout.readline().strip() == "bad frames sent"
    assert detector.poll() is None
    detector.terminate()
    _out, err = detector.communicate(timeout=10)
    assert "waiting for camera info" in err
    assert "unsupported image encoding 'yuv422'" in err
    assert "image is 320x320 px but the camera calibration is 640x640 px" in err
    assert "skipped {'no camera info'" in err  # the summary at shutdown counts what was skipped
    held = re.search(r"processed (\d+) frames", err)
    assert held and int(held.group(1)) >= 10  # the images held for the camera info were not lost
    assert "Traceback" not in err
