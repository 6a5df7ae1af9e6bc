"""Planar trajectories as arrays: interpolation, SE(2) alignment and absolute trajectory error.

A trajectory is a :class:`PoseTrack`: integer stamps (ns) and ``(N, 3)`` poses
``(x, y, theta)`` of ``base_link`` in one frame. Used for the odometry topics of a bag and
for a map's estimated trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.geometry import rotation, wrap_angle


@dataclass(frozen=True, eq=False)
class PoseTrack:
    """Poses sorted by stamp: ``stamps_ns`` (N,) int64, ``poses`` (N, 3) x [m], y [m], theta [rad]."""

    stamps_ns: NDArray[np.int64]
    poses: NDArray[np.float64]

    def __post_init__(self) -> None:
        stamps = np.asarray(self.stamps_ns, dtype=np.int64).reshape(-1)
        poses = np.asarray(self.poses, dtype=float).reshape(-1, 3)
        if len(stamps) != len(poses):
            raise ValueError(f"{len(stamps)} stamps for {len(poses)} poses")
        order = np.argsort(stamps, kind="stable")
        object.__setattr__(self, "stamps_ns", stamps[order])
        object.__setattr__(self, "poses", poses[order])

    def __len__(self) -> int:
        return len(self.stamps_ns)

    def covers(self, stamps_ns: ArrayLike) -> NDArray[np.bool_]:
        """Which stamps lie within the track's time span (interpolation, not extrapolation)."""
        s = np.asarray(stamps_ns, dtype=np.int64)
        if len(self) == 0:
            return np.zeros(s.shape, dtype=bool)
        return (s >= self.stamps_ns[0]) & (s <= self.stamps_ns[-1])

    def interpolate(self, stamps_ns: ArrayLike) -> NDArray[np.float64]:
        """(M, 3) poses at the stamps: linear in x, y, shortest arc in theta; held constant outside the span."""
        if len(self) == 0:
            raise ValueError("cannot interpolate an empty trajectory")
        s = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        if len(self) == 1:
            return np.repeat(self.poses, len(s), axis=0)
        hi = np.clip(np.searchsorted(self.stamps_ns, s, side="left"), 1, len(self) - 1)
        lo = hi - 1
        span = (self.stamps_ns[hi] - self.stamps_ns[lo]).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = np.where(span > 0, (s - self.stamps_ns[lo]).astype(float) / span, 0.0)
        frac = np.clip(frac, 0.0, 1.0)[:, None]
        p0, p1 = self.poses[lo], self.poses[hi]
        xy = p0[:, :2] + frac * (p1[:, :2] - p0[:, :2])
        theta = wrap_angle(p0[:, 2] + frac[:, 0] * wrap_angle(p1[:, 2] - p0[:, 2]))
        return np.column_stack([xy, np.atleast_1d(theta)])


def transform_poses(a_T_b: ArrayLike, b_poses: ArrayLike) -> NDArray[np.float64]:
    """Express (N, 3) poses given in frame b in frame a."""
    a_T_b = np.asarray(a_T_b, dtype=float)
    poses = np.asarray(b_poses, dtype=float).reshape(-1, 3)
    xy = poses[:, :2] @ rotation(a_T_b[2]).T + a_T_b[:2]
    return np.column_stack([xy, np.atleast_1d(wrap_angle(poses[:, 2] + a_T_b[2]))])


def fit_se2(source_xy: ArrayLike, target_xy: ArrayLike) -> NDArray[np.float64]:
    """Least-squares rigid fit: target_T_source (x, y, theta) minimising sum |R p_s + t - p_t|^2.

    Closed form (2-D Umeyama/Kabsch without scale). Needs at least one point; with a single
    point (or all points equal) the rotation is undetermined and taken as zero.
    """
    src = np.asarray(source_xy, dtype=float).reshape(-1, 2)
    dst = np.asarray(target_xy, dtype=float).reshape(-1, 2)
    if len(src) != len(dst) or len(src) == 0:
        raise ValueError(f"need equally many (>= 1) points, got {len(src)} and {len(dst)}")
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    # For 2-D rotations the optimal angle is atan2 of the summed cross and dot products.
    cross = float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))
    dot = float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]))
    theta = float(np.arctan2(cross, dot)) if (abs(cross) + abs(dot)) > 0 else 0.0
    t = mu_d - rotation(theta) @ mu_s
    return np.array([t[0], t[1], theta])


def position_rmse(estimated_xy: ArrayLike, reference_xy: ArrayLike) -> float:
    """Root mean square of the xy distances (the ATE once the estimate is aligned)."""
    d = np.asarray(estimated_xy, dtype=float).reshape(-1, 2) - np.asarray(reference_xy, dtype=float).reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1)))) if len(d) else float("nan")
