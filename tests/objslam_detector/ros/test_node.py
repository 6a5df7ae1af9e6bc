"""The detector node over a real ROS graph (subprocesses, isolated domain)."""

from __future__ import annotations

import ast
import re
import sys
import textwrap
import time

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
        objslam_cmd("detector", "--ros-args", "-p", "publish_debug_image:=true")  # transport: auto
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
    import sys, time, cv2, numpy as np, rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image, CompressedImage
    compressed = sys.argv[1] == "compressed"
    rclpy.init()
    node = rclpy.create_node("bad_images")
    info_pub = node.create_publisher(CameraInfo, "/camera/camera_info", qos_profile_sensor_data)
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    if compressed:
        image_pub = node.create_publisher(CompressedImage, "/camera/image_raw/compressed", reliable)
    else:
        image_pub = node.create_publisher(Image, "/camera/image_raw", reliable)
    while image_pub.get_subscription_count() == 0 or info_pub.get_subscription_count() == 0:
        time.sleep(0.1)
    time.sleep(0.5)
    def raw(encoding, width, height, channels):
        msg = Image(encoding=encoding, width=width, height=height, step=width * channels)
        msg.header.frame_id = "camera"
        msg.data = bytes(width * height * channels)
        return msg
    def packed(size=640, fmt="png", data=None):
        msg = CompressedImage(format=fmt)
        msg.header.frame_id = "camera"
        msg.data = cv2.imencode(".png", np.zeros((size, size, 3), np.uint8))[1].tobytes() if data is None else data
        return msg
    good = packed() if compressed else raw("rgb8", 640, 640, 3)
    for _ in range(40):  # before any camera info: more than the node holds
        image_pub.publish(good)
        time.sleep(0.05)
    info = CameraInfo(width=640, height=640, distortion_model="unified", d=[0.9])
    info.k = [170.0, 0.0, 320.0, 0.0, 170.0, 320.0, 0.0, 0.0, 1.0]
    for _ in range(20):
        info_pub.publish(info)
        time.sleep(0.05)
    # Five frames of each kind, well within one warning period. The size mismatches differ
    # in size, so their warnings differ in detail but not in reason.
    if compressed:
        bad = [packed(fmt="tiff")] * 5 + [packed(320 + 10 * i) for i in range(5)]
        bad += [packed(data=b"\\x89PNG\\r\\n\\x1a\\n" + bytes(40))] * 5 + [packed(data=b"")] * 5
    else:
        bad = [raw("yuv422", 640, 640, 2)] * 5 + [raw("rgb8", 320 + 10 * i, 320, 3) for i in range(5)]
        bad += [raw("rgb8", 0, 0, 3)] * 5
    for frame in bad:
        image_pub.publish(frame)
        time.sleep(0.1)
    print("bad frames sent", flush=True)
    for _ in range(100):
        info_pub.publish(info)
        image_pub.publish(good)
        time.sleep(0.1)
    """
)

# reason -> what its (first) warning says, for each transport the node can take.
BAD_FRAME_WARNINGS = {
    "raw": {
        "unsupported encoding": "unsupported image encoding 'yuv422'",
        "size mismatch": "image is 320x320 px but the camera calibration is 640x640 px",
        "empty image": "empty image (0x0 px)",
    },
    "compressed": {
        "unsupported encoding": "unsupported compressed format 'tiff'",
        "size mismatch": "image is 320x320 px but the camera calibration is 640x640 px",
        "corrupt compressed data": "cannot decode compressed image (png): corrupt or truncated data",
        "empty image": "empty compressed image",
    },
}


@pytest.mark.parametrize("transport", ["raw", "compressed"])
def test_bad_frames_are_skipped_with_a_warning_and_the_node_keeps_running(processes, transport):
    # Reliable images: no frame is lost, so the counts per reason are exact. The transport
    # is left to the node (auto): it takes whichever topic the talker publishes on.
    detector = processes.start(objslam_cmd("detector", "--ros-args", "-p", "reliable_images:=true"))
    talker = processes.start([sys.executable, "-c", BAD_THEN_GOOD, transport])
    assert talker.stdout.readline().strip() == "bad frames sent"
    # Slices published from now on come from frames sent after the bad ones (one reliable
    # stream, handled in order): once one arrives, every bad frame has been handled.
    result = processes.run(objslam_cmd("echo", "/objslam/slices", "--once", "--timeout", "60"), timeout=90)
    assert result.returncode == 0, result.stderr
    assert _first_message(result.stdout)["slices"] == []  # a black image has no objects
    assert detector.poll() is None
    detector.terminate()  # while good frames still stream in
    _out, err = detector.communicate(timeout=10)
    assert "Traceback" not in err, err
    assert err.count("waiting for camera info") == 1
    topic = "/camera/image_raw" + ("/compressed" if transport == "compressed" else "")
    assert f"images arrive on {topic}: detecting on it" in err
    expected = BAD_FRAME_WARNINGS[transport]
    for reason, detail in expected.items():
        # One warning per reason for its five frames: rate-limited by reason, not by detail.
        assert err.count(f"skipped a frame ({reason}:") == 1, (reason, err)
        assert detail in err
    # The summary at shutdown counts the skipped frames per reason.
    summary = re.search(r"processed (\d+) frames, skipped (\{.*\})", err)
    assert summary, err
    skipped = ast.literal_eval(summary.group(2))
    assert {r: n for r, n in skipped.items() if r != "no camera info"} == dict.fromkeys(expected, 5)
    # 40 images before the camera info, 10 held: 30 dropped, fewer if the info overtook some.
    assert 0 < skipped["no camera info"] <= 30
    assert int(summary.group(1)) >= 10  # the images held for the camera info were not lost


def test_a_detector_on_a_topic_without_images_says_which_topics_have_them(processes):
    detector = processes.start(objslam_cmd("detector", "--ros-args", "-p", "image_topic:=/front/image"))
    processes.start(objslam_cmd("play", str(BAGS / "small"), "--loop"))
    expected = (
        "no image has arrived on /front/image or /front/image/compressed in 5 s; "
        "image topics on the graph: /camera/image_raw/compressed (set image_topic)"
    )
    deadline = time.monotonic() + 60
    seen = []
    while time.monotonic() < deadline:
        line = detector.stderr.readline()
        seen.append(line)
        if "no image has arrived" in line and "/camera/image_raw/compressed" in line:
            break
    assert expected in seen[-1], "".join(seen)
    assert detector.poll() is None
