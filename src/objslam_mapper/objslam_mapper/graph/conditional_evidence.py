r"""One object's Laplace evidence with the robot's poses held fixed (the sampler's cheap screen).

With the poses fixed at ``P`` the factor graph of an association falls apart into one
small problem per object: its slice factors and its class prior over its 5 variables
(x, y, z_base, diameter, height), and a distractor's floor factor. Its Laplace evidence is

    log e_P(G) = -cost_G(o*) + sum_{k in G} -1/2 log|2 pi Sigma_k| + prior normalizer
                 + 5/2 log 2 pi - 1/2 log|Lambda_oo(o*)|,

the same terms as :mod:`objslam_mapper.graph.solver`'s evidence, restricted to one object and
conditioned on the poses. The evidence of a whole association conditioned on ``P`` is the
sum over its objects plus a term that does not depend on the association, so the
difference between two associations that differ by one move only needs the objects the
move touches: a few 5-variable solves instead of a graph of every pose. The odometry
calibration (when the graph estimates it) enters only the odometry factors and its prior,
which no association changes: it is held fixed with the poses and drops out with them.

The sampler uses it as the first stage of a delayed-acceptance Metropolis-Hastings step
(:mod:`objslam_mapper.inference.chain`): it is an approximation of the target, never the target.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from objslam_mapper.graph.linearize import OBJECT_COLUMNS
from objslam_mapper.graph.problem import LOG_2PI, OBJECT_DIM, GraphProblem
from objslam_mapper.model.floor import floor_jacobian, floor_residual
from objslam_mapper.model.outliers import WARM_START_CAP_SCALES, half_chi2, truncate
from objslam_mapper.model.slice_model import predict_reduced, whitened_slice_error

_MAX_LAMBDA = 1e8


@dataclass(frozen=True)
class ObjectEvidence:
    """log e_P(G) and the object's conditional MAP (x, y, z_base, diameter, height)."""

    log_evidence: float
    object_state: NDArray[np.float64]
    iterations: int
    converged: bool


class ObjectLinearization(NamedTuple):
    """One object's cost, gradient (5,) and Gauss-Newton information (5, 5) at fixed poses."""

    cost: float
    grad: NDArray[np.float64]
    info: NDArray[np.float64]
    outliers: int  # slices beyond their true cap

    @property
    def valid(self) -> bool:
        """False where the model is undefined (a pose inside the object)."""
        return len(self.grad) > 0


class _ObjectSystem:
    """Whitened slice residuals and object prior of one group at fixed poses."""

    def __init__(
        self, problem: GraphProblem, poses: NDArray[np.float64], group: NDArray[np.int64], prior: int | None = None
    ):
        row = int(problem.measurement_label[group[0]]) if prior is None else int(prior)
        self.poses = np.ascontiguousarray(poses[problem.measurement_pose[group]])
        self.z = np.ascontiguousarray(problem.measurements[group].T)
        self.inv_sigma = np.ascontiguousarray(1.0 / problem.measurement_stddev[group].T)
        self.bounds = problem.measurement_bounds[group]
        self.outlier_cost = problem.measurement_outlier_cost[group]
        self.has_outlier_model = bool(np.isfinite(self.outlier_cost).any())
        self.cap_scale = 1.0  # as AssociationSystem.cap_scale
        self.prior_mean = problem.prior_mean[row]
        self.prior_inv_sigma = 1.0 / problem.prior_stddev[row]
        self.floor_inv_sigma = 1.0 / problem.prior_floor_stddev[row]  # 0: no floor factor
        self.mount = problem.mount
        self.log_normalizer = float(np.sum(problem.measurement_log_normalizer[group])) + float(
            problem.prior_log_normalizer[row]
        )

    def linearize(self, state: NDArray[np.float64]) -> ObjectLinearization:
        """Cost, gradient, Gauss-Newton information and slices beyond their true cap; not
        ``valid`` where the model is undefined."""
        pred = predict_reduced(self.poses, state[:3], state[3:], self.mount)
        if not np.all(pred.valid):
            return ObjectLinearization(math.inf, np.zeros(0), np.zeros((0, 0)), len(self.z[0]))
        res, weight = whitened_slice_error(pred.values, self.z, self.inv_sigma, self.bounds)
        half = half_chi2(res)
        outliers = int(np.count_nonzero(half > self.outlier_cost))
        if self.has_outlier_model and self.cap_scale < np.inf:
            weight = weight * truncate(res, self.outlier_cost * self.cap_scale, half)
        jac = pred.jacobian[:, OBJECT_COLUMNS] * weight[:, None, :]  # (4, 5, A)
        prior = (state - self.prior_mean) * self.prior_inv_sigma
        floor = float(floor_residual(state[2], self.floor_inv_sigma))
        floor_jac = float(floor_jacobian(state[2], self.floor_inv_sigma))
        cost = 0.5 * float(np.sum(res * res) + prior @ prior + floor * floor)
        flat = jac.transpose(1, 0, 2).reshape(OBJECT_DIM, -1)
        info = flat @ flat.T
        info[np.diag_indices(OBJECT_DIM)] += self.prior_inv_sigma**2
        info[2, 2] += floor_jac**2
        grad = flat @ res.ravel() + prior * self.prior_inv_sigma
        grad[2] += floor * floor_jac
        return ObjectLinearization(cost, grad, info, outliers)


def object_information(
    problem: GraphProblem,
    poses: NDArray[np.float64],
    group: NDArray[np.int64],
    state: NDArray[np.float64],
    prior: int | None = None,
) -> NDArray[np.float64] | None:
    """(5, 5) information of one object at ``state`` with the poses fixed (None where undefined)."""
    linearized = _ObjectSystem(problem, poses, np.asarray(group, dtype=np.int64), prior).linearize(state)
    return linearized.info if linearized.valid else None


def object_evidence(
    problem: GraphProblem,
    poses: NDArray[np.float64],
    group: NDArray[np.int64],
    start: NDArray[np.float64],
    *,
    max_iterations: int = 20,
    relative_tolerance: float = 1e-6,
    absolute_tolerance: float = 1e-6,
    prior: int | None = None,
) -> ObjectEvidence:
    """Levenberg-Marquardt on one object at fixed ``poses``, then its Laplace evidence.

    ``prior`` is the object's prior row (default: its class's), as ``solver.solve``'s ``priors``.

    ``start`` (5,) is the starting object; an unusable start (a pose inside it) or a
    solve that never becomes valid gives ``-inf``. An unconverged solve reports the
    evidence at its last iterate, as :func:`objslam_mapper.graph.solver.solve` does.
    """
    system = _ObjectSystem(problem, poses, np.asarray(group, dtype=np.int64), prior)
    state = np.array(start, dtype=float)
    tolerances = (absolute_tolerance, relative_tolerance)
    # As solver.solve from a warm start: the poses are a MAP's, the start near the object.
    iterations, converged, outliers = 0, False, 0
    for phase, scale in enumerate(WARM_START_CAP_SCALES):
        if phase and not (system.has_outlier_model and outliers):
            break
        system.cap_scale = scale
        linearized = system.linearize(state)
        if not linearized.valid:
            return ObjectEvidence(-math.inf, state, 0, False)
        state, linearized, more, converged = _minimize(system, state, linearized, max_iterations, tolerances)
        cost, _, info, outliers = linearized
        iterations += more
    sign, log_det = np.linalg.slogdet(info)
    if sign <= 0.0:
        return ObjectEvidence(-math.inf, state, iterations, False)
    log_evidence = -cost + system.log_normalizer + 0.5 * OBJECT_DIM * LOG_2PI - 0.5 * float(log_det)
    return ObjectEvidence(float(log_evidence), state, iterations, converged)


def _minimize(
    system: _ObjectSystem,
    state: NDArray[np.float64],
    linearized: ObjectLinearization,
    max_iterations: int,
    tolerances: tuple[float, float],
) -> tuple[NDArray[np.float64], ObjectLinearization, int, bool]:
    """Levenberg-Marquardt from a valid ``state`` and its ``linearized`` (as
    ``_ObjectSystem.linearize``): (state, its linearization, linearizations, converged)."""
    absolute_tolerance, relative_tolerance = tolerances
    cost, grad, info, _ = linearized
    damping, iterations, converged = 0.0, 1, False
    while iterations < max_iterations:
        damped = info + damping * np.diag(np.diag(info))
        try:
            step = np.linalg.solve(damped, -grad)
        except np.linalg.LinAlgError:
            damping = max(1e-4, 10.0 * damping)
            if damping > _MAX_LAMBDA:
                break
            continue
        predicted = -0.5 * float(grad @ step)
        if predicted <= absolute_tolerance + relative_tolerance * cost and damping == 0.0:
            converged = True
            break
        new_state = state + step
        new = system.linearize(new_state)
        iterations += 1
        if new.valid and new.cost <= cost:
            state, linearized = new_state, new
            cost, grad, info, _ = new
            damping = 0.0 if damping < 1e-3 else damping / 10.0
        else:
            damping = max(1e-4, 10.0 * damping)
            if damping > _MAX_LAMBDA:
                break
    return state, linearized, iterations, converged
