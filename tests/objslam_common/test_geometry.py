"""SE(2) helpers and the one angle wrap, against numbers and identities."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from objslam_common.geometry import (
    between,
    between_rows,
    compose,
    compose_rows,
    interpolate_pose,
    inverse,
    quaternion_from_yaw,
    transform_points,
    wrap_angle,
    yaw_from_quaternion,
)

coord = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-20, 20, allow_nan=False)
poses = st.tuples(coord, coord, angle).map(np.array)


@given(angle)
def test_wrap_angle_lands_in_range_and_keeps_the_direction(a):
    w = wrap_angle(a)
    assert -np.pi <= w < np.pi
    assert np.isclose(np.cos(w), np.cos(a)) and np.isclose(np.sin(w), np.sin(a))


def test_wrap_angle_on_arrays():
    np.testing.assert_allclose(
        wrap_angle(np.array([np.pi, 3 * np.pi / 2, -np.pi / 2])), [-np.pi, -np.pi / 2, -np.pi / 2]
    )


@given(poses, poses)
def test_between_undoes_compose(a_T_b, b_T_c):
    a_T_c = compose(a_T_b, b_T_c)
    got = between(a_T_b, a_T_c)
    np.testing.assert_allclose(got[:2], b_T_c[:2], atol=1e-7)
    assert abs(wrap_angle(got[2] - b_T_c[2])) < 1e-9


@given(st.lists(st.tuples(poses, poses), min_size=1, max_size=5))
def test_row_wise_compose_and_between_are_the_single_ones(pairs):
    a, b = (np.array(side) for side in zip(*pairs, strict=True))
    np.testing.assert_allclose(compose_rows(a, b), [compose(p, q) for p, q in pairs], atol=1e-9)
    np.testing.assert_allclose(between_rows(a, b), [between(p, q) for p, q in pairs], atol=1e-9)


@given(poses)
def test_inverse_composes_to_identity(a_T_b):
    ident = compose(a_T_b, inverse(a_T_b))
    np.testing.assert_allclose(ident, [0, 0, 0], atol=1e-7)


def test_transform_points_known_numbers():
    np.testing.assert_allclose(transform_points([1.0, 2.0, np.pi / 2], [[1.0, 0.0]]), [[1.0, 3.0]])


def test_interpolation_takes_the_short_way_round():
    mid = interpolate_pose([0, 0, np.pi - 0.1], [2, 0, -np.pi + 0.1], 0.5)
    np.testing.assert_allclose(mid[:2], [1, 0])
    assert abs(abs(mid[2]) - np.pi) < 1e-9


@given(angle)
def test_quaternion_yaw_round_trip(yaw):
    assert abs(wrap_angle(yaw_from_quaternion(*quaternion_from_yaw(yaw)) - yaw)) < 1e-9
