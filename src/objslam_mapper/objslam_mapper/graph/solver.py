r"""Known-association solve: MAP, marginals and Laplace evidence of one association.

This is the inner loop of the association sampler, so it is built for speed: no
per-factor Python objects. For a given association (``groups``: one list of global
measurement indices per object) the nonlinear least-squares problem

    cost(theta) = 1/2 sum_k |e_k(theta)|^2_{Sigma_k}      (paper eqs. 6, 12-13)

over ``theta = (poses (N x 3), objects (K x 5))`` -- odometry factors, the first-pose
prior, one slice factor per assigned measurement (:mod:`slice_model`, analytic
Jacobians) and the class priors of every object -- is minimized by Gauss-Newton with a
Levenberg-Marquardt fallback, driven here over numpy arrays
(:mod:`objslam_mapper.graph.linearize` assembles and solves each linear system).

The Laplace approximation of the evidence (paper eq. 25) at the MAP ``theta*`` is

    log P(Z_J | J) = -1/2 chi2(theta*) + sum_k -1/2 log|2 pi Sigma_k|
                     + d/2 log(2 pi) - 1/2 log|Lambda|,

summed over every factor of the graph (odometry, first-pose prior, assigned slices,
object priors, and the odometry calibration's prior when it is estimated; a slice's
factor is the max-mixture of :mod:`objslam_mapper.model.outliers`, so an outlier slice adds
its capped cost and no information), with
``d = 3N + 5K (+ 3 for the calibration)`` and ``Lambda = J^T Sigma^-1 J`` the Gauss-Newton
information at the MAP (``2 log|R|`` of GTSAM's square-root information). Measurements in no
group are not part of the graph: the sampler scores them with its clutter model. A new
object pays its Occam price through its prior's normalizer and its ``5/2 log 2 pi -
1/2 log|information|``. Object covariances come from the same factorization, about the
trajectory as a whole rather than the anchored first pose (:mod:`objslam_mapper.graph.gauge`).

With ``odometry.calibration.enabled`` the state also holds the odometry calibration ``c``
(distance scale, turn scale, turn bias per metre; one per map, model in
:mod:`objslam_mapper.graph.linearize`): it starts from the warm start's or from 0, its
zero-mean prior's normalizer is part of ``problem.trajectory_log_normalizer``, it adds 3 to
``d``, and its MAP and marginal covariance are ``GraphSolution.calibration(_cov)``.

API (what the association sampler calls)::

    problem = build_problem(odometry, images, mount, catalog, config)   # objslam_mapper.graph.problem
    solution = solve(problem, groups, warm_start=None, with_covariances=False)
    solution.log_evidence, solution.map_T_base, solution.objects[j].location_m, ...

``warm_start`` is a previous :class:`GraphSolution` of the same problem: its poses are
reused, and each new group starts from the previous object sharing most of its
measurements (a merge starts from its larger part, a split from the parent), or from
:func:`objslam_mapper.graph.initialization.initial_object` when it shares none.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.geometry import wrap_angle
from objslam_mapper.config import SolverConfig
from objslam_mapper.graph.covariance import (
    calibration_covariance,
    object_covariance_about_trajectory,
    object_error_covariance_about_trajectory,
)
from objslam_mapper.graph.error_covariance import ErrorCovarianceError
from objslam_mapper.graph.factorize import Factorization, factorize
from objslam_mapper.graph.initialization import initial_object
from objslam_mapper.graph.keyframes import KeyframeGraph, keyframes_of
from objslam_mapper.graph.layout import Layout, layout_of
from objslam_mapper.graph.linearize import AssociationSystem, Linearization, cap_schedule
from objslam_mapper.graph.problem import LOG_2PI, OBJECT_DIM, POSE_DIM, GraphError, GraphProblem
from objslam_mapper.model.slice_model import camera_positions

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ObjectEstimate:
    """One object of a solution: MAP location (x, y, z_base) and size (diameter, height), m.

    Covariances (m^2), None unless asked for: ``location_cov`` and ``size_cov`` are the
    marginals of the Laplace posterior about the trajectory (the existence test reads
    them); ``error_cov`` (5, 5; location, then size) is the covariance of the estimate's
    error about the trajectory (:mod:`objslam_mapper.graph.error_covariance`), what a map
    reports, None when ``solver.error_covariance.enabled`` is off.
    """

    label: str
    location_m: NDArray[np.float64]
    size_m: NDArray[np.float64]
    measurement_indices: NDArray[np.int64]
    location_cov: NDArray[np.float64] | None = None
    size_cov: NDArray[np.float64] | None = None
    error_cov: NDArray[np.float64] | None = None


@dataclass(frozen=True, eq=False)
class GraphSolution:
    """MAP estimate and Laplace evidence of one association.

    ``objects[j]`` belongs to ``groups[j]`` of the call. ``chi2`` is the total whitened
    squared error at the MAP, ``log_det_information`` is ``log|Lambda|``; ``iterations``
    counts linearizations. A solve that could not start (a pose inside an object's
    starting cylinder) has ``converged=False`` and ``log_evidence=-inf``.
    ``object_of_measurement`` (M,) gives each measurement's object number, -1 if none.
    """

    map_T_base: NDArray[np.float64]  # (N, 3): every image's pose (objslam_mapper.graph.keyframes)
    objects: tuple[ObjectEstimate, ...]
    object_of_measurement: NDArray[np.int64]
    iterations: int
    converged: bool
    log_evidence: float
    chi2: float
    log_det_information: float
    # Odometry calibration (distance scale, turn scale, turn bias rad/m): (3,) MAP and (3, 3)
    # marginal covariance when the problem estimates it, else (0,) / (0, 0); covariance None unless asked for.
    calibration: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    calibration_cov: NDArray[np.float64] | None = None


def initial_calibration(problem: GraphProblem, warm_start: GraphSolution | None) -> NDArray:
    """The warm start's calibration, else the prior mean (no systematic error)."""
    if warm_start is not None and len(warm_start.calibration) == problem.calibration_dim:
        return np.array(warm_start.calibration, dtype=float)
    return np.zeros(problem.calibration_dim)


def initial_state(
    keyframes: KeyframeGraph, layout: Layout, warm_start: GraphSolution | None
) -> tuple[NDArray, NDArray]:
    """Starting graph poses and objects of a solve of ``keyframes.problem`` (``layout`` is over it)."""
    problem = keyframes.problem
    if warm_start is None:
        poses = np.array(problem.odometry_poses)
    else:
        if len(warm_start.map_T_base) != len(keyframes.pose_keyframe):
            raise GraphError(
                f"warm start has {len(warm_start.map_T_base)} poses, the problem {len(keyframes.pose_keyframe)}"
            )
        poses = keyframes.restrict(warm_start.map_T_base)
    objects = np.empty((len(layout.groups), OBJECT_DIM))
    for j, group in enumerate(layout.groups):
        owners = warm_start.object_of_measurement[group] if warm_start is not None else group[:0]
        owners = owners[owners >= 0]
        if warm_start is not None and len(owners):
            prev = warm_start.objects[int(np.argmax(np.bincount(owners)))]
            objects[j, :3], objects[j, 3:] = prev.location_m, prev.size_m
        else:
            objects[j] = initial_object(problem, group, poses)
    # A warm start can hand a group an object that some of its poses are inside (e.g. a
    # merge of far-apart tracklets) where the model is undefined (D <= r): start such an
    # object from its own measurements instead, and shrink any diameter that still does
    # not fit (the size prior regrows it while solving).
    nearest = _nearest_camera(problem, layout, poses, objects)
    for k in np.flatnonzero(nearest <= 0.5 * objects[:, 3]):
        objects[k] = initial_object(problem, layout.groups[k], poses)
    nearest = _nearest_camera(problem, layout, poses, objects)
    objects[:, 3] = np.minimum(objects[:, 3], 1.8 * nearest)
    return poses, objects


def _nearest_camera(problem: GraphProblem, layout: Layout, poses: NDArray, objects: NDArray) -> NDArray:
    """(K,) horizontal distance from each object's axis to the nearest camera that saw it."""
    cam_x, cam_y = camera_positions(poses[layout.pose_of], problem.mounts(layout.measurements))
    obj = objects[layout.object_of]
    nearest = np.full(len(objects), np.inf)
    np.minimum.at(nearest, layout.object_of, np.hypot(obj[:, 0] - cam_x, obj[:, 1] - cam_y))
    return nearest


def solve(
    problem: GraphProblem,
    groups: Sequence[ArrayLike],
    warm_start: GraphSolution | None = None,
    *,
    with_covariances: bool = False,
    max_iterations: int | None = None,
    priors: ArrayLike | None = None,
) -> GraphSolution:
    """MAP, evidence and (optionally) object marginals of the association ``groups``.

    ``groups[j]`` lists the global measurement indices of object j (sequence or integer
    array; one class per group, no measurement twice). Measurements in no group are left
    out of the graph. ``priors[j]`` is the prior row of object j (default: its class's;
    :func:`objslam_mapper.graph.problem.with_extra_priors`). ``max_iterations`` overrides
    ``solver.max_iterations`` for this call (per phase of the outlier caps,
    :mod:`objslam_mapper.model.outliers`); a sampler may cap hopeless proposals: an unconverged solution reports
    the evidence at its last iterate, which is below that of the optimum up to the
    log-determinant.
    """
    keyframes = keyframes_of(problem)
    problem = keyframes.problem  # from here on the graph's: one pose per keyframe
    layout = layout_of(problem, groups, priors)
    graph = AssociationSystem(problem, layout, problem.solver.dense_object_limit)
    poses, objects = initial_state(keyframes, layout, warm_start)
    calib = initial_calibration(problem, warm_start)

    # Phases of graduated outlier caps (objslam_mapper.model.outliers), each with the iteration
    # budget; where no slice is beyond its true cap the remaining phases' costs agree with
    # the current one: they are moot. (A shared budget was tried: it cut good proposals
    # short, 60-80 nats below their optimum, and the chain then never took them.)
    schedule = cap_schedule(problem, layout, poses, objects, warm_start is not None)
    graph.cap_scale = schedule[0]
    lin = graph.linearize(poses, objects, calib)
    if not lin.valid:
        logger.debug("solve cannot start: a pose lies inside an object's starting cylinder")
        return make_solution(keyframes, layout, (poses, objects, calib), NOT_STARTED)
    limit = problem.solver.max_iterations if max_iterations is None else max_iterations
    iterations, state = 0, (poses, objects, calib)
    for phase, scale in enumerate(schedule):
        if phase:
            if not (graph.has_outlier_model and lin.outliers):
                break
            graph.cap_scale = scale
            lin = graph.linearize(*state)
        state, lin, final, more, converged = _minimize(graph, state, lin, problem.solver, limit)
        iterations += more
    poses, objects, calib = state
    if final is None or (with_covariances and final.folded):
        try:
            final = factorize(graph, lin, 0.0, fold=not with_covariances)
        except np.linalg.LinAlgError:
            # Damping gave up where the information is not positive definite: no optimum, so
            # no Laplace evidence (seen fitting one distractor to slices of two things).
            logger.debug("solve ended where the information is not positive definite: no evidence")
            return make_solution(
                keyframes, layout, state, SolveOutcome(iterations, False, -np.inf, 2.0 * lin.cost, np.nan)
            )
    if not converged:
        logger.debug("solve stopped after %d linearizations without converging (cost %.6g)", iterations, lin.cost)

    log_evidence = -lin.cost + graph.log_normalizer + 0.5 * graph.dimension * LOG_2PI - 0.5 * final.log_det
    covariance = None
    if with_covariances:
        covariance = object_covariance_about_trajectory(
            graph, final, poses[:, :2], keyframes.images_per_keyframe, objects
        )
    calib_cov = calibration_covariance(graph, final) if with_covariances else None
    error_cov = object_error_covariance(keyframes, graph, state, lin) if with_covariances else None
    outcome = SolveOutcome(iterations, converged, log_evidence, 2.0 * lin.cost, final.log_det)
    covariances = SolutionCovariances(objects=covariance, calibration=calib_cov, errors=error_cov)
    return make_solution(keyframes, layout, (poses, objects, calib), outcome, covariances)


_State = tuple[NDArray, NDArray, NDArray]  # poses (N, 3), objects (K, 5), calibration (C,)


def object_error_covariance(
    keyframes: KeyframeGraph,
    system: AssociationSystem,
    state: tuple[NDArray, NDArray, NDArray],
    lin: Linearization | None = None,
) -> NDArray[np.float64] | None:
    """(K, 5, 5) error covariances about the trajectory at a MAP ``state`` (poses, objects, calibration).

    Any backend's: the model is the same, only the solver differs. ``system`` carries the
    outlier caps the MAP was solved with; ``lin`` is its linearization at ``state`` when the
    caller has it. None when ``solver.error_covariance`` is off, there are no objects, or
    the information at ``state`` cannot be inverted (the map then reports the marginals).
    """
    config = keyframes.problem.solver.error_covariance
    if not (config.enabled and system.n_objects):
        return None
    lin = system.linearize(*state) if lin is None else lin
    try:
        result = object_error_covariance_about_trajectory(
            system, lin, state, keyframes.images_per_keyframe, config.bias_shares()
        )
    except ErrorCovarianceError as exc:
        logger.warning("no error covariances for this solution, the marginals stand in: %s", exc)
        return None
    return result.covariance


def _minimize(
    graph: AssociationSystem,
    state: _State,
    lin: Linearization,
    cfg: SolverConfig,
    max_iterations: int,
) -> tuple[_State, Linearization, Factorization | None, int, bool]:
    """Gauss-Newton steps while they work, Levenberg-Marquardt damping when they do not.

    The damping follows Nielsen (1999): after a step with gain ratio rho (actual over
    predicted decrease) it shrinks by max(1/3, 1 - (2 rho - 1)^3), after a failure it
    grows by a factor that doubles. Converged when a (nearly) undamped step predicts, or
    achieves, less than the tolerance; when a damped step predicts less, the undamped one
    is computed to tell an optimum from a step the damping made small. Objects no slice
    places are held (:func:`hold_lost_objects`). Returns the undamped factorization at the
    final state when the last one computed is that.
    """
    damping, growth = 0.0, 2.0
    iterations = 1
    restarted = np.zeros(graph.n_objects, dtype=bool)
    while iterations < max_iterations:
        lost = lost_objects(graph, lin)
        fresh = lost & ~restarted
        if fresh.any():
            iterations += 1
            state, lin = _restart(graph, state, lin, fresh)
            restarted |= fresh
            continue
        try:
            fac = factorize(graph, lin, damping)
        except np.linalg.LinAlgError:
            damping, growth = max(cfg.initial_lambda, damping * growth), 2.0 * growth
            if damping > cfg.max_lambda:
                break
            continue
        hold_lost_objects(lin, fac, damping, lost)
        tolerance = cfg.absolute_tolerance + cfg.relative_tolerance * lin.cost
        if fac.predicted_decrease <= tolerance:
            if damping <= cfg.initial_lambda:
                return state, lin, fac if damping == 0.0 else None, iterations, True
            # Where slices sit at their caps' edge or objects are barely placed, the undamped
            # step fails again and again, and the damping never came back down to
            # initial_lambda: such solves ran to their budget at an optimum.
            undamped = _undamped(graph, lin, lost)
            if undamped is not None and undamped.predicted_decrease <= tolerance:
                return state, lin, undamped, iterations, True
        poses, objects, calib = state
        new_poses = poses + fac.step_pose.reshape(-1, POSE_DIM)
        new_poses[:, 2] = wrap_angle(new_poses[:, 2])
        new_state = (new_poses, objects + fac.step_object.reshape(-1, OBJECT_DIM), calib + fac.step_calib)
        new_lin = graph.linearize(*new_state)
        iterations += 1
        if new_lin.valid and new_lin.cost <= lin.cost:
            decrease = lin.cost - new_lin.cost
            rho = decrease / max(fac.predicted_decrease, 1e-300)
            state, lin = new_state, new_lin
            # rho capped at 1, where the factor is 1/3 anyway: a decrease over a vanishing
            # prediction (lost objects held) overflowed the cube.
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * min(rho, 1.0) - 1.0) ** 3)
            growth = 2.0
            if damping < 1e-3 * cfg.initial_lambda:
                damping = 0.0
            if decrease <= tolerance and damping <= cfg.initial_lambda:
                return state, lin, None, iterations, True
        else:
            damping, growth = max(cfg.initial_lambda, damping * growth), 2.0 * growth
            if damping > cfg.max_lambda:
                break
    return state, lin, None, iterations, False


def _undamped(graph: AssociationSystem, lin: Linearization, lost: NDArray[np.bool_]) -> Factorization | None:
    """The undamped step at ``lin`` (``lost`` objects held), None where the information is not positive definite."""
    try:
        fac = factorize(graph, lin, 0.0)
    except np.linalg.LinAlgError:
        return None
    hold_lost_objects(lin, fac, 0.0, lost)
    return fac


def lost_objects(graph: AssociationSystem, lin: Linearization) -> NDArray[np.bool_]:
    """(K,) whether no slice of an object says where it is: its slices are all beyond their
    outlier caps (or on the free side of their bounds), its x, y held by its class prior alone."""
    if not graph.n_objects or not lin.valid:
        return np.zeros(graph.n_objects, dtype=bool)
    prior_information = graph.prior_inv_sigma[:, :2] ** 2
    information = lin.object_diag[:, [0, 1], [0, 1]]
    return np.all(information - prior_information <= LOST_INFORMATION_SHARE * prior_information, axis=1)


def _restart(
    graph: AssociationSystem, state: _State, lin: Linearization, lost: NDArray[np.bool_]
) -> tuple[_State, Linearization]:
    """``state`` with each ``lost`` object started again from its own slices at the current
    poses, where that lowers the cost; else unchanged (its horizontal step is then held)."""
    poses, objects, calib = state
    for j in np.flatnonzero(lost):
        moved = objects.copy()
        moved[j] = initial_object(graph.problem, graph.layout.groups[j], poses)
        moved_lin = graph.linearize(poses, moved, calib)
        if moved_lin.valid and moved_lin.cost < lin.cost:
            objects, lin = moved, moved_lin
    return (poses, objects, calib), lin


def hold_lost_objects(lin: Linearization, fac: Factorization, damping: float, lost: NDArray[np.bool_]) -> None:
    """Zero the horizontal step of every ``lost`` object (:func:`lost_objects` at ``lin``),
    none of whose slices says where it is.

    An object whose slices are all beyond their outlier caps (or all on the free side of
    their bounds) is held in x, y by its class prior alone (``xy_stddev_m`` about the first
    pose, 100 m by default): the Gauss-Newton step sends it there in one jump, through the
    places its slices would fit, and every such step fails; Marquardt damping scales with
    that prior's tiny information, so before it shrinks that step it has frozen every other
    variable, and the solve crept to its budget (docs/method.md, "Solves that do not
    converge"). No slice links those x, y to the rest of the system, so dropping their
    step is the step of the system with them held; the cost left is the prior's pull,
    (distance / xy_stddev_m)^2 / 2, 0.125 nats at 50 m.
    """
    if not lost.any():
        return
    step = fac.step_object.reshape(-1, OBJECT_DIM)
    held = step[lost, :2]
    grad = lin.grad_object.reshape(-1, OBJECT_DIM)[lost, :2]
    information = lin.object_diag[lost][:, [0, 1], [0, 1]]
    fac.predicted_decrease -= 0.5 * float(np.sum(-grad * held + damping * information * held**2))
    step[lost, :2] = 0.0
    fac.step_object = step.reshape(-1)


# An object's slices add no more than this share of its prior's information on x, y: lost.
LOST_INFORMATION_SHARE = 1e-9


class SolveOutcome(NamedTuple):
    """How a solve ended: what :class:`GraphSolution` reports beside the state."""

    iterations: int
    converged: bool
    log_evidence: float
    chi2: float
    log_det: float


# A solve that could not start (a pose inside an object's starting cylinder).
NOT_STARTED = SolveOutcome(iterations=0, converged=False, log_evidence=-np.inf, chi2=np.inf, log_det=np.nan)


class SolutionCovariances(NamedTuple):
    """Covariances of a solution (None where not computed)."""

    objects: NDArray | None = None  # (K, 5, 5) posterior marginals about the trajectory
    calibration: NDArray | None = None  # (C, C)
    errors: NDArray | None = None  # (K, 5, 5) of the estimates' errors


NO_COVARIANCES = SolutionCovariances()


def make_solution(
    keyframes: KeyframeGraph,
    layout: Layout,
    state: tuple[NDArray, NDArray, NDArray | None],
    outcome: SolveOutcome,
    covariances: SolutionCovariances = NO_COVARIANCES,
) -> GraphSolution:
    """The solution of a solve of ``keyframes.problem`` that ended at ``state``: graph poses,
    objects and odometry calibration (None: the prior mean)."""
    poses, objects, calibration = state
    covariance, error_covariance = covariances.objects, covariances.errors
    problem = keyframes.problem
    estimates = tuple(
        ObjectEstimate(
            label=problem.labels[int(layout.labels[j])],
            location_m=objects[j, :3],
            size_m=objects[j, 3:],
            measurement_indices=group,
            location_cov=None if covariance is None else covariance[j, :3, :3],
            size_cov=None if covariance is None else covariance[j, 3:, 3:],
            error_cov=None if error_covariance is None else error_covariance[j],
        )
        for j, group in enumerate(layout.groups)
    )
    object_of = np.full(problem.measurement_count, -1, dtype=np.int64)
    object_of[layout.measurements] = layout.object_of
    calibration = np.zeros(problem.calibration_dim) if calibration is None else np.array(calibration, dtype=float)
    map_T_base = keyframes.expand(poses)
    for array in (map_T_base, objects, object_of, calibration):
        array.flags.writeable = False
    return GraphSolution(
        map_T_base=map_T_base,
        objects=estimates,
        object_of_measurement=object_of,
        iterations=outcome.iterations,
        converged=outcome.converged,
        log_evidence=float(outcome.log_evidence),
        chi2=float(outcome.chi2),
        log_det_information=float(outcome.log_det),
        calibration=calibration,
        calibration_cov=covariances.calibration,
    )
