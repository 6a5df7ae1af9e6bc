"""Fuzzing the message conversions both paths share: any field values give a record or the
conversion's own error (MessageError, CameraModelError), never another exception, and a
record that comes out is valid (finite, unit heading)."""

from __future__ import annotations

import math
from types import SimpleNamespace as Msg

from hypothesis import given, settings
from hypothesis import strategies as st

from objslam_common.cameras import FisheyeCamera, PinholeCamera, UnifiedCamera
from objslam_common.errors import CameraModelError, MessageError
from objslam_common.ros.conversions import camera_from_info, image_slices, odometry_sample

ANY_FLOAT = st.floats() | st.integers(-(2**40), 2**40).map(float)
STAMPS = st.builds(Msg, stamp=st.builds(Msg, sec=st.integers(0, 2**31 - 1), nanosec=st.integers(0, 999_999_999)))


def _odometry(draw_values):
    x, y, qx, qy, qz, qw = draw_values
    pose = Msg(position=Msg(x=x, y=y, z=0.0), orientation=Msg(x=qx, y=qy, z=qz, w=qw))
    return pose


@settings(max_examples=300, deadline=None)
@given(header=STAMPS, values=st.tuples(*[ANY_FLOAT] * 6))
def test_any_odometry_is_a_finite_sample_or_one_message_error(header, values):
    msg = Msg(header=header, pose=Msg(pose=_odometry(values)))
    try:
        sample = odometry_sample(msg)
    except MessageError as exc:
        assert exc.kind in ("odometry pose is not finite", "odometry orientation is not a unit quaternion")
        return
    assert all(math.isfinite(v) for v in (sample.x_m, sample.y_m, sample.theta_rad))
    assert -math.pi <= sample.theta_rad <= math.pi
    qx, qy, qz, qw = values[2:]
    assert abs(math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) - 1.0) <= 1e-3


SLICES = st.builds(
    Msg,
    label=st.text(max_size=6),
    confidence=ANY_FLOAT,
    bearing=ANY_FLOAT,
    angular_width=ANY_FLOAT,
    elevation_bottom=ANY_FLOAT,
    elevation_top=ANY_FLOAT,
    radius_inner_px=ANY_FLOAT,
    radius_outer_px=ANY_FLOAT,
    angle_start_rad=ANY_FLOAT,
    angle_end_rad=ANY_FLOAT,
    pixel_count=st.integers(-(2**31), 2**31),
    truncated=st.booleans(),
    cut_edges=st.integers(0, 15),
)


@settings(max_examples=200, deadline=None)
@given(header=STAMPS, slices=st.lists(SLICES, max_size=5))
def test_any_slice_array_keeps_the_valid_slices_and_counts_the_rest(header, slices):
    image, invalid = image_slices(Msg(header=header, slices=slices))
    assert len(image.slices) + invalid == len(slices)
    for s in image.slices:
        values = (s.bearing_rad, s.angular_width_rad, s.elevation_bottom_rad, s.elevation_top_rad)
        assert all(math.isfinite(v) for v in values)


@settings(max_examples=300, deadline=None)
@given(
    width=st.integers(-10, 10_000),
    height=st.integers(-10, 10_000),
    model=st.sampled_from(["unified", "plumb_bob", "rational_polynomial", "equidistant", "", "Unified"])
    | st.text(max_size=8),
    d=st.lists(ANY_FLOAT, max_size=6),
    k=st.lists(ANY_FLOAT, min_size=0, max_size=10),
)
def test_any_camera_info_is_a_camera_or_one_camera_model_error(width, height, model, d, k):
    msg = Msg(width=width, height=height, distortion_model=model, d=d, k=k)
    try:
        camera = camera_from_info(msg)
    except CameraModelError as exc:
        assert "\n" not in str(exc)
        return
    assert isinstance(camera, (UnifiedCamera, PinholeCamera, FisheyeCamera))
    assert camera.distortion_model == model
    assert camera.width_px > 0 and camera.height_px > 0
    assert all(math.isfinite(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy)) and min(camera.fx, camera.fy) > 0
