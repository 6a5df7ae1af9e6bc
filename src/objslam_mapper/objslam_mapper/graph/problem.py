"""The fixed part of the factor graph: poses, odometry factors, measurements, class priors.

:func:`build_problem` turns odometry samples and per-image slices into an immutable
:class:`GraphProblem`, built once per map and shared by every solve of the association
sampler (:func:`objslam_mapper.graph.solver.solve`). It holds

- one robot pose per image inside the odometry span (sorted by stamp), initialized from
  interpolated odometry, with odometry factors between consecutive poses and a tight
  prior on the first pose (which fixes the map frame to ``odom``);
- every slice of those images under a **global measurement index** ``m`` (pose order,
  i.e. images by stamp, then slice order): ``measurements[m]`` = (bearing, angular width, elevation bottom,
  elevation top), its noise, the pose it was seen from, its class; ``measurement_image``
  and ``measurement_slot`` lead back to the input ``images[i].slices[k]``. Slices of
  low confidence (likely cut short) get inflated noise; the edges the view cut off
  (the detector's ``cut_edges``, and upper edges of low confidence at the top of the
  camera's view, :func:`at_view_top`) are bounds on the object's, not measurements
  (``measurement_bounds``, :func:`objslam_mapper.model.slice_model.bounds_of_cuts` and
  :func:`~objslam_mapper.model.slice_model.censor`);
  ``measurement_outlier_cost`` is
  where each slice's cost stops growing (:mod:`objslam_mapper.model.outliers`);
- when ``odometry.calibration.enabled``, the zero-mean prior of the odometry calibration
  ``c = (distance_scale, turn_scale, turn_bias_rad_per_m)`` (one variable per map, see
  :mod:`objslam_mapper.graph.linearize`) and each increment's measured path length, which
  the turn bias multiplies;
- the class priors (paper eqs. 7-8) as per-class means and standard deviations of the
  object vector ``(x, y, z_base, diameter, height)``: ``x, y`` weak around the first
  pose (``xy_stddev_m``), ``z_base`` and the size from the catalog. They are the first
  ``len(labels)`` *prior rows*; a group of a solve takes its class's row unless told
  otherwise, and :func:`with_extra_priors` appends rows for things that are not objects
  of a class (the sampler's static distractors). Beside each row's stddev, the spread of
  real instances about its mean (``prior_spread``), which the error covariance counts: the
  same but for a floor object's base height, whose prior is slack for the MAP (it stands
  on the floor: ``solver.error_covariance.floor_z_base_spread_m``). An appended row may
  also keep its thing's base above the floor (``prior_floor_stddev``,
  :mod:`objslam_mapper.model.floor`); class rows need not, their base height is tight;
- the log-normalizers ``-0.5 log|2 pi Sigma|`` of every Gaussian factor, for the evidence.

Slices whose class is not in the catalog, and images outside the odometry span, are left
out and counted (``rejected_slice_count``, ``rejected_image_count``).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from objslam_common.catalog import Catalog, ObjectClass
from objslam_common.mount import CameraMount, CameraMounts
from objslam_common.records import ImageSlices, OdometrySample
from objslam_mapper.config import GraphConfig, OdometryNoiseConfig, SliceNoiseConfig, SolverConfig
from objslam_mapper.errors import MapperError
from objslam_mapper.model.floor import NO_FLOOR, floor_log_mass
from objslam_mapper.model.odometry import TrajectoryError, increment_stddev, odometry_increments, poses_at_stamps
from objslam_mapper.model.outliers import inlier_log_weight, outlier_cost
from objslam_mapper.model.slice_model import BEARING, ELEVATION_BOTTOM, ELEVATION_TOP, bounds_of_cuts

logger = logging.getLogger(__name__)

OBJECT_DIM = 5  # x, y, z_base, diameter, height
POSE_DIM = 3
CALIBRATION_DIM = 3  # distance scale, turn scale, turn bias per metre
LOG_2PI = float(np.log(2.0 * np.pi))


class GraphError(MapperError, ValueError):
    """Inputs that do not make a factor graph (bad groups, no usable poses)."""


def read_only(array: NDArray) -> NDArray:
    """A contiguous, read-only view of ``array`` (every array of a problem is one)."""
    array = np.ascontiguousarray(array)
    array.flags.writeable = False
    return array


def gaussian_log_normalizer(stddev: NDArray[np.float64]) -> NDArray[np.float64]:
    """-0.5 log|2 pi Sigma| of diagonal Gaussians, summed over the last axis."""
    return -0.5 * np.sum(LOG_2PI + 2.0 * np.log(stddev), axis=-1)


@dataclass(frozen=True, eq=False)
class GraphProblem:
    """Immutable inputs of every solve (arrays are read-only). See the module docstring."""

    mount: CameraMount
    solver: SolverConfig
    labels: tuple[str, ...]  # class labels; measurement_label and priors index into it
    # Poses (N)
    stamps_ns: NDArray[np.int64]
    pose_image: NDArray[np.int64]  # index of each pose's ImageSlices in the input
    odometry_poses: NDArray[np.float64]  # (N, 3) initial map_T_base, from odometry
    increments: NDArray[np.float64]  # (N-1, 3) odometry between consecutive poses
    increment_stddev: NDArray[np.float64]  # (N-1, 3)
    first_pose_stddev: NDArray[np.float64]  # (3,)
    increment_path_length_m: NDArray[np.float64]  # (N-1,) odometry path length of each increment
    calibration_prior_stddev: NDArray[np.float64]  # (C,): (3,) when the calibration is estimated, else (0,)
    # Measurements (M)
    measurements: NDArray[np.float64]  # (M, 4) bearing, width, elevation bottom, top (rad)
    measurement_stddev: NDArray[np.float64]  # (M, 4)
    measurement_pose: NDArray[np.int64]
    measurement_label: NDArray[np.int64]
    measurement_confidence: NDArray[np.float64]
    measurement_bounds: NDArray[np.int8]  # (M, 4) components that are bounds, not measurements (slice_model.censor)
    measurement_image: NDArray[np.int64]
    measurement_slot: NDArray[np.int64]
    # Prior rows (P >= L): row k < L is class k's prior
    prior_mean: NDArray[np.float64]  # (P, 5)
    prior_stddev: NDArray[np.float64]  # (P, 5)
    # (P, 5) stddev of real instances about prior_mean, what the error covariance counts:
    # prior_stddev but where the model's prior is slack on purpose (a floor object's base height)
    prior_spread: NDArray[np.float64]
    # Log-normalizers of the Gaussian factors
    trajectory_log_normalizer: float  # odometry factors + first-pose prior + calibration prior
    measurement_log_normalizer: NDArray[np.float64]  # (M,) Gaussian normalizer + log(1 - outlier probability)
    measurement_outlier_cost: NDArray[np.float64]  # (M,) cap of a slice's half chi-square (inf: none)
    prior_log_normalizer: NDArray[np.float64]  # (P,) per prior row, its floor factor's renormalisation included
    # (P,) stddev of the row's floor factor on z_base (objslam_mapper.model.floor; inf: none)
    prior_floor_stddev: NDArray[np.float64]
    rejected_image_count: int = 0
    rejected_slice_count: int = 0
    # Per-measurement camera mounts relative to measurement_pose; None: ``mount`` for all
    # (the image problem). A keyframe graph's slices of other images have their own.
    measurement_mount: CameraMounts | None = None
    # The odometry noise model the increments' stddevs come from (keyframes compose them).
    odometry_noise: OdometryNoiseConfig = OdometryNoiseConfig()

    @property
    def pose_count(self) -> int:
        return len(self.stamps_ns)

    @property
    def calibration_dim(self) -> int:
        """3 when the odometry calibration is a variable of the graph, else 0."""
        return len(self.calibration_prior_stddev)

    @property
    def measurement_count(self) -> int:
        return len(self.measurements)

    def label_of(self, measurement: int) -> str:
        return self.labels[int(self.measurement_label[measurement])]

    def mounts(self, measurements: NDArray[np.int64]) -> CameraMount | CameraMounts:
        """The camera mounts of ``measurements`` relative to their poses (for the slice model)."""
        return self.mount if self.measurement_mount is None else self.measurement_mount.take(measurements)


def with_extra_priors(
    problem: GraphProblem, mean: NDArray[np.float64], stddev: NDArray[np.float64], floor_stddev_m: float = NO_FLOOR
) -> tuple[GraphProblem, int]:
    """``problem`` with prior rows ``mean``, ``stddev`` (R, 5) appended, and the index of the first;
    with a floor factor of stddev ``floor_stddev_m`` on their base height (default none)."""
    first = len(problem.prior_mean)
    extra_mean = np.asarray(mean, dtype=float).reshape(-1, OBJECT_DIM)
    extra = np.asarray(stddev, dtype=float).reshape(-1, OBJECT_DIM)
    extra_floor = np.full(len(extra), float(floor_stddev_m))
    extended = dataclasses.replace(
        problem,
        prior_mean=read_only(np.concatenate([problem.prior_mean, extra_mean])),
        prior_stddev=read_only(np.concatenate([problem.prior_stddev, extra])),
        prior_spread=read_only(np.concatenate([problem.prior_spread, extra])),
        prior_log_normalizer=read_only(
            np.concatenate([problem.prior_log_normalizer, prior_log_normalizer(extra_mean, extra, extra_floor)])
        ),
        prior_floor_stddev=read_only(np.concatenate([problem.prior_floor_stddev, extra_floor])),
    )
    return extended, first


def prior_log_normalizer(
    mean: NDArray[np.float64], stddev: NDArray[np.float64], floor_stddev_m: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(R,) log-normalizers of prior rows: Gaussian, less the log mass their floor factors leave."""
    floor = [floor_log_mass(m[2], s[2], f) for m, s, f in zip(mean, stddev, floor_stddev_m, strict=True)]
    return gaussian_log_normalizer(stddev) - np.array(floor, dtype=float)


def class_measurement_stddev(cls: ObjectClass, noise: SliceNoiseConfig, mount: CameraMount) -> NDArray[np.float64]:
    stddev = np.array(
        [
            noise.bearing_stddev_rad,
            noise.angular_width_stddev_rad,
            noise.elevation_bottom_stddev_rad,
            noise.elevation_top_stddev_rad,
        ]
    )
    if not cls.on_floor and cls.z_base_m > mount.height_m:
        stddev[ELEVATION_BOTTOM] = noise.raised_elevation_bottom_stddev_rad
    return stddev


# Bearing bins of the view's top: where the image's border cuts the view (the corners of a
# square image, if they are not masked) its top varies with azimuth, by up to about 8 mrad per
# degree on the bundled camera; within a 5 degree bin the upper edges of cut blobs pile up
# near the bin's highest. A pile of at least this many tells the view's edge from one tall
# object's top seen once.
_VIEW_TOP_BINS = 72
_VIEW_TOP_PILE = 3


def at_view_top(measurements: NDArray[np.float64], tolerance_rad: float) -> NDArray[np.bool_]:
    """(M,) whether each slice's upper edge lies at the top of the view: within
    ``tolerance_rad`` of the highest upper edge at its bearing (of ``_VIEW_TOP_BINS``
    bins), where at least ``_VIEW_TOP_PILE`` upper edges lie that close to their bins'
    highest (in the bin and its two neighbours)."""
    measurements = np.asarray(measurements, dtype=float).reshape(-1, 4)
    top = measurements[:, ELEVATION_TOP]
    bins = np.floor((measurements[:, BEARING] + np.pi) / (2.0 * np.pi) * _VIEW_TOP_BINS).astype(np.int64)
    bins %= _VIEW_TOP_BINS
    highest = np.full(_VIEW_TOP_BINS, -np.inf)
    np.maximum.at(highest, bins, top)
    near = top >= highest[bins] - tolerance_rad
    count = np.bincount(bins[near], minlength=_VIEW_TOP_BINS)
    pile = count + np.roll(count, 1) + np.roll(count, -1)  # a pile may straddle two bins
    return near & (pile[bins] >= _VIEW_TOP_PILE)


def build_problem(
    odometry: Sequence[OdometrySample],
    images: Sequence[ImageSlices],
    mount: CameraMount,
    catalog: Catalog,
    config: GraphConfig | None = None,
) -> GraphProblem:
    """The factor-graph problem of one run (see the module docstring)."""
    config = config or GraphConfig()
    if not images:
        raise GraphError("no images: nothing to map")
    order = np.argsort(np.array([im.stamp_ns for im in images], dtype=np.int64), kind="stable")
    stamps = np.array([images[i].stamp_ns for i in order], dtype=np.int64)
    try:
        at = poses_at_stamps(odometry, stamps)
    except TrajectoryError as exc:
        raise GraphError(f"cannot place the robot: {exc}") from exc
    if not at.accepted.any():
        raise GraphError(f"none of the {len(images)} image stamps lies within the odometry span")
    pose_image = order[at.accepted]
    poses = at.poses
    increments = odometry_increments(poses)
    inc_stddev = increment_stddev(np.diff(at.path_length_m), np.diff(at.turn_rad), config.odometry)
    first_stddev = np.array(
        [
            config.odometry.first_pose_stddev_m,
            config.odometry.first_pose_stddev_m,
            config.odometry.first_pose_stddev_rad,
        ]
    )

    classes = tuple(catalog)
    label_index = {cls.label: k for k, cls in enumerate(classes)}
    class_stddev = [class_measurement_stddev(cls, config.slice_noise, mount) for cls in classes]
    rows, stddev, pose_of, label_of, confidence, image_of, slot_of, cuts = [], [], [], [], [], [], [], []
    rejected_slices = 0
    for pose_index, image_index in enumerate(pose_image):
        for slot, sl in enumerate(images[image_index].slices):
            k = label_index.get(sl.label)
            if k is None:
                rejected_slices += 1
                continue
            rows.append((sl.bearing_rad, sl.angular_width_rad, sl.elevation_bottom_rad, sl.elevation_top_rad))
            truncated = sl.confidence <= config.slice_noise.low_confidence
            stddev.append(class_stddev[k] * (config.slice_noise.low_confidence_stddev_scale if truncated else 1.0))
            pose_of.append(pose_index)
            label_of.append(k)
            confidence.append(sl.confidence)
            image_of.append(image_index)
            slot_of.append(slot)
            cuts.append(sl.cut_edges)
    if rejected_slices:
        logger.warning("%d slices of classes not in the catalog were left out", rejected_slices)
    measurements = np.array(rows, dtype=float).reshape(-1, 4)
    meas_stddev = np.array(stddev, dtype=float).reshape(-1, 4)
    censored = np.zeros(len(measurements), dtype=bool)
    if config.slice_noise.censor_view_top:
        low_confidence = np.array(confidence, dtype=float) <= config.slice_noise.low_confidence
        censored = low_confidence & at_view_top(measurements, config.slice_noise.view_top_tolerance_rad)
    if censored.any():
        logger.info("%d slices reach the top of the view: their upper edges are lower bounds", int(censored.sum()))
    bounds = bounds_of_cuts(np.array(cuts, dtype=np.int64), censored)
    if np.any(bounds[:, :ELEVATION_TOP]):
        logger.info(
            "%d slices cut by the view at a side or the bottom: those edges are bounds",
            int(np.any(bounds[:, :ELEVATION_TOP], axis=1).sum()),
        )
    gaussian_norm = gaussian_log_normalizer(meas_stddev)
    noise = config.slice_noise

    first_xy = poses[0, :2]
    prior_mean = np.array([[first_xy[0], first_xy[1], c.z_base_m, c.diameter_m, c.height_m] for c in classes])
    prior_stddev = np.array(
        [[c.xy_stddev_m, c.xy_stddev_m, c.z_base_stddev_m, c.diameter_stddev_m, c.height_stddev_m] for c in classes]
    )
    class_floor = np.full(len(classes), NO_FLOOR)  # a class's base height prior is tight: no floor factor
    prior_spread = prior_stddev.copy()
    on_floor = np.array([c.on_floor for c in classes], dtype=bool)
    prior_spread[on_floor, 2] = config.solver.error_covariance.floor_z_base_spread_m
    calibration = config.odometry.calibration
    calib_stddev = np.array(calibration.prior_stddev() if calibration.enabled else (), dtype=float)
    trajectory_norm = float(np.sum(gaussian_log_normalizer(inc_stddev)) + gaussian_log_normalizer(first_stddev))
    if calibration.enabled:
        trajectory_norm += float(gaussian_log_normalizer(calib_stddev))
    problem = GraphProblem(
        mount=mount,
        solver=config.solver,
        labels=tuple(c.label for c in classes),
        stamps_ns=read_only(stamps[at.accepted]),
        pose_image=read_only(pose_image.astype(np.int64)),
        odometry_poses=read_only(poses),
        increments=read_only(increments),
        increment_stddev=read_only(inc_stddev),
        first_pose_stddev=read_only(first_stddev),
        increment_path_length_m=read_only(np.abs(np.diff(at.path_length_m))),
        calibration_prior_stddev=read_only(calib_stddev),
        measurements=read_only(measurements),
        measurement_stddev=read_only(meas_stddev),
        measurement_pose=read_only(np.array(pose_of, dtype=np.int64)),
        measurement_label=read_only(np.array(label_of, dtype=np.int64)),
        measurement_confidence=read_only(np.array(confidence, dtype=float)),
        measurement_bounds=read_only(bounds),
        measurement_image=read_only(np.array(image_of, dtype=np.int64)),
        measurement_slot=read_only(np.array(slot_of, dtype=np.int64)),
        prior_mean=read_only(prior_mean.reshape(-1, OBJECT_DIM)),
        prior_stddev=read_only(prior_stddev.reshape(-1, OBJECT_DIM)),
        prior_spread=read_only(prior_spread.reshape(-1, OBJECT_DIM)),
        trajectory_log_normalizer=trajectory_norm,
        measurement_log_normalizer=read_only(gaussian_norm + inlier_log_weight(noise.outlier_probability)),
        measurement_outlier_cost=read_only(
            outlier_cost(gaussian_norm, noise.outlier_probability, noise.outlier_volume_rad4)
        ),
        prior_log_normalizer=read_only(
            prior_log_normalizer(prior_mean.reshape(-1, OBJECT_DIM), prior_stddev.reshape(-1, OBJECT_DIM), class_floor)
        ),
        prior_floor_stddev=read_only(class_floor),
        rejected_image_count=at.rejected_count,
        rejected_slice_count=rejected_slices,
        odometry_noise=config.odometry,
    )
    logger.info(
        "factor graph: %d poses, %d measurements of %d classes (%d images, %d slices left out)",
        problem.pose_count,
        problem.measurement_count,
        len(classes),
        problem.rejected_image_count,
        problem.rejected_slice_count,
    )
    return problem
