"""Robot poses at image stamps, from wheel odometry, and the odometry noise model.

Poses are interpolated (``geometry.interpolate_pose``) between the two odometry samples
around each image stamp. Stamps before the first or after the last odometry sample
cannot be interpolated: they are rejected, and counted, never extrapolated.

Between consecutive image poses the odometry increment ``u_i = between(o_i, o_{i+1})``
(in the frame of pose i) is the measurement of the odometry factor. Its noise is a random
walk (paper eq. 9, ``Q_i``): with path length ``s`` and absolute turn ``t`` travelled
between the two stamps (summed along the odometry samples, so a curve counts its length,
not its chord),

    var_xy    = xy_per_sqrt_m^2 s + xy_per_sqrt_rad^2 t + min_xy^2        (each of x, y)
    var_theta = theta_per_sqrt_m^2 s + theta_per_sqrt_rad^2 t + min_theta^2

The systematic part of the odometry error (distance and turn scales, turn bias per metre)
is not noise: the graph estimates it as a variable (``odometry.calibration``, see
:mod:`objslam_mapper.graph.linearize`), using ``s`` of each increment for the bias.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.geometry import between, interpolate_pose, wrap_angle
from objslam_common.records import OdometrySample
from objslam_mapper.config import OdometryNoiseConfig
from objslam_mapper.errors import MapperError

logger = logging.getLogger(__name__)


class TrajectoryError(MapperError, ValueError):
    """Odometry that cannot give poses."""


@dataclass(frozen=True)
class PosesAtStamps:
    """Odometry poses at the accepted stamps, in odometry order.

    ``accepted`` is a mask over the requested stamps; ``poses`` (K, 3), ``path_length_m``
    and ``turn_rad`` (cumulative along the odometry since its first sample) hold one row
    per accepted stamp, in the order of the requested stamps.
    """

    accepted: NDArray[np.bool_]
    poses: NDArray[np.float64]
    path_length_m: NDArray[np.float64]
    turn_rad: NDArray[np.float64]

    @property
    def rejected_count(self) -> int:
        return int(np.count_nonzero(~self.accepted))


def _sorted_odometry(odometry: Sequence[OdometrySample]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    if not odometry:
        raise TrajectoryError("no odometry samples")
    stamps = np.array([s.stamp_ns for s in odometry], dtype=np.int64)
    poses = np.array([(s.x_m, s.y_m, s.theta_rad) for s in odometry], dtype=float)
    order = np.argsort(stamps, kind="stable")
    stamps, poses = stamps[order], poses[order]
    # A repeated stamp carries no motion; keep the last sample of each stamp.
    keep = np.append(stamps[1:] != stamps[:-1], True)
    return stamps[keep], poses[keep]


def poses_at_stamps(odometry: Sequence[OdometrySample], stamps_ns: ArrayLike) -> PosesAtStamps:
    """Interpolate odometry at each stamp; stamps outside the odometry span are rejected."""
    odo_stamps, odo_poses = _sorted_odometry(odometry)
    steps = np.diff(odo_poses, axis=0)
    step_length = np.hypot(steps[:, 0], steps[:, 1])
    step_turn = np.abs(wrap_angle(steps[:, 2])) if len(steps) else np.zeros(0)
    cum_length = np.concatenate([[0.0], np.cumsum(step_length)])
    cum_turn = np.concatenate([[0.0], np.cumsum(step_turn)])

    stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    accepted = (stamps >= odo_stamps[0]) & (stamps <= odo_stamps[-1])
    kept = stamps[accepted]
    # Index of the sample at or before each stamp; the last sample pairs with itself.
    lower = np.clip(np.searchsorted(odo_stamps, kept, side="right") - 1, 0, len(odo_stamps) - 1)
    upper = np.minimum(lower + 1, len(odo_stamps) - 1)
    span = (odo_stamps[upper] - odo_stamps[lower]).astype(float)
    fraction = np.where(span > 0, (kept - odo_stamps[lower]).astype(float) / np.where(span > 0, span, 1.0), 0.0)
    poses = np.array(
        [interpolate_pose(odo_poses[lo], odo_poses[up], f) for lo, up, f in zip(lower, upper, fraction, strict=True)]
    ).reshape(-1, 3)
    path_length = cum_length[lower] + fraction * (cum_length[upper] - cum_length[lower])
    turn = cum_turn[lower] + fraction * (cum_turn[upper] - cum_turn[lower])
    result = PosesAtStamps(accepted=accepted, poses=poses, path_length_m=path_length, turn_rad=turn)
    if result.rejected_count:
        logger.warning(
            "%d of %d image stamps lie outside the odometry span [%d, %d] ns and were rejected",
            result.rejected_count,
            len(stamps),
            odo_stamps[0],
            odo_stamps[-1],
        )
    return result


def odometry_increments(poses: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N-1, 3) motions between consecutive poses, each in the frame of the earlier pose."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    return np.array([between(a, b) for a, b in itertools.pairwise(poses)]).reshape(-1, 3)


def increment_stddev(
    path_length_m: NDArray[np.float64], turn_rad: NDArray[np.float64], noise: OdometryNoiseConfig
) -> NDArray[np.float64]:
    """(N, 3) standard deviations (x, y, theta) of increments with this length and turn."""
    s = np.abs(np.asarray(path_length_m, dtype=float))
    t = np.abs(np.asarray(turn_rad, dtype=float))
    var_xy = noise.xy_stddev_per_sqrt_m**2 * s + noise.xy_stddev_per_sqrt_rad**2 * t + noise.min_xy_stddev_m**2
    var_th = noise.theta_stddev_per_sqrt_m**2 * s + noise.theta_stddev_per_sqrt_rad**2 * t
    var_th = var_th + noise.min_theta_stddev_rad**2
    return np.sqrt(np.stack([var_xy, var_xy, var_th], axis=-1))
