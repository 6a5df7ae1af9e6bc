"""How the simulated robot moves, and what its wheel odometry says about it.

The robot follows a smooth planar path (a cubic spline through waypoints, parametrised
by arc length) with its heading along the tangent, as a differential-drive robot does.
Its speed ramps up smoothly from rest, cruises, and ramps down to rest at the end.

Wheel odometry is integrated from the true motion increments between consecutive odometry
stamps, each disturbed by a systematic error (distance scale, turn scale, a turn bias
per metre: a real drift) and by white noise whose variance grows with distance and turn.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from objslam_common.geometry import rotation, wrap_angle
from objslam_tools.errors import ToolsError


class PathError(ToolsError, ValueError):
    """Waypoints that do not make a usable path."""


@dataclass(frozen=True)
class SmoothPath:
    """A C2 planar path through waypoints, sampled densely by arc length."""

    s_m: NDArray[np.float64]  # (K,) arc length of the samples
    xy_m: NDArray[np.float64]  # (K, 2)
    heading_rad: NDArray[np.float64]  # (K,)
    curvature_per_m: NDArray[np.float64]  # (K,)

    @classmethod
    def through(cls, waypoints_xy: NDArray[np.float64], step_m: float = 0.01) -> SmoothPath:
        # SciPy's interpolate pulls in its optimize (a quarter second) that `objslam sim
        # --help`, which lists the scenarios of this package, should not pay.
        from scipy.interpolate import CubicSpline

        pts = np.asarray(waypoints_xy, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
            raise PathError(f"need at least two (x, y) waypoints, got shape {pts.shape}")
        chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
        if np.any(np.diff(chord) <= 1e-6):
            raise PathError("consecutive waypoints coincide")
        spline = CubicSpline(chord, pts, bc_type="natural")
        # Integrate the speed along the spline parameter finely, then resample evenly in arc length.
        u = np.linspace(0.0, chord[-1], max(200, int(chord[-1] / step_m * 4)))
        speed = np.linalg.norm(spline(u, 1), axis=1)
        s_of_u = np.r_[0.0, np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(u))]
        s = np.linspace(0.0, s_of_u[-1], max(2, int(np.ceil(s_of_u[-1] / step_m)) + 1))
        u_s = np.interp(s, s_of_u, u)
        d1 = spline(u_s, 1)
        d2 = spline(u_s, 2)
        cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        curvature = cross / np.maximum(np.linalg.norm(d1, axis=1), 1e-9) ** 3
        return cls(s, spline(u_s), np.arctan2(d1[:, 1], d1[:, 0]), curvature)

    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])

    def truncated(self, length_m: float) -> SmoothPath:
        keep = self.s_m <= length_m + 1e-12
        return SmoothPath(self.s_m[keep], self.xy_m[keep], self.heading_rad[keep], self.curvature_per_m[keep])

    def pose_at(self, s_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N, 3) poses (x, y, heading) at arc lengths s (clamped to the path)."""
        s = np.clip(np.asarray(s_m, dtype=float), 0.0, self.length_m)
        x = np.interp(s, self.s_m, self.xy_m[:, 0])
        y = np.interp(s, self.s_m, self.xy_m[:, 1])
        heading = np.interp(s, self.s_m, np.unwrap(self.heading_rad))
        return np.stack([x, y, wrap_angle(heading)], axis=-1)


@dataclass(frozen=True)
class SpeedProfile:
    """Rest -> smooth ramp -> cruise -> smooth ramp -> rest, covering a path in a given time."""

    length_m: float
    duration_s: float
    ramp_s: float

    @classmethod
    def for_path(cls, length_m: float, duration_s: float, max_ramp_s: float = 1.5) -> SpeedProfile:
        if duration_s <= 0:
            raise PathError(f"duration must be positive, got {duration_s}")
        return cls(length_m, duration_s, min(max_ramp_s, duration_s / 4.0))

    @property
    def cruise_speed_mps(self) -> float:
        # Each smoothstep ramp covers half the distance it would at cruise speed.
        return self.length_m / (self.duration_s - self.ramp_s)

    def distance_at(self, t_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Arc length travelled at times t (s since the start)."""
        t = np.clip(np.asarray(t_s, dtype=float), 0.0, self.duration_s)
        v, r, total = self.cruise_speed_mps, self.ramp_s, self.duration_s

        def ramp_distance(tau: NDArray[np.float64]) -> NDArray[np.float64]:
            x = np.clip(tau / r, 0.0, 1.0)  # integral of the smoothstep 3x^2 - 2x^3
            return v * r * (x**3 - 0.5 * x**4)

        cruise = v * np.clip(t - r, 0.0, total - 2 * r)
        tail = ramp_distance(np.full_like(t, r)) - ramp_distance(r - np.clip(t - (total - r), 0.0, r))
        return ramp_distance(t) + cruise + tail


SPIN_S = 2.0 * np.pi / 1.0  # a turn at 1 rad/s on average, 1.5 rad/s at its fastest (smoothstep)
MAX_SPIN_SHARE = 0.5  # spins take at most this share of a drive's time


def spins_that_fit(duration_s: float, spins: int) -> int:
    """At most ``spins`` turns on the spot, as many as take at most half of ``duration_s``."""
    if spins < 0:
        raise PathError(f"spins must be >= 0, got {spins}")
    return min(spins, int(MAX_SPIN_SHARE * duration_s // SPIN_S))


@dataclass(frozen=True)
class Drive:
    """A path driven in ``duration_s``, stopping ``spins`` times to turn once around in place.

    A forward-looking camera sees only what lies ahead of the path; a turn on the spot shows
    it the whole room from there. The spins stand at the start of ``spins`` equal legs (the
    first where the drive begins), each :data:`SPIN_S` long, turning counter-clockwise with a
    smooth start and stop (at most 1.5 rad/s, so that slices still chain from image to
    image); each leg ramps from rest to rest. Without spins this is the path under one
    :class:`SpeedProfile`. :func:`spins_that_fit` says how many fit in a drive.
    """

    path: SmoothPath
    duration_s: float
    spins: int = 0

    def pose_at(self, t_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N, 3) true poses at times t (s since the start)."""
        t = np.asarray(t_s, dtype=float)
        if self.spins < 0:
            raise PathError(f"spins must be >= 0, got {self.spins}")
        if not self.spins:
            return self.path.pose_at(SpeedProfile.for_path(self.path.length_m, self.duration_s).distance_at(t))
        spin = SPIN_S
        leg_s = (self.duration_s - self.spins * spin) / self.spins
        leg_m = self.path.length_m / self.spins
        profile = SpeedProfile.for_path(leg_m, leg_s)
        period = spin + leg_s
        t = np.clip(t, 0.0, self.duration_s)
        k = np.minimum(np.floor(t / period), self.spins - 1)
        tau = t - k * period
        pose = self.path.pose_at(k * leg_m + profile.distance_at(np.clip(tau - spin, 0.0, leg_s)))
        x = np.clip(tau / spin, 0.0, 1.0)
        pose[..., 2] = wrap_angle(pose[..., 2] + 2.0 * np.pi * (3.0 * x**2 - 2.0 * x**3))
        return pose


@dataclass(frozen=True)
class OdometryNoise:
    """Wheel odometry errors per increment of forward distance d (m) and turn dtheta (rad).

    measured d      = d (1 + distance_scale) + N(0, distance_sigma^2 |d|)
    measured dtheta = dtheta (1 + turn_scale) + turn_bias_per_m |d|
                      + N(0, turn_sigma_per_rad^2 |dtheta| + turn_sigma_per_m^2 |d|)
    """

    distance_scale: float = 0.02  # systematic: over-reads distance by 2 %
    turn_scale: float = -0.02  # systematic: under-reads turns by 2 %
    turn_bias_rad_per_m: float = 0.001  # systematic: 0.057 deg of spurious left turn per metre
    distance_sigma_m_per_sqrt_m: float = 0.01
    turn_sigma_rad_per_sqrt_rad: float = 0.02
    turn_sigma_rad_per_sqrt_m: float = 0.003

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}


def increments(poses: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Forward distance (signed) and turn between consecutive (N, 3) poses."""
    d_xy = np.diff(poses[:, :2], axis=0)
    heading = poses[:-1, 2]
    forward = d_xy[:, 0] * np.cos(heading) + d_xy[:, 1] * np.sin(heading)
    distance = np.sign(forward) * np.linalg.norm(d_xy, axis=1)
    return distance, wrap_angle(np.diff(poses[:, 2]))


def noisy_increments(
    distance_m: NDArray[np.float64],
    turn_rad: NDArray[np.float64],
    noise: OdometryNoise,
    rng: np.random.Generator | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """What the wheel encoders report for true increments (rng None: systematic error only)."""
    d_abs = np.abs(distance_m)
    d = distance_m * (1.0 + noise.distance_scale)
    turn = turn_rad * (1.0 + noise.turn_scale) + noise.turn_bias_rad_per_m * d_abs
    if rng is not None:
        d = d + rng.standard_normal(len(d)) * noise.distance_sigma_m_per_sqrt_m * np.sqrt(d_abs)
        turn_var = noise.turn_sigma_rad_per_sqrt_rad**2 * np.abs(turn_rad) + noise.turn_sigma_rad_per_sqrt_m**2 * d_abs
        turn = turn + rng.standard_normal(len(turn)) * np.sqrt(turn_var)
    return d, turn


def integrate(
    distance_m: NDArray[np.float64], turn_rad: NDArray[np.float64], start: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """(N+1, 3) poses from N increments, each an arc (moving along the mid-step heading)."""
    start = np.zeros(3) if start is None else np.asarray(start, dtype=float)
    theta = start[2] + np.r_[0.0, np.cumsum(turn_rad)]
    mid = theta[:-1] + 0.5 * turn_rad
    local = np.stack([np.cumsum(distance_m * np.cos(mid)), np.cumsum(distance_m * np.sin(mid))], axis=-1)
    xy = np.vstack([np.zeros(2), local]) + start[:2]
    return np.column_stack([xy, wrap_angle(theta)])


def wheel_odometry(
    true_poses: NDArray[np.float64], noise: OdometryNoise, rng: np.random.Generator | None
) -> NDArray[np.float64]:
    """Odometry poses in the odom frame (starting at the identity) along the true poses."""
    distance, turn = increments(true_poses)
    return integrate(*noisy_increments(distance, turn, noise, rng))


def align_start(poses: NDArray[np.float64], start_pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """Express poses given in a frame whose origin is start_pose, in the outer frame."""
    xy = poses[:, :2] @ rotation(start_pose[2]).T + start_pose[:2]
    return np.column_stack([xy, wrap_angle(poses[:, 2] + start_pose[2])])
