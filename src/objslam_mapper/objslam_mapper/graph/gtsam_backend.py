r"""The known-association model as a GTSAM factor graph, solved by GTSAM (docs/method.md, "The model").

Same model, same answers as :func:`objslam_mapper.graph.solver.solve` (the fast numpy backend):
the same variables, residuals, whitening, initialization, Laplace evidence and object
marginals, so either backend can serve the association sampler
(:func:`objslam_mapper.graph.backends.solve_with_backend` picks one by ``solver.backend``).

Graph (:func:`build_gtsam_graph`)
    ``Pose2`` variables ``x<i>`` (one per image pose) and ``Vector5`` object variables
    ``o<j>`` = (x, y, z_base, diameter, height), one per group, and when the problem
    estimates it the ``Vector3`` odometry calibration ``c0`` = (distance scale, turn scale,
    turn bias per metre). Factors:

    - the first-pose prior and the odometry factors, with the residuals of the fast
      solver (``(R_i^T (t_j - t_i) - u_xy, wrap(theta_j - theta_i - u_theta))``, whitened
      per component; with the calibration ``((1 + s_d) R_i^T (t_j - t_i) - u_xy,
      wrap((1 + s_t) wrap(theta_j - theta_i) + b L - u_theta))``, each odometry factor then
      also keyed on ``c0``, which has a zero-mean ``PriorFactorVector``). GTSAM's
      ``BetweenFactorPose2``/``PriorFactorPose2`` would differ: this wheel's Pose2 chart
      is the exponential map, so their error is ``Logmap(u^-1 x_i^-1 x_j)``, another model.
      They are therefore custom factors too;
    - the class priors as ``PriorFactorVector`` with diagonal sigmas (built-in, C++), and
      a distractor's one-sided floor factor on its base height (:mod:`objslam_mapper.model.floor`)
      as a one-row custom factor;
    - the slice factors (:mod:`slice_model`), with its analytic Jacobians composed with the
      Pose2 chart: a GTSAM tangent vector ``v`` of a pose moves it by
      ``(R(theta) v_xy, v_theta)`` in map coordinates at ``v = 0``; an outlier slice
      (:mod:`objslam_mapper.model.outliers`) returns its residual scaled to the capped cost and
      zero Jacobians, so GTSAM sees the same truncated cost and information.

    Two granularities. ``per_detection=True`` is the naive graph: one ``CustomFactor`` per
    detection and per odometry increment (thousands of Python calls per linearization).
    ``per_detection=False`` stacks residuals in numpy: one factor per object group and
    window of ``window_poses`` consecutive poses (the group's detections from those poses;
    keys: the distinct poses + the object), and one factor per window of odometry
    increments. A GTSAM factor's Jacobian blocks are dense, so a factor over all the poses
    of a long-seen object (``window_poses=None``: literally one factor per group) ties
    hundreds of poses into one dense clique; windows keep the cliques small and aligned
    (every group's factor of a window shares its poses), at a few Python calls per window.

Solve (:func:`solve_gtsam`)
    ``drive="python"`` runs the fast solver's Gauss-Newton / Levenberg-Marquardt loop
    (same damping rule, tolerances and convergence test) with GTSAM doing the work:
    ``graph.linearize(values)``, multifrontal elimination, ``values.retract(delta)``. GTSAM's own
    ``LevenbergMarquardtOptimizer`` (``drive="optimizer"``) is slower with custom factors
    (their cost inside its loop grows with the graph). Either way the evidence is the Laplace
    formula of :mod:`solver` with ``log|Lambda| = 2 log|R|`` from GTSAM's elimination, and
    object covariances are ``gtsam.Marginals`` blocks.

A step into a state where the model is undefined (a camera inside an object's cylinder)
evaluates to a huge error, so both drives reject it.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.geometry import wrap_angle
from objslam_mapper.config import SolverConfig
from objslam_mapper.errors import MapperError
from objslam_mapper.graph.gauge import GAUGE_DIM, about_trajectory, trajectory_gauge
from objslam_mapper.graph.initialization import initial_object
from objslam_mapper.graph.keyframes import keyframes_of
from objslam_mapper.graph.layout import Layout, graph_log_normalizer, layout_of
from objslam_mapper.graph.linearize import AssociationSystem, cap_schedule, count_outliers
from objslam_mapper.graph.problem import LOG_2PI, OBJECT_DIM, POSE_DIM, GraphProblem
from objslam_mapper.graph.solver import (
    LOST_INFORMATION_SHARE,
    NOT_STARTED,
    GraphSolution,
    SolutionCovariances,
    SolveOutcome,
    initial_calibration,
    initial_state,
    make_solution,
    object_error_covariance,
)
from objslam_mapper.model.floor import floor_jacobian, floor_residual
from objslam_mapper.model.outliers import truncate
from objslam_mapper.model.slice_model import predict_reduced, whitened_slice_error

logger = logging.getLogger(__name__)

Drive = Literal["optimizer", "python"]
DRIVES: tuple[str, ...] = ("optimizer", "python")
# Python calls per linearization against elimination cost; a cold office_run solve (400
# poses, 12 objects) took 1.6 s / 1.0 / 0.7 / 0.9 / 1.9 s with windows of 4 / 8 / 16 / 32 / 64
# poses, 40 s with one factor per group.
DEFAULT_WINDOW_POSES = 16
# Whitened residual of a slice where the model is undefined (camera inside the cylinder):
# large enough that no optimizer accepts a step there, finite so GTSAM's bookkeeping holds.
_INVALID_RESIDUAL = 1e6
# A slice factor's 8 variables enter through slice_model's 6 reduced columns (delta_x,
# delta_y, theta, z_base, d, H): pose x, y as -delta, object x, y as +delta.
_POSE_SIGN = np.array([-1.0, -1.0, 1.0])
_OBJECT_COLUMNS = np.array([0, 1, 3, 4, 5])


class GtsamBackendError(MapperError, ValueError):
    """A request the GTSAM backend cannot serve (unknown drive, bad window)."""


@dataclass(frozen=True)
class GtsamKeys:
    """Keys of a graph's variables: Pose2 ``x<i>`` per pose, Vector5 ``o<j>`` per group, Vector3 ``c0``."""

    pose_count: int
    object_count: int
    calibration_dim: int = 0  # 3: the odometry calibration c0 is a variable

    @staticmethod
    def calibration() -> int:
        return gtsam.symbol("c", 0)

    @staticmethod
    def pose(i: int) -> int:
        return gtsam.symbol("x", int(i))

    @staticmethod
    def object(j: int) -> int:
        return gtsam.symbol("o", int(j))

    @property
    def pose_keys(self) -> list[int]:
        return [self.pose(i) for i in range(self.pose_count)]

    @property
    def object_keys(self) -> list[int]:
        return [self.object(j) for j in range(self.object_count)]

    def to_values(
        self, map_T_base: ArrayLike, objects: ArrayLike, calibration: ArrayLike | None = None
    ) -> gtsam.Values:
        """Values of (N, 3) poses (x, y, theta), (K, 5) objects and the calibration (zero if None)."""
        values = gtsam.Values()
        if self.calibration_dim:
            calib = np.zeros(self.calibration_dim) if calibration is None else np.asarray(calibration, dtype=float)
            values.insert(self.calibration(), np.array(calib))
        for i, (x, y, theta) in enumerate(np.asarray(map_T_base, dtype=float)):
            values.insert(self.pose(i), gtsam.Pose2(x, y, theta))
        for j, obj in enumerate(np.asarray(objects, dtype=float).reshape(-1, OBJECT_DIM)):
            values.insert(self.object(j), np.array(obj))
        return values

    def from_values(self, values: gtsam.Values) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(N, 3) poses with wrapped heading and (K, 5) objects of ``values``."""
        poses = np.array([_pose_array(values.atPose2(k)) for k in self.pose_keys]).reshape(-1, POSE_DIM)
        poses[:, 2] = wrap_angle(poses[:, 2])
        objects = np.array([values.atVector(k) for k in self.object_keys]).reshape(-1, OBJECT_DIM)
        return poses, objects

    def calibration_of(self, values: gtsam.Values) -> NDArray[np.float64]:
        """The calibration of ``values``: (3,), or (0,) when it is not a variable."""
        return np.array(values.atVector(self.calibration())) if self.calibration_dim else np.zeros(0)


def _pose_array(pose: gtsam.Pose2) -> NDArray[np.float64]:
    return np.array([pose.x(), pose.y(), pose.theta()])


def _read_poses(values: gtsam.Values, keys: Sequence[int]) -> NDArray[np.float64]:
    return np.array([_pose_array(values.atPose2(k)) for k in keys])


def _chart(jac_world: NDArray[np.float64], theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Pose Jacobians (rows, 3, A) w.r.t. map (x, y, theta) -> w.r.t. Pose2 tangent (times blockdiag(R, 1))."""
    c, s = np.cos(theta), np.sin(theta)
    out = np.empty_like(jac_world)
    out[:, 0] = jac_world[:, 0] * c + jac_world[:, 1] * s
    out[:, 1] = jac_world[:, 1] * c - jac_world[:, 0] * s
    out[:, 2] = jac_world[:, 2]
    return out


def _set_pose_jacobians(jacobians: list, n_keys: int, *blocks: tuple[NDArray[np.float64], NDArray[np.int64]]) -> None:
    """Fill ``jacobians[0:n_keys]``, the dense (rows, 3) blocks GTSAM wants, from sparse row groups.

    Each ``(block, key_of)`` holds one (r, 3) block per row group a (``block`` (A, r, 3)),
    which belongs to the rows r*a..r*a+r-1 and to the pose key number ``key_of[a]``.
    """
    count, rows = blocks[0][0].shape[:2]
    full = np.zeros((count, rows, n_keys, POSE_DIM))
    groups = np.arange(count)
    for block, key_of in blocks:
        full[groups, :, key_of, :] += block
    flat = full.reshape(count * rows, n_keys * POSE_DIM)
    for k in range(n_keys):
        jacobians[k] = flat[:, POSE_DIM * k : POSE_DIM * (k + 1)]


# -- factors ------------------------------------------------------------------------------------


def _slice_factor(
    problem: GraphProblem, measurements: NDArray[np.int64], object_key: int, cap_scale: float = 1.0
) -> gtsam.CustomFactor:
    """One CustomFactor over ``measurements`` of one object: residual rows 4m..4m+3 per measurement m.

    ``cap_scale`` multiplies the outlier caps (inf: every slice Gaussian; objslam_mapper.model.outliers)."""
    pose_index, local = np.unique(problem.measurement_pose[measurements], return_inverse=True)
    pose_keys = [GtsamKeys.pose(i) for i in pose_index]
    z = np.ascontiguousarray(problem.measurements[measurements].T)  # (4, A)
    inv_sigma = np.ascontiguousarray(1.0 / problem.measurement_stddev[measurements].T)
    bounds = problem.measurement_bounds[measurements]
    cap = problem.measurement_outlier_cost[measurements] * cap_scale
    capped = bool(np.isfinite(cap).any())
    mount = problem.mounts(measurements)
    n_keys = len(pose_keys)

    def error(_factor: gtsam.CustomFactor, values: gtsam.Values, jacobians: list | None) -> NDArray[np.float64]:
        at = _read_poses(values, pose_keys)[local]
        obj = values.atVector(object_key)
        pred = predict_reduced(at, obj[:3], obj[3:], mount, jacobians=jacobians is not None)
        err, sigma_weight = whitened_slice_error(pred.values, z, inv_sigma, bounds)
        weight = sigma_weight * truncate(err, cap) if capped else sigma_weight  # capped slices carry no information
        err[:, ~pred.valid] = _INVALID_RESIDUAL
        if jacobians is not None:
            jac = pred.jacobian * weight[:, None, :]  # (4, 6, A)
            pose_block = _chart(jac[:, :3] * _POSE_SIGN[None, :, None], at[:, 2])
            _set_pose_jacobians(jacobians, n_keys, (pose_block.transpose(2, 0, 1), local))
            jacobians[n_keys] = jac[:, _OBJECT_COLUMNS].transpose(2, 0, 1).reshape(-1, OBJECT_DIM)
        return err.T.ravel()

    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(4 * len(measurements)), [*pose_keys, object_key], error)


def _floor_factor(object_key: int, floor_stddev_m: float) -> gtsam.CustomFactor:
    """The one-sided floor factor on an object's base height (objslam_mapper.model.floor)."""
    inv_sigma = 1.0 / floor_stddev_m

    def error(_factor: gtsam.CustomFactor, values: gtsam.Values, jacobians: list | None) -> NDArray[np.float64]:
        z_base = values.atVector(object_key)[2]
        if jacobians is not None:
            jacobians[0] = np.zeros((1, OBJECT_DIM))
            jacobians[0][0, 2] = floor_jacobian(z_base, inv_sigma)
        return np.atleast_1d(floor_residual(z_base, inv_sigma))

    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(1), [object_key], error)


def _odometry_factor(problem: GraphProblem, first: int, stop: int) -> gtsam.CustomFactor:
    """One CustomFactor over the odometry increments first..stop-1 (poses first..stop), rows 3k..3k+2 each.

    Keyed on the calibration too (last key) when the problem estimates it."""
    pose_keys = [GtsamKeys.pose(i) for i in range(first, stop + 1)]
    calibrated = problem.calibration_dim > 0
    u = problem.increments[first:stop]
    length = problem.increment_path_length_m[first:stop]
    w = 1.0 / problem.increment_stddev[first:stop]  # (n, 3)
    n = stop - first

    def error(_factor: gtsam.CustomFactor, values: gtsam.Values, jacobians: list | None) -> NDArray[np.float64]:
        poses = _read_poses(values, pose_keys)
        pi, pj = poses[:-1], poses[1:]
        c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
        dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
        q1, q2 = c * dx + s * dy, -s * dx + c * dy
        if calibrated:
            calib = values.atVector(GtsamKeys.calibration())
            k, m = 1.0 + calib[0], 1.0 + calib[1]
            dtheta = wrap_angle(pj[:, 2] - pi[:, 2])
            err = np.stack([k * q1 - u[:, 0], k * q2 - u[:, 1], m * dtheta + calib[2] * length - u[:, 2]], -1)
        else:
            k = m = 1.0
            err = np.stack([q1 - u[:, 0], q2 - u[:, 1], pj[:, 2] - pi[:, 2] - u[:, 2]], -1)
        err[:, 2] = wrap_angle(err[:, 2])
        if jacobians is not None:
            # d err / d (map x, y, theta) of pose i and pose j, per increment (n, 3, 3).
            zero, mm = np.zeros(n), np.full(n, m)
            jac_i = np.array([[-k * c, -k * s, k * q2], [k * s, -k * c, -k * q1], [zero, zero, -mm]])  # (3, 3, n)
            jac_j = np.array([[k * c, k * s, zero], [-k * s, k * c, zero], [zero, zero, mm]])
            jac_i = _chart(jac_i * w.T[:, None, :], pi[:, 2]).transpose(2, 0, 1)
            jac_j = _chart(jac_j * w.T[:, None, :], pj[:, 2]).transpose(2, 0, 1)
            increment = np.arange(n)
            _set_pose_jacobians(jacobians, n + 1, (jac_i, increment), (jac_j, increment + 1))
            if calibrated:
                jac_c = np.zeros((n, 3, 3))
                jac_c[:, 0, 0], jac_c[:, 1, 0] = w[:, 0] * q1, w[:, 1] * q2
                jac_c[:, 2, 1], jac_c[:, 2, 2] = w[:, 2] * dtheta, w[:, 2] * length
                jacobians[n + 1] = jac_c.reshape(3 * n, 3)
        return (err * w).ravel()

    keys = [*pose_keys, GtsamKeys.calibration()] if calibrated else pose_keys
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(3 * n), keys, error)


def _first_pose_factor(problem: GraphProblem) -> gtsam.CustomFactor:
    """The prior ``wrap(x_0 - odometry_0) / sigma`` of the first pose (additive, as in the fast solver)."""
    mean, w = problem.odometry_poses[0], 1.0 / problem.first_pose_stddev

    def error(_factor: gtsam.CustomFactor, values: gtsam.Values, jacobians: list | None) -> NDArray[np.float64]:
        pose = _pose_array(values.atPose2(GtsamKeys.pose(0)))
        err = pose - mean
        err[2] = wrap_angle(err[2])
        if jacobians is not None:
            jacobians[0] = _chart(np.diag(w)[:, :, None], pose[2:])[:, :, 0]
        return err * w

    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(POSE_DIM), [GtsamKeys.pose(0)], error)


def _window_size(count: int, window_poses: int | None, per_detection: bool) -> int:
    if per_detection:
        return 1
    if window_poses is None:
        return max(count, 1)
    if isinstance(window_poses, bool) or not isinstance(window_poses, int) or window_poses < 1:
        raise GtsamBackendError(f"window_poses must be a positive integer or None, got {window_poses!r}")
    return window_poses


def build_gtsam_graph(
    problem: GraphProblem,
    groups: Sequence[ArrayLike],
    *,
    per_detection: bool = False,
    window_poses: int | None = DEFAULT_WINDOW_POSES,
    priors: ArrayLike | None = None,
    cap_scale: float = 1.0,
) -> tuple[gtsam.NonlinearFactorGraph, GtsamKeys]:
    """The factor graph of the association ``groups`` (module docstring) and its keys.

    ``groups[j]`` lists the measurement indices of object j (checked as by ``solver.solve``),
    ``priors[j]`` its prior row (as ``solver.solve``'s). ``window_poses`` only matters with
    ``per_detection=False``: None makes one slice factor per group and one odometry factor
    for the whole trajectory. ``cap_scale`` multiplies the slices' outlier caps (inf: none).
    """
    problem = keyframes_of(problem).problem
    return _build(problem, layout_of(problem, groups, priors), per_detection, window_poses, cap_scale)


def _build(
    problem: GraphProblem, layout: Layout, per_detection: bool, window_poses: int | None, cap_scale: float = 1.0
) -> tuple[gtsam.NonlinearFactorGraph, GtsamKeys]:
    keys = GtsamKeys(problem.pose_count, layout.n_objects, problem.calibration_dim)
    window = _window_size(problem.pose_count, window_poses, per_detection)
    graph = gtsam.NonlinearFactorGraph()
    graph.add(_first_pose_factor(problem))
    for first in range(0, problem.pose_count - 1, window):
        graph.add(_odometry_factor(problem, first, min(first + window, problem.pose_count - 1)))
    for j, group in enumerate(layout.groups):
        row = int(layout.priors[j])
        sigmas = gtsam.noiseModel.Diagonal.Sigmas(problem.prior_stddev[row])
        graph.add(gtsam.PriorFactorVector(keys.object(j), np.array(problem.prior_mean[row]), sigmas))
        if np.isfinite(problem.prior_floor_stddev[row]):
            graph.add(_floor_factor(keys.object(j), float(problem.prior_floor_stddev[row])))
        if per_detection:
            chunks = np.split(group, np.arange(1, len(group)))
        else:
            cell = problem.measurement_pose[group] // window
            order = np.argsort(cell, kind="stable")
            chunks = np.split(group[order], np.flatnonzero(np.diff(cell[order])) + 1)
        for chunk in chunks:
            graph.add(_slice_factor(problem, chunk, keys.object(j), cap_scale))
    if problem.calibration_dim:
        sigmas = gtsam.noiseModel.Diagonal.Sigmas(np.array(problem.calibration_prior_stddev))
        graph.add(gtsam.PriorFactorVector(keys.calibration(), np.zeros(problem.calibration_dim), sigmas))
    return graph, keys


# -- solving ------------------------------------------------------------------------------------


@dataclass
class _Linear:
    """One linearization: the Gaussian graph and the cost (half chi-square) at its point."""

    graph: gtsam.GaussianFactorGraph
    cost: float
    # Per variable, its block of diag(Lambda), read once (:meth:`_Linearizer.diagonals`) where
    # the lost test or the damping needs it: one sparse Jacobian per linearization, not per use.
    diagonals: dict[int, NDArray[np.float64]] | None = None


class _Linearizer:
    """Linearizes a graph and reads off its cost (``1/2 |b|^2`` of the whitened system) in one pass."""

    def __init__(self, graph: gtsam.NonlinearFactorGraph, keys: GtsamKeys, problem: GraphProblem, layout: Layout):
        self.graph = graph
        self.keys, self.problem, self.layout = keys, problem, layout
        self.prior_xy_information = problem.prior_stddev[layout.priors, :2] ** -2.0  # (K, 2)
        self.dims = {k: POSE_DIM for k in keys.pose_keys} | {k: OBJECT_DIM for k in keys.object_keys}
        if keys.calibration_dim:
            self.dims[keys.calibration()] = keys.calibration_dim
        self.zero = gtsam.VectorValues()
        for k, dim in self.dims.items():
            self.zero.insert(k, np.zeros(dim))
        self.ordering: gtsam.Ordering | None = None

    def __call__(self, values: gtsam.Values) -> _Linear:
        lin = self.graph.linearize(values)
        if self.ordering is None:
            self.ordering = gtsam.Ordering.ColamdGaussianFactorGraph(lin)
        return _Linear(lin, float(lin.error(self.zero)))

    def eliminate(self, graph: gtsam.GaussianFactorGraph) -> gtsam.GaussianBayesTree:
        return graph.eliminateMultifrontal(self.ordering)

    def diagonals(self, current: _Linear) -> dict[int, NDArray[np.float64]]:
        """``current``'s blocks of diag(Lambda) (:func:`_diagonals`), read on first use."""
        if current.diagonals is None:
            current.diagonals = _diagonals(current.graph, self.dims)
        return current.diagonals

    def lost(self, current: _Linear) -> NDArray[np.bool_]:
        """(K,) the objects no slice places, as :func:`solver.lost_objects` finds them."""
        diagonals = self.diagonals(current)
        information = np.array([diagonals[k][:2] for k in self.keys.object_keys]).reshape(-1, 2)
        prior = self.prior_xy_information
        return np.all(information - prior <= LOST_INFORMATION_SHARE * prior, axis=1)

    def restart(self, values: gtsam.Values, current: _Linear, lost: NDArray[np.bool_]) -> tuple[gtsam.Values, _Linear]:
        """As :func:`solver._restart`: each lost object from its own slices, where that lowers the cost."""
        poses, _ = self.keys.from_values(values)
        for j in np.flatnonzero(lost).tolist():
            moved = gtsam.Values(values)
            moved.update(self.keys.object(j), initial_object(self.problem, self.layout.groups[j], poses))
            moved_linear = self(moved)
            if moved_linear.cost < current.cost:
                values, current = moved, moved_linear
        return values, current


def _diagonals(lin: gtsam.GaussianFactorGraph, dims: dict[int, int]) -> dict[int, NDArray[np.float64]]:
    """Per variable, its block of the diagonal of ``Lambda = A^T A``, from the sparse whitened
    Jacobian, whose columns are numbered by sorted key (``dims``: every variable's dimension)."""
    triplets = lin.sparseJacobian_()
    total = sum(dims.values())
    columns = triplets[1].astype(np.int64) - 1
    diagonal = np.asarray(np.bincount(columns, weights=triplets[2] ** 2, minlength=total + 1), dtype=float)
    blocks: dict[int, NDArray[np.float64]] = {}
    start = 0
    for key in sorted(dims):
        blocks[key] = diagonal[start : start + dims[key]]
        start += dims[key]
    return blocks


def _damped(
    lin: gtsam.GaussianFactorGraph, damping: float, diagonals: dict[int, NDArray[np.float64]]
) -> gtsam.GaussianFactorGraph:
    """``lin`` with Marquardt damping ``diag(Lambda) *= 1 + damping`` (as the fast solver damps),
    ``diagonals`` its blocks of diag(Lambda) (:func:`_diagonals`)."""
    damped = lin.clone()
    for key, diag in diagonals.items():
        dim = len(diag)
        damped.add(
            gtsam.JacobianFactor(
                key, np.diag(np.sqrt(damping * diag)), np.zeros(dim), gtsam.noiseModel.Unit.Create(dim)
            )
        )
    return damped


def _hold_lost_objects(keys: GtsamKeys, lost: NDArray[np.bool_], delta: gtsam.VectorValues) -> None:
    """Zero the x, y step of every ``lost`` object, as :func:`solver.hold_lost_objects` does."""
    held = gtsam.VectorValues()
    for j in np.flatnonzero(lost).tolist():
        key = keys.object(j)
        step = np.array(delta.at(key))
        step[:2] = 0.0
        held.insert(key, step)
    if held.size():
        delta.update(held)


def _step(
    keys: GtsamKeys, lost: NDArray[np.bool_], current: _Linear, bayes_tree: gtsam.GaussianBayesTree
) -> tuple[gtsam.VectorValues, float]:
    """The step of an elimination, ``lost`` objects held, and the decrease the undamped linear model predicts for it."""
    delta = bayes_tree.optimize()
    _hold_lost_objects(keys, lost, delta)
    return delta, current.cost - float(current.graph.error(delta))


@dataclass
class _Driven:
    values: gtsam.Values
    linear: _Linear
    bayes_tree: gtsam.GaussianBayesTree | None  # undamped elimination at ``values``, if the loop made one
    iterations: int
    converged: bool | None  # None: decided by the final check


def _drive_python(linearize: _Linearizer, values: gtsam.Values, cfg: SolverConfig, max_iterations: int) -> _Driven:
    """The fast solver's loop (``solver._minimize``) over GTSAM linearizations.

    Gauss-Newton while it works, Nielsen's damping after a failed step; the predicted
    decrease is the undamped linear model's ``cost - 1/2 |A delta - b|^2``, which equals the
    fast solver's ``1/2 (-g^T step + damping step^T D step)`` for a damped step too.
    """
    current = linearize(values)
    damping, growth = 0.0, 2.0
    iterations = 1
    restarted = np.zeros(linearize.keys.object_count, dtype=bool)
    while iterations < max_iterations:
        lost = linearize.lost(current)
        fresh = lost & ~restarted
        if fresh.any():
            iterations += 1
            values, current = linearize.restart(values, current, fresh)
            restarted |= fresh
            continue
        system = current.graph if damping == 0.0 else _damped(current.graph, damping, linearize.diagonals(current))
        try:
            bayes_tree = linearize.eliminate(system)
        except RuntimeError:  # GTSAM's indeterminant linear system
            damping, growth = max(cfg.initial_lambda, damping * growth), 2.0 * growth
            if damping > cfg.max_lambda:
                break
            continue
        delta, predicted = _step(linearize.keys, lost, current, bayes_tree)
        tolerance = cfg.absolute_tolerance + cfg.relative_tolerance * current.cost
        if predicted <= tolerance:
            if damping <= cfg.initial_lambda:
                return _Driven(values, current, bayes_tree if damping == 0.0 else None, iterations, True)
            try:  # as the fast solver: is the undamped step's prediction small too?
                undamped = linearize.eliminate(current.graph)
            except RuntimeError:
                undamped = None
            if undamped is not None and _step(linearize.keys, lost, current, undamped)[1] <= tolerance:
                return _Driven(values, current, undamped, iterations, True)
        new_values = values.retract(delta)
        new = linearize(new_values)
        iterations += 1
        if np.isfinite(new.cost) and new.cost <= current.cost:
            decrease = current.cost - new.cost
            rho = decrease / max(predicted, 1e-300)
            values, current = new_values, new
            # rho capped at 1, where the factor is 1/3 anyway: a decrease over a vanishing
            # prediction (lost objects held) overflowed the cube.
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * min(rho, 1.0) - 1.0) ** 3)
            growth = 2.0
            if damping < 1e-3 * cfg.initial_lambda:
                damping = 0.0
            if decrease <= tolerance and damping <= cfg.initial_lambda:
                return _Driven(values, current, None, iterations, True)
        else:
            damping, growth = max(cfg.initial_lambda, damping * growth), 2.0 * growth
            if damping > cfg.max_lambda:
                break
    return _Driven(values, current, None, iterations, False)


def _drive_optimizer(
    graph: gtsam.NonlinearFactorGraph,
    linearize: _Linearizer,
    values: gtsam.Values,
    cfg: SolverConfig,
    max_iterations: int,
) -> _Driven:
    """GTSAM's LevenbergMarquardtOptimizer with the solver settings (Marquardt damping, same tolerances)."""
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    params.setAbsoluteErrorTol(cfg.absolute_tolerance)
    params.setRelativeErrorTol(cfg.relative_tolerance)
    params.setlambdaInitial(cfg.initial_lambda)
    params.setlambdaUpperBound(cfg.max_lambda)
    params.setDiagonalDamping(True)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    result = optimizer.optimize()
    # One linearization per iteration, plus the final one for the evidence.
    return _Driven(result, linearize(result), None, optimizer.iterations() + 1, None)


def solve_gtsam(
    problem: GraphProblem,
    groups: Sequence[ArrayLike],
    warm_start: GraphSolution | None = None,
    *,
    with_covariances: bool = False,
    max_iterations: int | None = None,
    per_detection: bool = False,
    drive: Drive = "python",
    window_poses: int | None = DEFAULT_WINDOW_POSES,
    priors: ArrayLike | None = None,
) -> GraphSolution:
    """MAP, Laplace evidence and (optionally) object marginals of ``groups``, solved by GTSAM.

    Arguments and result as :func:`objslam_mapper.graph.solver.solve` (same initialization from
    ``warm_start`` or odometry and :func:`initialization.initial_object`); ``per_detection``
    and ``window_poses`` choose the graph (:func:`build_gtsam_graph`), ``drive`` the loop.
    ``converged`` means the final Gauss-Newton step predicts a decrease within the tolerance.
    """
    if drive not in DRIVES:
        raise GtsamBackendError(f"drive must be one of {', '.join(DRIVES)}, got {drive!r}")
    keyframes = keyframes_of(problem)
    problem = keyframes.problem  # from here on the graph's: one pose per keyframe
    layout = layout_of(problem, groups, priors)
    poses, objects = initial_state(keyframes, layout, warm_start)
    calib = initial_calibration(problem, warm_start)
    valid = predict_reduced(
        poses[layout.pose_of],
        objects[layout.object_of, :3],
        objects[layout.object_of, 3:],
        problem.mounts(layout.measurements),
        jacobians=False,
    ).valid
    if not np.all(valid):
        logger.debug("GTSAM solve cannot start: a pose lies inside an object's starting cylinder")
        return make_solution(keyframes, layout, (poses, objects, calib), NOT_STARTED)

    cfg = problem.solver
    limit = cfg.max_iterations if max_iterations is None else max_iterations
    keys = GtsamKeys(problem.pose_count, layout.n_objects, problem.calibration_dim)
    values = keys.to_values(poses, objects, calib)
    # As the fast solver: graduated caps, each phase with the budget and only while a slice
    # is beyond its true cap.
    iterations = 0
    for phase, cap_scale in enumerate(cap_schedule(problem, layout, poses, objects, warm_start is not None)):
        if phase and not count_outliers(problem, layout, *keys.from_values(values)):
            break
        graph, keys = _build(problem, layout, per_detection, window_poses, cap_scale)
        solved_cap_scale = cap_scale
        linearize = _Linearizer(graph, keys, problem, layout)
        if drive == "python":
            driven = _drive_python(linearize, values, cfg, limit)
        else:
            driven = _drive_optimizer(graph, linearize, values, cfg, limit)
        values = driven.values
        iterations += driven.iterations

    final = driven.linear
    bayes_tree = driven.bayes_tree or linearize.eliminate(final.graph)
    converged = driven.converged
    if converged is None:
        predicted = final.cost - float(final.graph.error(bayes_tree.optimize()))
        converged = predicted <= cfg.absolute_tolerance + cfg.relative_tolerance * final.cost
    if not converged:
        logger.debug("GTSAM solve stopped after %d linearizations without converging", iterations)
    log_det = 2.0 * float(bayes_tree.logDeterminant())
    dimension = POSE_DIM * problem.pose_count + OBJECT_DIM * layout.n_objects + problem.calibration_dim
    log_evidence = -final.cost + graph_log_normalizer(problem, layout) + 0.5 * dimension * LOG_2PI - 0.5 * log_det
    covariance = calib_cov = None
    if with_covariances:
        marginals = gtsam.Marginals(final.graph, driven.values)
        covariance = np.array([marginals.marginalCovariance(k) for k in keys.object_keys]).reshape(
            -1, OBJECT_DIM, OBJECT_DIM
        )
        calib_cov = marginals.marginalCovariance(keys.calibration()) if keys.calibration_dim else np.zeros((0, 0))
    poses, objects = keys.from_values(driven.values)
    if covariance is not None and len(covariance) and problem.pose_count > 1:
        covariance = _about_trajectory(final.graph, keys, poses, objects, keyframes.images_per_keyframe, covariance)
    calib = keys.calibration_of(driven.values)
    error_cov = None
    if with_covariances:
        system = AssociationSystem(problem, layout, cfg.dense_object_limit)
        system.cap_scale = solved_cap_scale
        error_cov = object_error_covariance(keyframes, system, (poses, objects, calib))
    outcome = SolveOutcome(iterations, converged, log_evidence, 2.0 * final.cost, log_det)
    covariances = SolutionCovariances(objects=covariance, calibration=calib_cov, errors=error_cov)
    return make_solution(keyframes, layout, (poses, objects, calib), outcome, covariances)


def _about_trajectory(
    linear: gtsam.GaussianFactorGraph,
    keys: GtsamKeys,
    poses: NDArray[np.float64],
    objects: NDArray[np.float64],
    pose_weights: NDArray[np.float64],
    marginals: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Object covariances about the trajectory (:mod:`objslam_mapper.graph.gauge`) from GTSAM's linear graph.

    GTSAM perturbs a Pose2 in its own frame (first order: world ``δt = R(θ) δt_body``), so
    the gauge's rows are taken through each pose's rotation before the solve.
    """
    ordering = gtsam.Ordering()
    all_keys = [*keys.pose_keys, *keys.object_keys] + ([keys.calibration()] if keys.calibration_dim else [])
    for key in all_keys:
        ordering.push_back(key)
    information, _ = linear.hessian(ordering)
    gauge = trajectory_gauge(poses[:, :2], pose_weights)
    cos, sin = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    world_x, world_y = gauge.rows[:, 0::3], gauge.rows[:, 1::3]
    rows = np.zeros((GAUGE_DIM, len(information)))
    rows[:, 0 : POSE_DIM * len(poses) : 3] = world_x * cos + world_y * sin
    rows[:, 1 : POSE_DIM * len(poses) : 3] = -world_x * sin + world_y * cos
    solved = np.linalg.solve(information, rows.T)
    split = POSE_DIM * len(poses)
    object_gauge_cov = solved[split : split + OBJECT_DIM * len(objects)]
    return about_trajectory(marginals, object_gauge_cov, rows @ solved, objects[:, :2], gauge.centroid_xy)
