r"""Keyframes: the factor graph's robot poses, one per stretch of path instead of one per image.

A known-association solve costs time linear in the number of graph poses (the objects'
Schur complement is a product over the pose band, :mod:`objslam_mapper.graph.linearize`),
and the association sampler solves hundreds of associations. With one pose per image the
cost of a map grows with the frame rate, though a camera that takes twice the images of the
same path sees the same world. So the graph has one pose per *keyframe*: the first image,
then every image once the odometry has travelled ``solver.keyframes.min_travel_m`` or
turned ``min_turn_rad`` since the last keyframe. Every image keeps its stamp and its pose in
every output: an image's pose is its keyframe's composed with the odometry from the keyframe
to it, ``keyframe_T_pose``, and its slices are predicted from the keyframe's pose through
that offset (:class:`objslam_common.mount.CameraMounts`).

The offset is odometry, not truth: taking it as exact would make a slice seen 4 cm after
its keyframe as certain as one seen from it. The model's own noise of the odometry over
the offset (the random walk of :mod:`objslam_mapper.model.odometry` for the offset's path and
turn) is added to that slice's noise, to first order: the heading error turns the
bearing; the position error (isotropic) moves the camera, by ``D`` the horizontal range
guessed from the slice's width and its class's prior diameter: sideways it turns the bearing
by ``1/D`` per metre, along the line of sight it changes the width and the elevations by
their derivatives in ``D``. The ``k`` slices of one image share its offset's error; taken
as independent they would know that error ``k`` times better than it is known (on
simulated runs at two to three images per keyframe the objects' NEES tripled and their
error grew by 70 %), so each takes ``k`` times the added variance: together they weigh the shared
error as one slice would, and the maps match those of a pose per image
(``tests/objslam_mapper/graph/test_keyframes.py``). The odometry factors join consecutive
keyframes with the composed increments, their noise the model's for the path and turn
between them. (Both take the noise model's floor, ``odometry.min_*_stddev``, once per
interval, as the odometry of the interval itself would: summed over the increments of a
robot standing still it claims a drift that grows with the number of images, 1 cm and
0.6 deg after 25, and on the ``clutter`` bag it made the bearing stddev of slices taken
from one spot up to 7 times their own.)

Keyframes are used only when they remove at least ``min_reduction`` of the poses. At the
rate of the bundled bags (about 8 cm between images) they would only join the few images
taken while the robot stands, for a gain of a percent or two; there one pose per image is
kept, as the paper has it. (Even that small change moved the chain on the ``clutter`` bag
to a state its target prefers by 156 nats, with or without keyframes, that has a floor
patch as an object: a fault of the missed-detection term, see docs/method.md, which the chain
had not found before.)

:func:`keyframes_of` gives the :class:`KeyframeGraph` of a problem (built once per problem).
Where every image is a keyframe (or keyframes are off or not worth it) its problem is
the image problem itself, so nothing changes.
"""

from __future__ import annotations

import dataclasses
import weakref
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.geometry import between_rows, compose_rows
from objslam_common.mount import CameraMounts
from objslam_mapper.config import KeyframeConfig
from objslam_mapper.graph.problem import GraphProblem, gaussian_log_normalizer, read_only
from objslam_mapper.model.odometry import increment_stddev as increment_stddev_of
from objslam_mapper.model.odometry import odometry_increments
from objslam_mapper.model.slice_model import BEARING, ELEVATION_BOTTOM, ELEVATION_TOP, WIDTH

# Range guesses below this (m) are taken as this: a slice wider than its class allows
# would otherwise claim the camera is nearly touching the object.
_MIN_RANGE_M = 0.2


def select_keyframes(path_length_m: ArrayLike, turn_rad: ArrayLike, config: KeyframeConfig) -> NDArray[np.int64]:
    """Indices of the keyframe poses, given each increment's (N-1,) path length and turn.

    Pose 0 is one (it carries the map's anchor); pose i > 0 is one once the travel or the
    turn summed since the last keyframe reaches the threshold.
    """
    travel = np.abs(np.asarray(path_length_m, dtype=float))
    turn = np.abs(np.asarray(turn_rad, dtype=float))
    if not config.enabled:
        return np.arange(len(travel) + 1, dtype=np.int64)
    keyframes = [0]
    since_travel = since_turn = 0.0
    for i, (ds, dt) in enumerate(zip(travel, turn, strict=True), start=1):
        since_travel += ds
        since_turn += dt
        if since_travel >= config.min_travel_m or since_turn >= config.min_turn_rad:
            keyframes.append(i)
            since_travel = since_turn = 0.0
    return np.array(keyframes, dtype=np.int64)


@dataclass(frozen=True, eq=False)
class KeyframeGraph:
    """The graph of an image problem: ``problem`` has one pose per keyframe (module docstring).

    ``keyframe_pose`` (K,) is each keyframe's pose in the image problem, ``pose_keyframe`` (N,)
    each image pose's keyframe, ``keyframe_T_pose`` (N, 3) the odometry from it.
    """

    problem: GraphProblem
    keyframe_pose: NDArray[np.int64]
    pose_keyframe: NDArray[np.int64]
    keyframe_T_pose: NDArray[np.float64]

    @property
    def reduces(self) -> bool:
        """Whether some images share a keyframe (else the graph is the image problem)."""
        return len(self.keyframe_pose) < len(self.pose_keyframe)

    @property
    def images_per_keyframe(self) -> NDArray[np.float64]:
        """(K,) how many image poses each graph pose stands for (weights of a fit to the images' trajectory)."""
        return np.bincount(self.pose_keyframe, minlength=len(self.keyframe_pose)).astype(float)

    def restrict(self, map_T_base: ArrayLike) -> NDArray[np.float64]:
        """(K, 3) keyframe poses of (N, 3) image poses."""
        return np.array(np.asarray(map_T_base, dtype=float)[self.keyframe_pose])

    def expand(self, map_T_keyframe: ArrayLike) -> NDArray[np.float64]:
        """(N, 3) image poses of (K, 3) keyframe poses."""
        keyframe = np.asarray(map_T_keyframe, dtype=float)
        if not self.reduces:
            return np.array(keyframe)
        return compose_rows(keyframe[self.pose_keyframe], self.keyframe_T_pose)


def _range_guess(problem: GraphProblem, radius_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M,) horizontal range of each slice's object axis, from its width and the radius ``radius_m``."""
    half_width = np.clip(0.5 * problem.measurements[:, WIDTH], 1e-4, 0.5 * np.pi - 1e-3)
    return np.maximum(radius_m / np.sin(half_width), np.maximum(1.05 * radius_m, _MIN_RANGE_M))


def offset_slice_variance(
    measurements: NDArray[np.float64],
    range_m: NDArray[np.float64],
    radius_m: NDArray[np.float64],
    xy_var: NDArray[np.float64],
    theta_var: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(M, 4) variance that camera position noise ``xy_var`` (per axis, m^2) and heading noise
    ``theta_var`` (rad^2) add to slices of objects of radius ``radius_m`` at range ``range_m``.

    First order in the slice model (:mod:`objslam_mapper.model.slice_model`): sideways motion and
    the heading turn the bearing; motion along the line of sight changes the width and the
    elevations (each edge is on its rim's near or far side, from the edge's sign).
    """
    half_width = 0.5 * measurements[:, WIDTH]
    added = np.empty_like(measurements)
    added[:, BEARING] = theta_var + xy_var / range_m**2
    added[:, WIDTH] = (2.0 * np.tan(half_width) / range_m) ** 2 * xy_var
    for comp, near in (
        (ELEVATION_BOTTOM, measurements[:, ELEVATION_BOTTOM] < 0.0),
        (ELEVATION_TOP, measurements[:, ELEVATION_TOP] > 0.0),
    ):
        e = measurements[:, comp]
        rim_range = np.maximum(range_m + np.where(near, -radius_m, radius_m), _MIN_RANGE_M)
        added[:, comp] = (np.sin(e) * np.cos(e) / rim_range) ** 2 * xy_var
    return added


def keyframe_graph(problem: GraphProblem, config: KeyframeConfig) -> KeyframeGraph:
    """The :class:`KeyframeGraph` of an image-level ``problem``."""
    n = problem.pose_count
    keyframes = select_keyframes(problem.increment_path_length_m, problem.increments[:, 2], config)
    pose_keyframe = np.searchsorted(keyframes, np.arange(n), side="right") - 1
    if len(keyframes) > (1.0 - config.min_reduction) * n:
        every = np.arange(n, dtype=np.int64)
        return KeyframeGraph(problem, every, every, np.zeros((n, 3)))

    odometry = np.asarray(problem.odometry_poses)
    keyframe_T_pose = between_rows(odometry[keyframes[pose_keyframe]], odometry)
    path = np.concatenate([[0.0], np.cumsum(problem.increment_path_length_m)])
    swept = np.concatenate([[0.0], np.cumsum(np.abs(problem.increments[:, 2]))])
    noise = problem.odometry_noise
    increment_stddev = increment_stddev_of(np.diff(path[keyframes]), np.diff(swept[keyframes]), noise)
    since = keyframes[pose_keyframe]
    offset_var = increment_stddev_of(path - path[since], swept - swept[since], noise) ** 2  # (N, 3)
    offset_var[keyframes] = 0.0

    at = problem.measurement_pose
    radius = 0.5 * problem.prior_mean[problem.measurement_label, 3]  # the class's prior diameter
    added = offset_slice_variance(
        problem.measurements, _range_guess(problem, radius), radius, offset_var[at, 0], offset_var[at, 2]
    )
    # The slices of one image share its offset's error: counted as independent, k of them
    # would know it k times better than it is known. Each takes k times the variance, so
    # together they weigh that error as one slice would (tested against a pose per image).
    per_image = np.bincount(at, minlength=n)[at]
    stddev = np.sqrt(problem.measurement_stddev**2 + per_image[:, None] * added)
    normalizer_change = gaussian_log_normalizer(stddev) - gaussian_log_normalizer(problem.measurement_stddev)
    trajectory_change = float(
        np.sum(gaussian_log_normalizer(increment_stddev)) - np.sum(gaussian_log_normalizer(problem.increment_stddev))
    )
    graph = dataclasses.replace(
        problem,
        solver=dataclasses.replace(problem.solver, keyframes=dataclasses.replace(config, enabled=False)),
        stamps_ns=read_only(problem.stamps_ns[keyframes]),
        pose_image=read_only(problem.pose_image[keyframes]),
        odometry_poses=read_only(odometry[keyframes]),
        increments=read_only(odometry_increments(odometry[keyframes])),
        increment_stddev=read_only(increment_stddev),
        increment_path_length_m=read_only(np.diff(path[keyframes])),
        trajectory_log_normalizer=problem.trajectory_log_normalizer + trajectory_change,
        measurement_pose=read_only(pose_keyframe[at]),
        measurement_mount=CameraMounts.behind(problem.mount, keyframe_T_pose[at]),
        measurement_stddev=read_only(stddev),
        measurement_log_normalizer=read_only(problem.measurement_log_normalizer + normalizer_change),
        measurement_outlier_cost=read_only(problem.measurement_outlier_cost + normalizer_change),
    )
    return KeyframeGraph(graph, keyframes, pose_keyframe, read_only(keyframe_T_pose))


_GRAPHS: weakref.WeakKeyDictionary[GraphProblem, KeyframeGraph] = weakref.WeakKeyDictionary()


def keyframes_of(problem: GraphProblem) -> KeyframeGraph:
    """The graph the solvers work on: ``problem``'s :class:`KeyframeGraph` under its own
    ``solver.keyframes`` settings, built on first use and kept as long as the problem."""
    graph = _GRAPHS.get(problem)
    if graph is None:
        graph = _GRAPHS[problem] = keyframe_graph(problem, problem.solver.keyframes)
    return graph
