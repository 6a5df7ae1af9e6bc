"""The camera mount from a bag's /tf_static (base_link -> the camera frame), and which mount
``objslam map`` takes: the bag's, else the parameters'; disagreeing parameter files are refused."""

from __future__ import annotations

import pytest

from objslam_common.cameras import DEFAULT_CAMERA
from objslam_common.mount import CameraMount, CameraMountConfig
from objslam_tools.bag import open_bag
from objslam_tools.errors import UserError
from objslam_tools.mapping import bag_mount
from objslam_tools.sim.messages import mount_transform
from tests.objslam_tools.synthetic_bag import _T, camera_info_msg, odometry_msg, write_bag

MOUNT = CameraMount(height_m=0.42, offset_x_m=0.12, offset_y_m=-0.03, yaw_rad=0.2, roll_rad=-0.05, pitch_rad=0.15)


def _bag(tmp_path, tf_messages=()):
    records = [
        ("/camera/camera_info", 1, camera_info_msg(1, DEFAULT_CAMERA)),
        ("/odom", 1, odometry_msg(1, (0.0, 0.0, 0.0))),
        *(("/tf_static", 1, m) for m in tf_messages),
    ]
    return open_bag(write_bag(tmp_path / "bag", records))


def _renamed(message, parent: str, child: str):
    t = message.transforms[0]
    header = _T["std_msgs/msg/Header"](stamp=t.header.stamp, frame_id=parent)
    stamped = _T["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id=child, transform=t.transform)
    return _T["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def test_the_mount_is_read_from_tf_static(tmp_path):
    reading = _bag(tmp_path, [mount_transform(1, MOUNT)]).read_mount()
    assert reading is not None and reading.source == "/tf_static base_link -> camera"
    for name in ("height_m", "offset_x_m", "offset_y_m", "yaw_rad", "roll_rad", "pitch_rad"):
        assert getattr(reading.mount, name) == pytest.approx(getattr(MOUNT, name), abs=1e-9), name


def test_the_camera_frame_is_picked_among_other_transforms(tmp_path):
    laser = _renamed(mount_transform(1, CameraMount(height_m=0.2)), "base_link", "laser")
    reading = _bag(tmp_path, [laser, mount_transform(1, MOUNT)]).read_mount()
    assert reading is not None and reading.mount.height_m == pytest.approx(0.42)


def test_a_tf_static_without_the_camera_is_one_clear_error(tmp_path):
    laser = _renamed(mount_transform(1, MOUNT), "base_link", "laser")
    imu = _renamed(mount_transform(1, MOUNT), "base_link", "imu")
    with pytest.raises(UserError, match=r"no transform base_link -> 'camera'.*imu, laser"):
        _bag(tmp_path, [laser, imu]).read_mount()


def test_without_tf_static_the_parameters_give_the_mount(tmp_path):
    bag = _bag(tmp_path)
    assert bag.read_mount() is None
    given = CameraMountConfig(height_m=0.3)
    assert bag_mount(bag, given, CameraMountConfig()) == (given, "camera_mount parameters")
    # The detector's file alone may give it too; two different ones are refused.
    assert bag_mount(bag, CameraMountConfig(), given)[0] == given
    with pytest.raises(UserError, match="different camera_mount"):
        bag_mount(bag, given, CameraMountConfig(pitch_rad=0.1))


def test_tf_static_wins_over_the_parameters(tmp_path):
    bag = _bag(tmp_path, [mount_transform(1, MOUNT)])
    mount, source = bag_mount(bag, CameraMountConfig(height_m=0.3), CameraMountConfig())
    assert source.startswith("/tf_static") and mount.pitch_rad == pytest.approx(0.15)
