"""objslam_tools.bag on tiny bags written here (MCAP and sqlite3), and its one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from objslam_common.cameras.unified import UnifiedCamera
from objslam_tools.bag import ImageFrame, decode_rgb, open_bag
from objslam_tools.errors import UserError
from tests.objslam_tools.synthetic_bag import (
    camera_info_msg,
    compressed_msg,
    image_msg,
    odometry_records,
    write_bag,
)

CAMERA = UnifiedCamera(width_px=40, height_px=30, xi=0.8, fx=20.0, fy=21.0, cx=19.5, cy=14.5)
S = 1_000_000_000


def _rgb(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, size=(30, 40, 3), dtype=np.uint8)


def _records():
    stamps = np.array([1 * S, 1 * S + 250_000_000, 2 * S, 3 * S + 1])
    poses = np.array([[0.0, 0.0, 0.0], [0.5, 0.1, 0.3], [1.0, -0.2, 3.1], [1.5, 0.0, -3.1]])
    records = odometry_records("/odom", stamps, poses)
    records += odometry_records("/ground_truth/odom", stamps, poses + 1.0)
    records.append(("/camera/camera_info", 1 * S, camera_info_msg(1 * S, CAMERA)))
    records.append(("/camera/image_raw", 2 * S, image_msg(2 * S, _rgb(1), "rgb8")))
    records.append(("/camera/image_raw", 3 * S, image_msg(3 * S, _rgb(2), "bgr8")))
    # Written out of time order on purpose: readers must return time order.
    records.sort(key=lambda r: -r[1])
    return records, stamps, poses


@pytest.fixture(params=["mcap", "sqlite3"])
def bag_dir(request, tmp_path):
    records, _, _ = _records()
    return write_bag(tmp_path / f"bag_{request.param}", records, storage=request.param)


def test_topics_and_counts(bag_dir):
    bag = open_bag(bag_dir)
    assert {n: (t.msgtype, t.count) for n, t in bag.topics.items()} == {
        "/odom": ("nav_msgs/msg/Odometry", 4),
        "/ground_truth/odom": ("nav_msgs/msg/Odometry", 4),
        "/camera/camera_info": ("sensor_msgs/msg/CameraInfo", 1),
        "/camera/image_raw": ("sensor_msgs/msg/Image", 2),
    }
    assert bag.message_count == 11
    assert bag.start_ns == 1 * S
    assert bag.directory == bag_dir


def test_raw_messages_in_time_order_and_filtered(bag_dir):
    bag = open_bag(bag_dir)
    all_stamps = [m.stamp_ns for m in bag.raw_messages()]
    assert all_stamps == sorted(all_stamps) and len(all_stamps) == 11
    odom = list(bag.raw_messages(["/odom", "/camera/image_raw"]))
    assert {m.topic for m in odom} == {"/odom", "/camera/image_raw"}
    assert len(odom) == 6
    first = odom[0]
    assert first.msgtype == "nav_msgs/msg/Odometry" and isinstance(first.data, bytes) and len(first.data) > 100


def test_decoded_messages_are_plain(bag_dir):
    raw, content = next(open_bag(bag_dir).messages(["/camera/camera_info"]))
    assert raw.topic == "/camera/camera_info"
    assert content["distortion_model"] == "unified"
    assert content["d"] == [pytest.approx(0.8)]
    assert content["header"]["stamp"] == {"sec": 1, "nanosec": 0}


def test_read_odometry(bag_dir):
    _, stamps, poses = _records()
    bag = open_bag(bag_dir)
    odom = bag.read_odometry()
    assert odom.stamps_ns.dtype == np.int64
    np.testing.assert_array_equal(odom.stamps_ns, stamps)
    np.testing.assert_allclose(odom.poses, poses, atol=1e-12)
    gt = bag.read_odometry("/ground_truth/odom")
    np.testing.assert_allclose(gt.poses[:, :2], poses[:, :2] + 1.0, atol=1e-12)
    # Interpolation takes the short way round through +-pi between the last two poses.
    mid = odom.interpolate([int(2.5 * S)])[0]
    assert abs(abs(mid[2]) - np.pi) < 0.05


def test_read_camera(bag_dir):
    assert open_bag(bag_dir).read_camera() == CAMERA


def test_raw_images(bag_dir):
    frames = list(open_bag(bag_dir).images())
    assert [f.stamp_ns for f in frames] == [2 * S, 3 * S]
    assert [f.encoding for f in frames] == ["rgb8", "bgr8"]
    assert frames[0].data.shape == (30, 40, 3)
    np.testing.assert_array_equal(decode_rgb(frames[0]), _rgb(1))
    np.testing.assert_array_equal(decode_rgb(frames[1]), _rgb(2))


def test_compressed_images(tmp_path):
    rgb = _rgb(3)
    records = [("/camera/image_raw/compressed", 5 * S, compressed_msg(5 * S, rgb, "png"))]
    bag = open_bag(write_bag(tmp_path / "c", records))
    assert bag.image_topic() == "/camera/image_raw/compressed"
    (frame,) = bag.images()
    assert frame.compressed and frame.encoding == "png" and frame.data.ndim == 1
    np.testing.assert_array_equal(decode_rgb(frame), rgb)


def test_mono_and_padded_rows():
    data = np.arange(12, dtype=np.uint8).reshape(3, 4)
    frame = ImageFrame(0, "mono8", data)
    rgb = decode_rgb(frame)
    assert rgb.shape == (3, 4, 3) and (rgb[:, :, 1] == data).all()


def test_padded_raw_image(tmp_path):
    msg = image_msg(S, _rgb(4)[:, :, 0], "mono8")
    msg.step = 48  # 8 padding bytes per row
    msg.data = np.concatenate([_rgb(4)[:, :, 0], np.zeros((30, 8), np.uint8)], axis=1).reshape(-1)
    (frame,) = open_bag(write_bag(tmp_path / "p", [("/camera/image_raw", S, msg)])).images()
    np.testing.assert_array_equal(frame.data, _rgb(4)[:, :, 0])


def test_missing_path(tmp_path):
    with pytest.raises(UserError, match="bag not found"):
        open_bag(tmp_path / "nope")


def test_folder_that_is_not_a_bag(tmp_path):
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(UserError, match=r"no metadata\.yaml"):
        open_bag(tmp_path)


def test_plain_file_is_not_a_bag(tmp_path):
    f = tmp_path / "map.yaml"
    f.write_text("objects: []")
    with pytest.raises(UserError, match="not a rosbag2 bag"):
        open_bag(f)


def test_corrupt_metadata(tmp_path):
    (tmp_path / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9}\n")
    with pytest.raises(UserError, match="cannot read bag") as info:
        open_bag(tmp_path)
    assert "\n" not in str(info.value)


def test_missing_topic_is_a_user_error(bag_dir):
    bag = open_bag(bag_dir)
    with pytest.raises(UserError, match="has no topic /nope"):
        list(bag.raw_messages(["/nope"]))
    with pytest.raises(UserError, match="expected nav_msgs/msg/Odometry"):
        bag.read_odometry("/camera/camera_info")


def test_missing_images_is_a_user_error(tmp_path):
    records = odometry_records("/odom", [S], np.zeros((1, 3)))
    bag = open_bag(write_bag(tmp_path / "o", records))
    with pytest.raises(UserError, match="no camera image topic"):
        next(bag.images())
    with pytest.raises(UserError, match="no camera info topic"):
        bag.read_camera()
