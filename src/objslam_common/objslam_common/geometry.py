"""Planar geometry: angle wrapping and SE(2) poses as (x, y, theta) arrays.

This is the one place where angles are wrapped; everything else calls ``wrap_angle``.
Poses are named ``a_T_b``: the pose of frame b expressed in frame a, so that
``compose(a_T_b, b_T_c) == a_T_c``.
"""

from __future__ import annotations

from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

_TWO_PI = 2.0 * np.pi


@overload
def wrap_angle(angle_rad: float) -> float: ...
@overload
def wrap_angle(angle_rad: NDArray[Any]) -> NDArray[np.float64]: ...
@overload
def wrap_angle(angle_rad: ArrayLike) -> NDArray[np.float64] | float: ...
def wrap_angle(angle_rad: ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angles to [-pi, pi). Works on scalars and arrays."""
    angle = np.asarray(angle_rad, dtype=float)
    # Rounding is several times faster than np.mod on arrays (this runs on every slice of
    # every solver iteration); rounding sends odd multiples of pi to +pi, moved to -pi.
    wrapped = np.asarray(angle - _TWO_PI * np.round(angle / _TWO_PI))
    if wrapped.ndim == 0:
        value = float(wrapped)
        return value - _TWO_PI if value >= np.pi else value
    np.subtract(wrapped, _TWO_PI, out=wrapped, where=wrapped >= np.pi)
    return wrapped


def rotation(theta_rad: float) -> NDArray[np.float64]:
    """2x2 rotation matrix."""
    c, s = np.cos(theta_rad), np.sin(theta_rad)
    return np.array([[c, -s], [s, c]])


def compose(a_T_b: ArrayLike, b_T_c: ArrayLike) -> NDArray[np.float64]:
    """a_T_c from a_T_b and b_T_c, each (x, y, theta)."""
    a_T_b = np.asarray(a_T_b, dtype=float)
    b_T_c = np.asarray(b_T_c, dtype=float)
    xy = a_T_b[:2] + rotation(a_T_b[2]) @ b_T_c[:2]
    return np.array([xy[0], xy[1], wrap_angle(a_T_b[2] + b_T_c[2])])


def inverse(a_T_b: ArrayLike) -> NDArray[np.float64]:
    """b_T_a from a_T_b."""
    a_T_b = np.asarray(a_T_b, dtype=float)
    xy = -(rotation(a_T_b[2]).T @ a_T_b[:2])
    return np.array([xy[0], xy[1], wrap_angle(-a_T_b[2])])


def between(a_T_b: ArrayLike, a_T_c: ArrayLike) -> NDArray[np.float64]:
    """b_T_c: the motion from b to c, both given in frame a."""
    return compose(inverse(a_T_b), a_T_c)


def compose_rows(a_T_b: ArrayLike, b_T_c: ArrayLike) -> NDArray[np.float64]:
    """``compose`` row by row of (N, 3) poses (rows broadcast)."""
    a_T_b = np.atleast_2d(np.asarray(a_T_b, dtype=float))
    b_T_c = np.atleast_2d(np.asarray(b_T_c, dtype=float))
    cos_t, sin_t = np.cos(a_T_b[:, 2]), np.sin(a_T_b[:, 2])
    x = a_T_b[:, 0] + cos_t * b_T_c[:, 0] - sin_t * b_T_c[:, 1]
    y = a_T_b[:, 1] + sin_t * b_T_c[:, 0] + cos_t * b_T_c[:, 1]
    return np.stack(np.broadcast_arrays(x, y, wrap_angle(a_T_b[:, 2] + b_T_c[:, 2])), axis=-1)


def between_rows(a_T_b: ArrayLike, a_T_c: ArrayLike) -> NDArray[np.float64]:
    """``between`` row by row of (N, 3) poses (rows broadcast)."""
    a_T_b = np.atleast_2d(np.asarray(a_T_b, dtype=float))
    a_T_c = np.atleast_2d(np.asarray(a_T_c, dtype=float))
    cos_t, sin_t = np.cos(a_T_b[:, 2]), np.sin(a_T_b[:, 2])
    dx, dy = a_T_c[:, 0] - a_T_b[:, 0], a_T_c[:, 1] - a_T_b[:, 1]
    x, y = cos_t * dx + sin_t * dy, -sin_t * dx + cos_t * dy
    return np.stack(np.broadcast_arrays(x, y, wrap_angle(a_T_c[:, 2] - a_T_b[:, 2])), axis=-1)


def transform_points(a_T_b: ArrayLike, b_points_xy: ArrayLike) -> NDArray[np.float64]:
    """Map (N, 2) points from frame b into frame a."""
    a_T_b = np.asarray(a_T_b, dtype=float)
    pts = np.atleast_2d(np.asarray(b_points_xy, dtype=float))
    return pts @ rotation(a_T_b[2]).T + a_T_b[:2]


def interpolate_pose(a_T_b0: ArrayLike, a_T_b1: ArrayLike, fraction: float) -> NDArray[np.float64]:
    """Pose a fraction of the way from b0 to b1 (linear in x, y; shortest arc in theta)."""
    p0 = np.asarray(a_T_b0, dtype=float)
    p1 = np.asarray(a_T_b1, dtype=float)
    xy = p0[:2] + fraction * (p1[:2] - p0[:2])
    theta = p0[2] + fraction * wrap_angle(p1[2] - p0[2])
    return np.array([xy[0], xy[1], wrap_angle(theta)])


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rotation about z) of a unit quaternion, rad."""
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def rpy_from_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Roll, pitch, yaw (rad, ROS fixed axes: R = Rz(yaw) Ry(pitch) Rx(roll)) of a unit quaternion."""
    roll = float(np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)))
    pitch = float(np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0)))
    return roll, pitch, yaw_from_quaternion(x, y, z, w)


def quaternion_from_rpy(roll_rad: float, pitch_rad: float, yaw_rad: float) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of ROS fixed-axis roll, pitch, yaw (the inverse of :func:`rpy_from_quaternion`)."""
    cr, sr = np.cos(roll_rad / 2.0), np.sin(roll_rad / 2.0)
    cp, sp = np.cos(pitch_rad / 2.0), np.sin(pitch_rad / 2.0)
    cy, sy = np.cos(yaw_rad / 2.0), np.sin(yaw_rad / 2.0)
    return (
        float(sr * cp * cy - cr * sp * sy),
        float(cr * sp * cy + sr * cp * sy),
        float(cr * cp * sy - sr * sp * cy),
        float(cr * cp * cy + sr * sp * sy),
    )


def rotation_from_rpy(roll_rad: float, pitch_rad: float, yaw_rad: float = 0.0) -> NDArray[np.float64]:
    """3x3 rotation Rz(yaw) Ry(pitch) Rx(roll): positive pitch tilts the x axis down."""
    cr, sr = np.cos(roll_rad), np.sin(roll_rad)
    cp, sp = np.cos(pitch_rad), np.sin(pitch_rad)
    cy, sy = np.cos(yaw_rad), np.sin(yaw_rad)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


def quaternion_from_yaw(yaw_rad: float) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of a rotation about z."""
    return (0.0, 0.0, float(np.sin(yaw_rad / 2.0)), float(np.cos(yaw_rad / 2.0)))
