"""Chaining slices of one class across consecutive images into tracklets.

Before sampling associations the paper filters the input "by associating similar
measurements in consecutive images and removing those that could not be associated to
any other" (section 5). Here a slice in image ``i`` continues a tracklet whose last slice
is in image ``i - g`` when the gap is short (``g <= max_frame_gap``, or the robot
travelled at most ``max_gap_travel_m`` and turned at most ``max_gap_turn_rad`` in
between), both are of the same class and the slice's bearing, elevations and width match
what the earlier slice predicts after the odometry motion between the two images:

- the earlier slice's range is estimated from its apparent size and the class's nominal
  size (width, top and bottom edges each give a range; their median is used);
- the point at that range and bearing is carried into the later camera pose, giving a
  predicted bearing, elevations (the edges' heights at the earlier range) and width;
- the range is uncertain (``range_relative_uncertainty``), so the prediction is an
  interval spanned by the near and far ends of the range; a component matches when it
  lies within its gate of that interval.

Within each image pair, slices and tracklets are matched one-to-one by the smallest total
normalized innovation (Hungarian assignment). Tracklets shorter than ``min_length``
(isolated detections, by default) are dropped and counted.

Bounding a gap in robot motion as well as in images makes the chaining a property of the
path rather than of the frame rate: the same path recorded with four times the images (a
slower robot) then gives about the same tracklets instead of more breaks where an object
flickers in and out of detection, and the number of tracklets is what the sampler's cost
grows with. At the simulated bags' 8 cm per image the motion bound only matters where the
robot (nearly) stands still, at the ends of a run: elsewhere a skipped image is 16 cm.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from objslam_common.geometry import wrap_angle
from objslam_common.mount import CameraMount
from objslam_mapper.config import TrackletConfig
from objslam_mapper.graph.problem import GraphProblem

logger = logging.getLogger(__name__)

_INFEASIBLE = 1e12


@dataclass(frozen=True)
class ClassShape:
    """Nominal geometry of a class (catalog means): base height, diameter, height, m."""

    z_base_m: float
    diameter_m: float
    height_m: float


@dataclass(frozen=True)
class Tracklet:
    """Slices of one class chained over images; indices are global measurement indices."""

    label: str
    measurement_indices: tuple[int, ...]
    frame_indices: tuple[int, ...]  # the image (pose) of each slice, increasing
    position_xy_m: tuple[float, float]  # rough, from odometry and range-from-size: proposals only
    # The camera's (x, y) and the azimuth (rad) of the line of sight of the tracklet's middle slice,
    # from odometry: proposals only. A short tracklet's range from size can be metres off (a blob
    # cut by an edge looks narrow, hence far); its bearing is not.
    sight_line: tuple[float, float, float] | None = None

    def __len__(self) -> int:
        return len(self.measurement_indices)


@dataclass(frozen=True)
class TrackletResult:
    tracklets: tuple[Tracklet, ...]
    dropped_measurements: tuple[int, ...]  # slices of tracklets shorter than min_length
    dropped_tracklets: int

    @property
    def labels(self) -> list[str]:
        return [t.label for t in self.tracklets]

    def measurement_lists(self) -> list[tuple[int, ...]]:
        return [t.measurement_indices for t in self.tracklets]


def estimate_range(measurements: NDArray[np.float64], shape: ClassShape, camera_height_m: float) -> NDArray:
    """(M,) horizontal range (m) from each slice's apparent size, NaN where nothing is usable.

    Width: ``w = 2 asin(r / D)``. Top edge at ``a = z_top - h``: the far rim ``atan2(a,
    D + r)`` when below the camera, the near rim ``atan2(a, D - r)`` above it. Bottom edge
    likewise (near rim below the camera, far rim above). The median of the usable ones.
    """
    r = 0.5 * shape.diameter_m
    width, bottom, top = measurements[:, 1], measurements[:, 2], measurements[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        from_width = r / np.sin(0.5 * np.clip(width, 1e-6, np.pi))
        a = shape.z_base_m + shape.height_m - camera_height_m
        from_top = a / np.tan(top) + (-r if a < 0 else r)
        b = shape.z_base_m - camera_height_m
        from_bottom = b / np.tan(bottom) + (r if b < 0 else -r)
        candidates = np.stack([from_width, from_top, from_bottom], axis=-1)
        # An edge only says something when it is on the expected side of the horizon.
        candidates[:, 1] = np.where(np.sign(top) == np.sign(a), candidates[:, 1], np.nan)
        candidates[:, 2] = np.where(np.sign(bottom) == np.sign(b), candidates[:, 2], np.nan)
    candidates[~np.isfinite(candidates) | (candidates <= r)] = np.nan
    out = np.full(len(measurements), np.nan)
    usable = np.isfinite(candidates).any(axis=1)
    out[usable] = np.nanmedian(candidates[usable], axis=1)
    return out


def _carry(
    meas: NDArray[np.float64],
    range_m: NDArray[np.float64],
    cam_from: NDArray[np.float64],
    cam_to: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(K, 4) slices predicted in camera pose ``cam_to`` of slices ``meas`` seen from ``cam_from``
    at ranges ``range_m`` (K,); camera poses are (K, 3) map_T_camera."""
    azimuth = cam_from[:, 2] + meas[:, 0]
    x = cam_from[:, 0] + range_m * np.cos(azimuth)
    y = cam_from[:, 1] + range_m * np.sin(azimuth)
    dx, dy = x - cam_to[:, 0], y - cam_to[:, 1]
    new_range = np.maximum(np.hypot(dx, dy), 1e-3)
    bearing = wrap_angle(np.arctan2(dy, dx) - cam_to[:, 2])
    # Heights of the two edges above the camera where the earlier rays meet the object.
    z_bottom = range_m * np.tan(meas[:, 2])
    z_top = range_m * np.tan(meas[:, 3])
    sin_half = np.clip(np.sin(0.5 * meas[:, 1]) * range_m / new_range, 0.0, 1.0)
    return np.stack(
        [bearing, 2.0 * np.arcsin(sin_half), np.arctan2(z_bottom, new_range), np.arctan2(z_top, new_range)], axis=-1
    )


def _outside(value: ArrayLike, predicted: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance of ``value`` from the interval spanned by ``predicted`` along axis 0 (0 inside)."""
    return np.maximum(0.0, np.maximum(predicted.min(0) - value, value - predicted.max(0)))


def _innovation_cost(
    observed: NDArray[np.float64], predictions: Sequence[NDArray[np.float64]], gates: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(K,) cost of ``observed`` (K, 4) against the interval spanned by ``predictions`` (each
    (K, 4)), ``_INFEASIBLE`` when a component is farther than its gate (K, 4) from it."""
    stacked = np.stack(predictions)
    # Bearings relative to the observed one (wrapped), so the interval test needs no wrapping.
    relative = stacked.copy()
    relative[:, :, 0] = wrap_angle(stacked[:, :, 0] - observed[None, :, 0])
    reference = observed.copy()
    reference[:, 0] = 0.0
    outside = _outside(reference, relative) / gates
    # Among feasible pairs the one closest to the central prediction wins.
    cost = ((relative[len(predictions) // 2] - reference) / gates) ** 2
    return np.where((outside <= 1.0).all(-1), cost.sum(-1), _INFEASIBLE)


def chain_tracklets(
    measurements: ArrayLike,
    measurement_frame: ArrayLike,
    measurement_label: Sequence[str],
    frame_poses: ArrayLike,
    shapes: Mapping[str, ClassShape],
    mount: CameraMount,
    *,
    config: TrackletConfig | None = None,
    measurement_stddev: ArrayLike | None = None,
) -> TrackletResult:
    """Chain slices into tracklets (see the module docstring).

    ``measurements`` (M, 4): bearing, angular width, elevation bottom, elevation top (rad);
    measurement ``m`` was seen in frame ``measurement_frame[m]`` whose odometry pose
    map_T_base is ``frame_poses[frame]``; ``shapes`` gives each label's nominal geometry.
    ``measurement_stddev`` (M, 4), the slices' noise, widens the gates of noisy components.
    """
    config = config or TrackletConfig()
    meas = np.asarray(measurements, dtype=float).reshape(-1, 4)
    frame_of = np.asarray(measurement_frame, dtype=np.int64).reshape(-1)
    poses = np.asarray(frame_poses, dtype=float).reshape(-1, 3)
    labels = list(measurement_label)
    if not len(meas) == len(frame_of) == len(labels):
        raise ValueError(f"{len(meas)} measurements, {len(frame_of)} frames, {len(labels)} labels")
    noise = np.zeros_like(meas) if measurement_stddev is None else np.asarray(measurement_stddev, float).reshape(-1, 4)
    base_gates = np.array([config.bearing_gate_rad, 0.0, config.elevation_gate_rad, config.elevation_gate_rad])
    cameras = np.array([mount.camera_pose(p) for p in poses]).reshape(-1, 3)
    range_m = np.full(len(meas), np.nan)
    for label in set(labels):
        rows = np.array([lab == label for lab in labels])
        range_m[rows] = estimate_range(meas[rows], shapes[label], mount.height_m)
    range_m = np.clip(np.nan_to_num(range_m, nan=config.max_range_m), config.min_range_m, config.max_range_m)
    travel_m, turn_rad = _odometer(poses)

    chains: list[list[int]] = []  # measurement indices per tracklet
    open_chains: dict[str, list[int]] = {}  # label -> tracklets that may still grow
    order = np.lexsort((np.arange(len(meas)), frame_of))
    frames = np.unique(frame_of)
    spread = (1.0 - config.range_relative_uncertainty, 1.0, 1.0 + config.range_relative_uncertainty)
    for frame in frames:
        in_frame = order[frame_of[order] == frame]
        for label in dict.fromkeys(labels[m] for m in in_frame):
            new = [int(m) for m in in_frame if labels[m] == label]
            candidates = [
                c
                for c in open_chains.get(label, [])
                if _may_bridge(int(frame_of[chains[c][-1]]), int(frame), travel_m, turn_rad, config)
            ]
            taken: set[int] = set()
            if candidates:
                last = np.array([chains[c][-1] for c in candidates])
                # cost[i, j]: tracklet i's last slice carried into the new frame vs new slice j
                ci, nj = np.meshgrid(np.arange(len(candidates)), np.arange(len(new)), indexing="ij")
                src, dst = last[ci.ravel()], np.array(new)[nj.ravel()]
                cam_to = np.repeat(cameras[frame][None, :], len(src), axis=0)
                predictions = [_carry(meas[src], range_m[src] * k, cameras[frame_of[src]], cam_to) for k in spread]
                gates = np.maximum(base_gates, config.gate_sigmas * np.hypot(noise[src], noise[dst]))
                gates[:, 1] = np.maximum(gates[:, 1], config.width_relative_gate * predictions[1][:, 1])
                gates = np.maximum(gates, 1e-9)
                cost = _innovation_cost(meas[dst], predictions, gates).reshape(len(candidates), len(new))
                rows, cols = linear_sum_assignment(cost)
                for i, j in zip(rows, cols, strict=True):
                    if cost[i, j] < _INFEASIBLE:
                        chains[candidates[i]].append(new[j])
                        taken.add(j)
            open_chains[label] = candidates
            for j, m in enumerate(new):
                if j not in taken:
                    chains.append([m])
                    open_chains[label].append(len(chains) - 1)

    kept, dropped = [], []
    for chain in chains:
        if len(chain) >= config.min_length:
            kept.append(chain)
        else:
            dropped.extend(chain)
    tracklets = []
    for chain in sorted(kept, key=lambda c: c[0]):
        idx = np.array(chain)
        azimuth = cameras[frame_of[idx], 2] + meas[idx, 0]
        xy = cameras[frame_of[idx], :2] + range_m[idx, None] * np.column_stack([np.cos(azimuth), np.sin(azimuth)])
        centre = np.median(xy, axis=0)
        middle = idx[len(idx) // 2]
        camera = cameras[frame_of[middle]]
        tracklets.append(
            Tracklet(
                label=labels[chain[0]],
                measurement_indices=tuple(int(m) for m in chain),
                frame_indices=tuple(int(frame_of[m]) for m in chain),
                position_xy_m=(float(centre[0]), float(centre[1])),
                sight_line=(float(camera[0]), float(camera[1]), float(camera[2] + meas[middle, 0])),
            )
        )
    logger.info(
        "chained %d slices into %d tracklets; dropped %d slices in %d tracklets shorter than %d",
        len(meas),
        len(tracklets),
        len(dropped),
        len(chains) - len(kept),
        config.min_length,
    )
    return TrackletResult(tuple(tracklets), tuple(sorted(int(m) for m in dropped)), len(chains) - len(kept))


def _odometer(poses: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Path length (m) and total absolute turn (rad) from the first frame to each frame."""
    step = np.diff(poses, axis=0)
    travel = np.concatenate([[0.0], np.cumsum(np.hypot(step[:, 0], step[:, 1]))])
    turn = np.concatenate([[0.0], np.cumsum(np.abs(wrap_angle(step[:, 2])))])
    return travel, turn


def _may_bridge(last_frame: int, frame: int, travel_m: NDArray, turn_rad: NDArray, config: TrackletConfig) -> bool:
    """Whether a tracklet last seen in ``last_frame`` may continue in ``frame`` (module docstring)."""
    if frame - last_frame <= config.max_frame_gap:
        return True
    return bool(
        travel_m[frame] - travel_m[last_frame] <= config.max_gap_travel_m
        and turn_rad[frame] - turn_rad[last_frame] <= config.max_gap_turn_rad
    )


def class_shapes(problem: GraphProblem) -> dict[str, ClassShape]:
    """Nominal geometry per class from the problem's class priors."""
    return {
        label: ClassShape(z_base_m=float(mean[2]), diameter_m=float(mean[3]), height_m=float(mean[4]))
        for label, mean in zip(problem.labels, problem.prior_mean[: len(problem.labels)], strict=True)
    }


def tracklets_of_problem(problem: GraphProblem, config: TrackletConfig | None = None) -> TrackletResult:
    """Tracklets of a factor-graph problem's measurements, with its odometry poses."""
    return chain_tracklets(
        problem.measurements,
        problem.measurement_pose,
        [problem.labels[k] for k in problem.measurement_label],
        problem.odometry_poses,
        class_shapes(problem),
        problem.mount,
        config=config,
        measurement_stddev=problem.measurement_stddev,
    )
