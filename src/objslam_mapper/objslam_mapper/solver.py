r"""Known-association solve: MAP, marginals and Laplace evidence of one association.

This is the inner loop of the association sampler, so it is built for speed: no
per-factor Python objects. For a given association (``groups``: one list of global
measurement indices per object) the nonlinear least-squares problem

    cost(theta) = 1/2 sum_k |e_k(theta)|^2_{Sigma_k}      (paper eqs. 6, 12-13)

over ``theta = (poses (N x 3), objects (K x 5))`` -- odometry factors, the first-pose
prior, one slice factor per assigned measurement (:mod:`slice_model`, analytic
Jacobians) and the class priors of every object -- is minimized by Gauss-Newton with a
Levenberg-Marquardt fallback, driven here over numpy arrays. Each linearization is
assembled vectorized over all measurements, and the normal equations are solved by
eliminating the poses first: their block is block-tridiagonal (a band of half-width 5,
LAPACK banded Cholesky) and the objects' Schur complement is small and dense. That is
exactly the square-root information GTSAM's multifrontal QR would give with the poses
ordered first, at a fraction of the cost.

The Laplace approximation of the evidence (paper eq. 25) at the MAP ``theta*`` is

    log P(Z_J | J) = -1/2 chi2(theta*) + sum_k -1/2 log|2 pi Sigma_k|
                     + d/2 log(2 pi) - 1/2 log|Lambda|,

summed over every factor of the graph (odometry, first-pose prior, assigned slices,
object priors), with ``d = 3N + 5K`` and ``Lambda = J^T Sigma^-1 J`` the Gauss-Newton
information at the MAP; ``log|Lambda| = log|A| + log|S|`` (pose block, object Schur
complement), i.e. ``2 log|R|`` of GTSAM's square-root information. Measurements in no
group are not part of the graph: the sampler scores them with its clutter model. A new
object pays its Occam price through its prior's normalizer and its ``5/2 log 2 pi -
1/2 log|information|``. The object marginal covariances are the blocks of ``S^-1``.

API (what the association sampler calls)::

    problem = build_problem(odometry, images, mount, catalog, config)   # objslam_mapper.problem
    solution = solve(problem, groups, warm_start=None, with_covariances=False)
    solution.log_evidence, solution.map_T_base, solution.objects[j].location_m, ...

``warm_start`` is a previous :class:`GraphSolution` of the same problem: its poses are
reused, and each new group starts from the previous object sharing most of its
measurements (a merge starts from its larger part, a split from the parent), or from
:func:`objslam_mapper.initialization.initial_object` when it shares none.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import lapack

from objslam_mapper.geometry import wrap_angle
from objslam_mapper.initialization import initial_object
from objslam_mapper.graph_config import SolverConfig
from objslam_mapper.problem import LOG_2PI, OBJECT_DIM, POSE_DIM, GraphError, GraphProblem
from objslam_mapper.slice_model import BEARING, predict_reduced

logger = logging.getLogger(__name__)

_BAND = 5  # upper bandwidth of the pose block: pose i couples with pose i+1 only


@dataclass(frozen=True, eq=False)
class ObjectEstimate:
    """One object of a solution: MAP location (x, y, z_base) and size (diameter, height), m.

    Covariances (m^2) are the marginals of the Laplace posterior, None unless asked for.
    """

    label: str
    location_m: NDArray[np.float64]
    size_m: NDArray[np.float64]
    measurement_indices: NDArray[np.int64]
    location_cov: NDArray[np.float64] | None = None
    size_cov: NDArray[np.float64] | None = None


@dataclass(frozen=True, eq=False)
class GraphSolution:
    """MAP estimate and Laplace evidence of one association.

    ``objects[j]`` belongs to ``groups[j]`` of the call. ``chi2`` is the total whitened
    squared error at the MAP, ``log_det_information`` is ``log|Lambda|``; ``iterations``
    counts linearizations. A solve that could not start (a pose inside an object's
    starting cylinder) has ``converged=False`` and ``log_evidence=-inf``.
    ``object_of_measurement`` (M,) gives each measurement's object number, -1 if none.
    """

    map_T_base: NDArray[np.float64]
    objects: tuple[ObjectEstimate, ...]
    object_of_measurement: NDArray[np.int64]
    iterations: int
    converged: bool
    log_evidence: float
    chi2: float
    log_det_information: float


@dataclass(frozen=True)
class _Layout:
    """Index arrays of one association, fixed for the whole solve (measurement axis last)."""

    groups: tuple[NDArray[np.int64], ...]
    measurements: NDArray[np.int64]  # (A,) assigned measurements, grouped by object
    object_of: NDArray[np.int64]
    pose_of: NDArray[np.int64]
    labels: NDArray[np.int64]  # (K,) label index of each object
    pose_bins: NDArray[np.int64]  # (3, 3, A) bins of the per-slice pose blocks in (N, 3, 3)
    pose_grad_bins: NDArray[np.int64]  # (3, A) bins in (N, 3)
    starts: NDArray[np.int64]  # (K,) where each object's run of measurements starts
    cross_bins: NDArray[np.int64]  # (3, 5, A) bins in the (3N, 5K) pose-object block


@dataclass
class _Linearization:
    cost: float
    valid: bool
    grad_pose: NDArray[np.float64] | None = None  # (3N,)
    grad_object: NDArray[np.float64] | None = None  # (5K,)
    pose_diag: NDArray[np.float64] | None = None  # (N, 3, 3)
    pose_off: NDArray[np.float64] | None = None  # (N-1, 3, 3): block (i, i+1)
    pose_object: NDArray[np.float64] | None = None  # (3N, 5K)
    object_diag: NDArray[np.float64] | None = None  # (K, 5, 5)


@dataclass
class _Factorization:
    chol_pose: NDArray[np.float64]  # upper banded Cholesky factor U of the pose block, A = U^T U
    chol_schur: NDArray[np.float64] | None  # upper Cholesky factor of the objects' Schur complement
    log_det: float
    step_pose: NDArray[np.float64]
    step_object: NDArray[np.float64]
    predicted_decrease: float


def _layout(problem: GraphProblem, groups: Sequence[ArrayLike]) -> _Layout:
    arrays = tuple(np.asarray(g, dtype=np.int64).reshape(-1) for g in groups)
    sizes = np.array([len(g) for g in arrays], dtype=np.int64)
    if np.any(sizes == 0):
        raise GraphError("every group must hold at least one measurement")
    measurements = np.concatenate(arrays) if arrays else np.zeros(0, dtype=np.int64)
    if len(measurements) and (measurements.min() < 0 or measurements.max() >= problem.measurement_count):
        raise GraphError(f"measurement indices must lie in [0, {problem.measurement_count})")
    if np.any(np.bincount(measurements, minlength=problem.measurement_count) > 1):
        raise GraphError("a measurement is assigned to more than one object (or twice to one)")
    object_of = np.repeat(np.arange(len(arrays), dtype=np.int64), sizes)
    label_of = problem.measurement_label[measurements]
    labels = label_of[np.cumsum(sizes) - sizes] if len(arrays) else np.zeros(0, dtype=np.int64)
    mixed = label_of != labels[object_of]
    if np.any(mixed):
        raise GraphError(f"group {int(object_of[np.argmax(mixed)])} mixes classes; an object holds one class")
    for g in arrays:
        g.flags.writeable = False
    pose_of = problem.measurement_pose[measurements]
    n_cols = OBJECT_DIM * len(arrays)
    p3, o5 = np.arange(POSE_DIM)[:, None], np.arange(OBJECT_DIM)[:, None]
    return _Layout(
        groups=arrays,
        measurements=measurements,
        object_of=object_of,
        pose_of=pose_of,
        labels=labels,
        pose_bins=(POSE_DIM * pose_of + p3)[:, None, :] * POSE_DIM + p3.T[:, :, None],
        pose_grad_bins=POSE_DIM * pose_of + p3,
        starts=np.cumsum(sizes) - sizes,
        cross_bins=(POSE_DIM * pose_of + p3)[:, None, :] * n_cols + (OBJECT_DIM * object_of + o5)[None, :, :],
    )


@functools.lru_cache(maxsize=8)
def _band_index(n_poses: int) -> tuple[tuple[NDArray, NDArray], NDArray, tuple[NDArray, NDArray], NDArray]:
    """Where the pose blocks go in LAPACK upper banded storage ab[BAND + i - j, j]."""
    p, a, b = np.meshgrid(np.arange(n_poses), np.arange(3), np.arange(3), indexing="ij")
    upper = (a <= b).ravel()
    diag_at = ((_BAND + a - b).ravel()[upper], (3 * p + b).ravel()[upper])
    diag_src = (9 * p + 3 * a + b).ravel()[upper]
    p, a, b = np.meshgrid(np.arange(max(n_poses - 1, 0)), np.arange(3), np.arange(3), indexing="ij")
    off_at = ((_BAND + a - b - 3).ravel(), (3 * p + 3 + b).ravel())
    off_src = (9 * p + 3 * a + b).ravel()
    return diag_at, diag_src, off_at, off_src


@functools.lru_cache(maxsize=32)
def _block_diag_index(n_blocks: int, size: int) -> tuple[NDArray, NDArray]:
    """(row, col) of the entries of n_blocks diagonal size x size blocks, block-major."""
    k, a, b = np.meshgrid(np.arange(n_blocks), np.arange(size), np.arange(size), indexing="ij")
    return (size * k + a).ravel(), (size * k + b).ravel()


# A slice factor's 8 variables (pose x, y, theta | location x, y, z_base | diameter, height)
# enter its 4 components through the 6 reduced columns of slice_model.predict_reduced
# (delta_x, delta_y, theta, z_base, d, H): pose x, y as -delta, location x, y as +delta.
_POSE_SIGN = np.array([-1.0, -1.0, 1.0])
_OBJECT_COLUMNS = np.array([0, 1, 3, 4, 5])


def _bin_sum(bins: NDArray[np.int64], values: NDArray[np.float64], shape: tuple[int, ...]) -> NDArray[np.float64]:
    """Sum ``values`` into a zero array of ``shape`` at the flat positions ``bins`` (same shape as values)."""
    size = int(np.prod(shape))
    return np.bincount(bins.ravel(), weights=values.ravel(), minlength=size).reshape(shape)


class _Graph:
    """Residuals and normal equations of one association over a fixed layout."""

    def __init__(self, problem: GraphProblem, layout: _Layout):
        self.problem = problem
        self.layout = layout
        self.n_poses = problem.pose_count
        self.n_objects = len(layout.labels)
        self.z = np.ascontiguousarray(problem.measurements[layout.measurements].T)  # (4, A)
        self.inv_sigma = np.ascontiguousarray(1.0 / problem.measurement_stddev[layout.measurements].T)
        self.inc_inv_sigma = 1.0 / problem.increment_stddev
        self.prior_mean = problem.prior_mean[layout.labels]
        self.prior_inv_sigma = 1.0 / problem.prior_stddev[layout.labels]
        self.log_normalizer = (
            problem.trajectory_log_normalizer
            + float(np.sum(problem.measurement_log_normalizer[layout.measurements]))
            + float(np.sum(problem.prior_log_normalizer[layout.labels]))
        )

    @property
    def dimension(self) -> int:
        return POSE_DIM * self.n_poses + OBJECT_DIM * self.n_objects

    def _odometry(self, poses: NDArray) -> tuple[float, NDArray, NDArray, NDArray, NDArray]:
        """Odometry factors: cost, and their normal-equation blocks in closed form.

        Error ``e = (R_i^T (t_j - t_i) - u_xy, wrap(theta_j - theta_i - u_theta))``, whitened
        by ``w`` (x, y) and ``w_t`` (theta). With ``d = t_j - t_i`` the Gram blocks are
        ``Ji^T Ji = w^2 [[1, 0, -d_y], [0, 1, d_x], [-d_y, d_x, |d|^2]] + w_t^2 e3 e3^T``,
        ``Jj^T Jj = diag(w^2, w^2, w_t^2)``, ``Ji^T Jj = [[-w^2, 0, 0], [0, -w^2, 0],
        [w^2 d_y, -w^2 d_x, -w_t^2]]``. Returns (cost, diag_i, diag_j, off, grad (N, 3)).
        """
        pi, pj = poses[:-1], poses[1:]
        c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
        dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
        u = self.problem.increments
        w, wt = self.inc_inv_sigma[:, 0], self.inc_inv_sigma[:, 2]
        e1 = w * (c * dx + s * dy - u[:, 0])
        e2 = w * (-s * dx + c * dy - u[:, 1])
        e3 = wt * wrap_angle(pj[:, 2] - pi[:, 2] - u[:, 2])
        cost = 0.5 * float(np.sum(e1 * e1) + np.sum(e2 * e2) + np.sum(e3 * e3))
        w2, wt2 = w * w, wt * wt
        m = len(pi)
        diag_i = np.zeros((m, 3, 3))
        diag_i[:, 0, 0] = diag_i[:, 1, 1] = w2
        diag_i[:, 0, 2] = diag_i[:, 2, 0] = -w2 * dy
        diag_i[:, 1, 2] = diag_i[:, 2, 1] = w2 * dx
        diag_i[:, 2, 2] = w2 * (dx * dx + dy * dy) + wt2
        diag_j = np.zeros((m, 3, 3))
        diag_j[:, 0, 0] = diag_j[:, 1, 1] = w2
        diag_j[:, 2, 2] = wt2
        off = np.zeros((m, 3, 3))
        off[:, 0, 0] = off[:, 1, 1] = -w2
        off[:, 2, 0] = w2 * dy
        off[:, 2, 1] = -w2 * dx
        off[:, 2, 2] = -wt2
        a, b = -s * dx + c * dy, -c * dx - s * dy  # d(R_i^T d)/d theta_i
        grad = np.zeros((m + 1, 3))
        grad[:-1, 0] = w * (-c * e1 + s * e2)
        grad[:-1, 1] = w * (-s * e1 - c * e2)
        grad[:-1, 2] = w * (a * e1 + b * e2) - wt * e3
        grad[1:, 0] += w * (c * e1 - s * e2)
        grad[1:, 1] += w * (s * e1 + c * e2)
        grad[1:, 2] += wt * e3
        return cost, diag_i, diag_j, off, grad

    def linearize(self, poses: NDArray, objects: NDArray) -> _Linearization:
        n, k = self.n_poses, self.n_objects
        lay = self.layout
        obj = objects[lay.object_of]
        pred = predict_reduced(poses[lay.pose_of], obj[:, :3], obj[:, 3:], self.problem.mount)
        if not np.all(pred.valid):
            return _Linearization(cost=np.inf, valid=False)
        sl = pred.values - self.z
        sl[BEARING] = wrap_angle(sl[BEARING])
        sl *= self.inv_sigma
        jac = pred.jacobian * self.inv_sigma[:, None, :]  # (4, 6, A)
        jac_pose = jac[:, :3] * _POSE_SIGN[None, :, None]  # (4, 3, A)
        jac_object = jac[:, _OBJECT_COLUMNS]  # (4, 5, A)
        odo_cost, diag_i, diag_j, pose_off, grad_pose = self._odometry(poses)
        first = poses[0] - self.problem.odometry_poses[0]
        first[2] = wrap_angle(first[2])
        first /= self.problem.first_pose_stddev
        pr = (objects - self.prior_mean) * self.prior_inv_sigma
        cost = odo_cost + 0.5 * float(np.sum(first**2) + np.sum(sl**2) + np.sum(pr**2))

        pose_diag = _bin_sum(lay.pose_bins, np.einsum("kim,kjm->ijm", jac_pose, jac_pose), (n, 3, 3))
        pose_diag[:-1] += diag_i
        pose_diag[1:] += diag_j
        pose_diag[0] += np.diag(self.problem.first_pose_stddev**-2)
        grad_pose += _bin_sum(lay.pose_grad_bins, np.einsum("kim,km->im", jac_pose, sl), (n, 3))
        grad_pose[0] += first / self.problem.first_pose_stddev

        # Measurements are grouped by object: per-object sums are contiguous runs.
        object_diag = np.add.reduceat(np.einsum("kim,kjm->ijm", jac_object, jac_object), lay.starts, axis=2)
        object_diag = np.ascontiguousarray(object_diag.transpose(2, 0, 1)) if k else np.zeros((0, 5, 5))
        object_diag[:, np.arange(OBJECT_DIM), np.arange(OBJECT_DIM)] += self.prior_inv_sigma**2
        grad_object = pr * self.prior_inv_sigma
        if k:
            grad_object += np.add.reduceat(np.einsum("kim,km->im", jac_object, sl), lay.starts, axis=1).T
        cross = np.einsum("kim,kjm->ijm", jac_pose, jac_object)
        pose_object = _bin_sum(lay.cross_bins, cross, (POSE_DIM * n, OBJECT_DIM * k))
        return _Linearization(
            cost, True, grad_pose.ravel(), grad_object.ravel(), pose_diag, pose_off, pose_object, object_diag
        )

    def factorize(self, lin: _Linearization, damping: float) -> _Factorization:
        """Solve the (damped) normal equations by the objects' Schur complement.

        With A = U^T U the pose block, W = U^-T B and w = U^-T g_pose:
        S = C - W^T W, step_object = S^-1 (W^T w - g_object),
        step_pose = -U^-1 (w + W step_object). Raises LinAlgError if not positive definite.
        """
        n, k = self.n_poses, self.n_objects
        diag_at, diag_src, off_at, off_src = _band_index(n)
        pose_diag, object_diag = lin.pose_diag, lin.object_diag
        if damping > 0.0:
            # Marquardt: scale-invariant damping of the diagonal.
            pose_diag, object_diag = pose_diag.copy(), object_diag.copy()
            i3, i5 = np.arange(POSE_DIM), np.arange(OBJECT_DIM)
            pose_diag[:, i3, i3] *= 1.0 + damping
            object_diag[:, i5, i5] *= 1.0 + damping
        band = np.zeros((_BAND + 1, POSE_DIM * n))
        band[diag_at] = pose_diag.ravel()[diag_src]
        band[off_at] = lin.pose_off.ravel()[off_src]
        chol_pose = scipy.linalg.cholesky_banded(band, lower=False, check_finite=False)
        log_det = 2.0 * float(np.sum(np.log(chol_pose[_BAND])))
        rhs = np.empty((POSE_DIM * n, OBJECT_DIM * k + 1), order="F")
        rhs[:, :-1] = lin.pose_object
        rhs[:, -1] = lin.grad_pose
        whitened, info = lapack.dtbtrs(chol_pose, rhs, uplo="U", trans="T", overwrite_b=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
        w_cross, w_grad = whitened[:, :-1], whitened[:, -1]
        chol_schur = None
        step_object = np.zeros(0)
        if k:
            schur = -(w_cross.T @ w_cross)
            schur[_block_diag_index(k, OBJECT_DIM)] += object_diag.ravel()
            chol_schur = scipy.linalg.cholesky(schur, lower=False, check_finite=False)
            log_det += 2.0 * float(np.sum(np.log(np.diag(chol_schur))))
            step_object = scipy.linalg.cho_solve(
                (chol_schur, False), w_cross.T @ w_grad - lin.grad_object, check_finite=False
            )
        back, info = lapack.dtbtrs(chol_pose, (w_grad + w_cross @ step_object)[:, None], uplo="U", trans="N")
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
        step_pose = -back[:, 0]
        # Decrease of the quadratic model: 1/2 (-g^T step + damping step^T diag(Lambda) step).
        predicted = -float(lin.grad_pose @ step_pose + lin.grad_object @ step_object)
        if damping > 0.0:
            i3, i5 = np.arange(POSE_DIM), np.arange(OBJECT_DIM)
            predicted += damping * float(
                lin.pose_diag[:, i3, i3].ravel() @ step_pose**2 + lin.object_diag[:, i5, i5].ravel() @ step_object**2
            )
        predicted *= 0.5
        return _Factorization(chol_pose, chol_schur, log_det, step_pose, step_object, predicted)

    def object_covariance(self, fac: _Factorization) -> NDArray[np.float64]:
        """(K, 5, 5) marginal covariance blocks of the objects (from S^-1)."""
        k = self.n_objects
        if not k:
            return np.zeros((0, OBJECT_DIM, OBJECT_DIM))
        inv = scipy.linalg.cho_solve((fac.chol_schur, False), np.eye(OBJECT_DIM * k), check_finite=False)
        blocks = inv.reshape(k, OBJECT_DIM, k, OBJECT_DIM)
        return blocks[np.arange(k), :, np.arange(k), :]


def _initial_state(problem: GraphProblem, layout: _Layout, warm_start: GraphSolution | None) -> tuple[NDArray, NDArray]:
    if warm_start is None:
        poses = np.array(problem.odometry_poses)
    else:
        poses = np.array(warm_start.map_T_base, dtype=float)
        if poses.shape != problem.odometry_poses.shape:
            raise GraphError(f"warm start has {len(poses)} poses, the problem {problem.pose_count}")
    objects = np.empty((len(layout.groups), OBJECT_DIM))
    for j, group in enumerate(layout.groups):
        owners = warm_start.object_of_measurement[group] if warm_start is not None else group[:0]
        owners = owners[owners >= 0]
        if len(owners):
            prev = warm_start.objects[int(np.argmax(np.bincount(owners)))]
            objects[j, :3], objects[j, 3:] = prev.location_m, prev.size_m
        else:
            objects[j] = initial_object(problem, group, poses)
    return poses, objects


def solve(
    problem: GraphProblem,
    groups: Sequence[ArrayLike],
    warm_start: GraphSolution | None = None,
    *,
    with_covariances: bool = False,
    max_iterations: int | None = None,
) -> GraphSolution:
    """MAP, evidence and (optionally) object marginals of the association ``groups``.

    ``groups[j]`` lists the global measurement indices of object j (sequence or integer
    array; one class per group, no measurement twice). Measurements in no group are left
    out of the graph. ``max_iterations`` overrides ``solver.max_iterations`` for this call
    (a sampler may cap hopeless proposals: an unconverged solution reports the evidence
    at its last iterate, which is below that of the optimum up to the log-determinant).
    """
    layout = _layout(problem, groups)
    graph = _Graph(problem, layout)
    poses, objects = _initial_state(problem, layout, warm_start)

    lin = graph.linearize(poses, objects)
    if not lin.valid:
        logger.debug("solve cannot start: a pose lies inside an object's starting cylinder")
        return _solution(problem, layout, poses, objects, 0, False, -np.inf, np.inf, np.nan, None)
    limit = problem.solver.max_iterations if max_iterations is None else max_iterations
    poses, objects, lin, final, iterations, converged = _minimize(graph, poses, objects, lin, problem.solver, limit)
    if final is None:
        final = graph.factorize(lin, 0.0)
    if not converged:
        logger.debug("solve stopped after %d linearizations without converging (cost %.6g)", iterations, lin.cost)

    log_evidence = -lin.cost + graph.log_normalizer + 0.5 * graph.dimension * LOG_2PI - 0.5 * final.log_det
    covariance = graph.object_covariance(final) if with_covariances else None
    return _solution(
        problem, layout, poses, objects, iterations, converged, log_evidence, 2.0 * lin.cost, final.log_det, covariance
    )


def _minimize(
    graph: _Graph,
    poses: NDArray,
    objects: NDArray,
    lin: _Linearization,
    cfg: SolverConfig,
    max_iterations: int,
) -> tuple[NDArray, NDArray, _Linearization, _Factorization | None, int, bool]:
    """Gauss-Newton steps while they work, Levenberg-Marquardt damping when they do not.

    The damping follows Nielsen (1999): after a step with gain ratio rho (actual over
    predicted decrease) it shrinks by max(1/3, 1 - (2 rho - 1)^3), after a failure it
    grows by a factor that doubles. Converged when a (nearly) undamped step predicts, or
    achieves, less than the tolerance. Returns the undamped factorization at the final
    state when the last one computed is that.
    """
    damping, growth = 0.0, 2.0
    iterations = 1
    while iterations < max_iterations:
        try:
            fac = graph.factorize(lin, damping)
        except np.linalg.LinAlgError:
            damping, growth = max(cfg.initial_lambda, damping * growth), 2.0 * growth
            if damping > cfg.max_lambda:
                break
            continue
        tolerance = cfg.absolute_tolerance + cfg.relative_tolerance * lin.cost
        if fac.predicted_decrease <= tolerance and damping <= cfg.initial_lambda:
            return poses, objects, lin, fac if damping == 0.0 else None, iterations, True
        new_poses = poses + fac.step_pose.reshape(-1, POSE_DIM)
        new_poses[:, 2] = wrap_angle(new_poses[:, 2])
        new_objects = objects + fac.step_object.reshape(-1, OBJECT_DIM)
        new_lin = graph.linearize(new_poses, new_objects)
        iterations += 1
        if new_lin.valid and new_lin.cost <= lin.cost:
            decrease = lin.cost - new_lin.cost
            rho = decrease / max(fac.predicted_decrease, 1e-300)
            poses, objects, lin = new_poses, new_objects, new_lin
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            growth = 2.0
            if damping < 1e-3 * cfg.initial_lambda:
                damping = 0.0
            if decrease <= tolerance and damping <= cfg.initial_lambda:
                return poses, objects, lin, None, iterations, True
        else:
            damping, growth = max(cfg.initial_lambda, damping * growth), 2.0 * growth
            if damping > cfg.max_lambda:
                break
    return poses, objects, lin, None, iterations, False


def _solution(
    problem: GraphProblem,
    layout: _Layout,
    poses: NDArray,
    objects: NDArray,
    iterations: int,
    converged: bool,
    log_evidence: float,
    chi2: float,
    log_det: float,
    covariance: NDArray | None,
) -> GraphSolution:
    estimates = tuple(
        ObjectEstimate(
            label=problem.labels[int(layout.labels[j])],
            location_m=objects[j, :3],
            size_m=objects[j, 3:],
            measurement_indices=group,
            location_cov=None if covariance is None else covariance[j, :3, :3],
            size_cov=None if covariance is None else covariance[j, 3:, 3:],
        )
        for j, group in enumerate(layout.groups)
    )
    object_of = np.full(problem.measurement_count, -1, dtype=np.int64)
    object_of[layout.measurements] = layout.object_of
    for array in (poses, objects, object_of):
        array.flags.writeable = False
    return GraphSolution(
        map_T_base=poses,
        objects=estimates,
        object_of_measurement=object_of,
        iterations=iterations,
        converged=converged,
        log_evidence=float(log_evidence),
        chi2=float(chi2),
        log_det_information=float(log_det),
    )
