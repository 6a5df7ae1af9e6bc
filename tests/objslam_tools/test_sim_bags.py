"""The bundled simulated bags keep the data contract (docs/design.md, "Data contract"), read back with rosbags."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from objslam_common.catalog import load_catalog
from objslam_common.mount import CameraMount
from objslam_tools.ground_truth import load_ground_truth
from objslam_tools.sim.motion import OdometryNoise

BAGS = Path(__file__).resolve().parents[2] / "bags"
BUNDLED = ("small", "office")
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
IMAGE_TOPICS = {
    "/camera/image_raw": "sensor_msgs/msg/Image",
    "/camera/image_raw/compressed": "sensor_msgs/msg/CompressedImage",
}
CONTRACT = {
    "/camera/camera_info": "sensor_msgs/msg/CameraInfo",
    "/odom": "nav_msgs/msg/Odometry",
    "/ground_truth/odom": "nav_msgs/msg/Odometry",
}


@dataclass
class BagData:
    topics: dict[str, str]
    log_ns: dict[str, np.ndarray]
    header_ns: dict[str, np.ndarray]
    first: dict[str, object]  # first message of every topic
    last_image: object
    odom: np.ndarray  # (N, 3) x, y, yaw
    truth: np.ndarray
    frames: dict[str, tuple[str, str]]  # topic -> (frame_id, child_frame_id)


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def yaw(q) -> float:
    return float(np.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z)))


@functools.cache
def read_bag(name: str) -> BagData:
    path = BAGS / name
    if not (path / "metadata.yaml").is_file():
        pytest.fail(f"bundled bag {path} is missing: render it as bags/README.md says")
    log: dict[str, list[int]] = {}
    head: dict[str, list[int]] = {}
    first: dict[str, object] = {}
    poses: dict[str, list[tuple[float, float, float]]] = {"/odom": [], "/ground_truth/odom": []}
    frames: dict[str, tuple[str, str]] = {}
    last_image = None
    with Reader(path) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        for conn, t_ns, raw in reader.messages():
            msg = TYPESTORE.deserialize_cdr(raw, conn.msgtype)
            log.setdefault(conn.topic, []).append(t_ns)
            head.setdefault(conn.topic, []).append(stamp_ns(msg.header))
            first.setdefault(conn.topic, msg)
            if conn.topic in poses:
                p = msg.pose.pose
                poses[conn.topic].append((p.position.x, p.position.y, yaw(p.orientation)))
                frames[conn.topic] = (msg.header.frame_id, msg.child_frame_id)
            elif conn.topic in IMAGE_TOPICS:
                last_image = msg
    return BagData(
        topics=topics,
        log_ns={k: np.array(v, dtype=np.int64) for k, v in log.items()},
        header_ns={k: np.array(v, dtype=np.int64) for k, v in head.items()},
        first=first,
        last_image=last_image,
        odom=np.array(poses["/odom"]),
        truth=np.array(poses["/ground_truth/odom"]),
        frames=frames,
    )


def image_topic(bag: BagData) -> str:
    (topic,) = [t for t in bag.topics if t in IMAGE_TOPICS]
    return topic


@pytest.mark.parametrize("name", BUNDLED)
def test_bag_is_mcap_with_the_contract_topics_and_types(name: str) -> None:
    meta = yaml.safe_load((BAGS / name / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap"
    bag = read_bag(name)
    topic = image_topic(bag)
    assert bag.topics == {**CONTRACT, topic: IMAGE_TOPICS[topic]}


@pytest.mark.parametrize("name", BUNDLED)
def test_rates_and_stamps(name: str) -> None:
    bag = read_bag(name)
    gt = load_ground_truth(BAGS / name)
    topic = image_topic(bag)
    for t in bag.topics:
        assert np.array_equal(bag.log_ns[t], bag.header_ns[t]), f"{t}: log time differs from header stamp"
        assert np.all(np.diff(bag.header_ns[t]) > 0), f"{t}: stamps not strictly increasing"
    # Images and camera info at 5 Hz, one camera info per image with the same stamp.
    assert len(bag.header_ns[topic]) == gt.simulation["frames"]
    assert np.array_equal(bag.header_ns[topic], bag.header_ns["/camera/camera_info"])
    assert np.all(np.diff(bag.header_ns[topic]) == 200_000_000)
    # Odometry and ground truth at 50 Hz on the same stamps, covering every image.
    assert np.array_equal(bag.header_ns["/odom"], bag.header_ns["/ground_truth/odom"])
    assert np.all(np.diff(bag.header_ns["/odom"]) == 20_000_000)
    assert bag.header_ns["/odom"][0] <= bag.header_ns[topic][0]
    assert bag.header_ns["/odom"][-1] >= bag.header_ns[topic][-1]
    # A realistic epoch: 2020..2030.
    assert 1_577_836_800 * 10**9 < bag.header_ns["/odom"][0] < 1_893_456_000 * 10**9


@pytest.mark.parametrize("name", BUNDLED)
def test_camera_info_and_images(name: str) -> None:
    bag = read_bag(name)
    info = bag.first["/camera/camera_info"]
    assert info.header.frame_id == "camera"
    assert (info.width, info.height, info.distortion_model) == (640, 640, "unified")
    np.testing.assert_array_equal(info.d, [0.9])
    np.testing.assert_array_equal(info.k, [170, 0, 320, 0, 170, 320, 0, 0, 1])
    for msg in (bag.first[image_topic(bag)], bag.last_image):
        assert msg.header.frame_id == "camera"
        if msg.__msgtype__ == "sensor_msgs/msg/CompressedImage":
            assert msg.format in ("png", "jpeg")
            rgb = cv2.imdecode(np.asarray(msg.data), cv2.IMREAD_COLOR)
        else:
            assert msg.encoding == "rgb8" and msg.step == 3 * msg.width
            rgb = np.asarray(msg.data).reshape(msg.height, msg.width, 3)
        assert rgb.shape == (640, 640, 3)
        assert rgb[320, 320].sum() > 100 and rgb[2, 2].sum() < 30  # floor in the middle, black outside the circle


@pytest.mark.parametrize("name", BUNDLED)
def test_frames_and_ground_truth_file(name: str) -> None:
    bag = read_bag(name)
    gt = load_ground_truth(BAGS / name)
    assert bag.frames["/odom"] == ("odom", "base_link")
    assert bag.frames["/ground_truth/odom"] == (gt.frame_id, "base_link") and gt.frame_id != "odom"
    # Odometry starts at the identity; the ground truth elsewhere: the frames differ.
    np.testing.assert_allclose(bag.odom[0], [0, 0, 0], atol=1e-12)
    assert np.hypot(*bag.truth[0, :2]) > 0.5
    np.testing.assert_allclose(bag.truth[0], gt.simulation["initial_pose"], atol=1e-5)
    assert gt.mount == CameraMount()
    catalog = load_catalog()
    assert {o.label for o in gt.objects} <= set(catalog.labels)
    assert len(gt.objects) >= 4 and any(o.position_m[2] > 0 for o in gt.objects)
    assert gt.distractors and all(d.kind == "poster" for d in gt.distractors)


def increments(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed forward distance and turn between consecutive (N, 3) poses."""
    step = np.diff(poses[:, :2], axis=0)
    forward = step[:, 0] * np.cos(poses[:-1, 2]) + step[:, 1] * np.sin(poses[:-1, 2])
    distance = np.sign(forward) * np.hypot(*step.T)  # noise may read a tiny step backwards while crawling
    return distance, np.angle(np.exp(1j * np.diff(poses[:, 2])))


def integrate_from(start: np.ndarray, distance: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """Final (..., 2) position of arcs integrated from a start pose; leading axes are draws."""
    theta = start[2] + np.cumsum(turn, axis=-1)
    mid = theta - turn / 2
    return start[:2] + np.stack([np.sum(distance * np.cos(mid), -1), np.sum(distance * np.sin(mid), -1)], -1)


@pytest.mark.parametrize("name", BUNDLED)
def test_odometry_drift_is_within_the_documented_noise(name: str) -> None:
    bag = read_bag(name)
    gt = load_ground_truth(BAGS / name)
    noise = OdometryNoise(**gt.simulation["odometry_noise"])
    assert noise == OdometryNoise(), "bags/README.md documents the default noise figures"
    d_true, t_true = increments(bag.truth)
    d_odom, t_odom = increments(bag.odom)
    moving = d_true > 1e-4
    # Random part, normalised by the documented standard deviations: unit spread.
    r_d = (d_odom - d_true * (1 + noise.distance_scale))[moving] / np.sqrt(d_true[moving])
    assert r_d.std() == pytest.approx(noise.distance_sigma_m_per_sqrt_m, rel=0.15)
    turn_var = noise.turn_sigma_rad_per_sqrt_rad**2 * np.abs(t_true) + noise.turn_sigma_rad_per_sqrt_m**2 * d_true
    r_t = (t_odom - t_true * (1 + noise.turn_scale) - noise.turn_bias_rad_per_m * d_true)[moving]
    assert (r_t / np.sqrt(turn_var[moving])).std() == pytest.approx(1.0, rel=0.15)
    # Systematic part: the distance scale shows in the total distance.
    assert d_odom.sum() / d_true.sum() - 1 == pytest.approx(noise.distance_scale, abs=0.01)

    # The final position error (after aligning the start poses) is a plausible draw of the noise model.
    rng = np.random.default_rng(0)
    draws = 1000
    d_sim = d_true * (1 + noise.distance_scale) + rng.standard_normal((draws, len(d_true))) * (
        noise.distance_sigma_m_per_sqrt_m * np.sqrt(d_true)
    )
    t_sim = t_true * (1 + noise.turn_scale) + noise.turn_bias_rad_per_m * d_true
    t_sim = t_sim + rng.standard_normal((draws, len(t_true))) * np.sqrt(turn_var)
    errors = np.hypot(*(integrate_from(bag.truth[0], d_sim, t_sim) - bag.truth[-1, :2]).T)
    bag_end = integrate_from(bag.truth[0], d_odom, t_odom)
    bag_error = float(np.hypot(*(bag_end - bag.truth[-1, :2])))
    lo, hi = np.quantile(errors, [0.001, 0.999])
    assert lo <= bag_error <= hi, f"final odometry error {bag_error:.3f} m outside [{lo:.3f}, {hi:.3f}] m"
    # The odometry in the bag is exactly these increments integrated (no hidden extra error).
    np.testing.assert_allclose(integrate_from(np.zeros(3), d_odom, t_odom), bag.odom[-1, :2], atol=1e-6)
    assert hi > 0.1, "the noise model must allow a real drift"
