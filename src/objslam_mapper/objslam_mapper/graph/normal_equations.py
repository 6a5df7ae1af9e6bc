r"""Normal equations of one association: assembled vectorized, solved by sparse elimination.

The variables are the poses (N x 3, additive x, y, theta) and the objects (K x 5:
x, y, z_base, diameter, height). The factors are the odometry factors between
consecutive poses, the first-pose prior, one slice factor per assigned measurement
(:mod:`objslam_mapper.model.slice_model`) and one class prior per object; all residuals are
whitened.

When the problem estimates the odometry calibration (``problem.calibration_dim == 3``),
one more variable ``c = (s_d, s_t, b)`` (distance scale, turn scale, turn bias per metre
of measured path ``L``) enters every odometry factor, which then predicts the measured
increment ``u`` from the true one between the poses, in the frame of pose i:

    u_xy    = (1 + s_d) R_i^T (t_j - t_i)
    u_theta = (1 + s_t) wrap(theta_j - theta_i) + b L

(a wheel-diameter error scales every distance, a wheelbase error every turn, a
left/right diameter mismatch adds a turn per metre; ``L`` is the odometry's own path
length of the increment, so ``b`` multiplies a constant: the true length differs from it
by ``s_d L``, a second-order term). ``c`` has a zero-mean Gaussian prior. It couples with
every pose, so it joins the objects in the dense block: the Schur complement is over
``(objects, c)`` and the sparse system gets 3 dense rows and columns.
:class:`AssociationSystem` evaluates the cost and the Gauss-Newton system
``Lambda step = -g`` (``Lambda = J^T J``) with numpy over all measurements at once, with
the measurement axis last so every operation runs over contiguous arrays.

Two ways solve it, both exact (``log|Lambda|`` is what GTSAM's ``2 log|R|`` gives):

- up to ``solver.dense_object_limit`` objects, by eliminating the poses first. Their
  block ``A`` is block-tridiagonal: a band of half-width 5, factored by LAPACK's banded
  Cholesky (``A = U^T U``). With ``B`` the pose-object block and ``C`` the object block,
  ``W = U^-T B`` gives the objects' Schur complement ``S = C - W^T W`` (dense, 5K x 5K),
  ``log|Lambda| = log|A| + log|S|``, and the object marginal covariances are the blocks of
  ``S^-1``. This is the fast path for a map's worth of long-lived objects.
- beyond, by a sparse LU (SuperLU, minimum-degree ordering, symmetric mode without
  pivoting, which is Cholesky in disguise for a positive definite matrix): many small
  objects (tracklets seen over a few poses) are then eliminated into the pose band
  instead of making the dense Schur complement (cubic in K) large.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg
from numpy.typing import ArrayLike, NDArray
from objslam_common.geometry import wrap_angle
from scipy.linalg import lapack

from objslam_mapper.graph.error_covariance import ErrorCovariance, NoiseGroup, error_covariance
from objslam_mapper.graph.gauge import GAUGE_DIM, about_trajectory, object_motion, trajectory_gauge
from objslam_mapper.graph.problem import CALIBRATION_DIM, OBJECT_DIM, POSE_DIM, GraphError, GraphProblem
from objslam_mapper.model.outliers import (
    COLD_START_CAP_SCALES,
    WARM_START_CAP_SCALES,
    WARM_START_MAX_BEYOND,
    half_chi2,
    truncate,
)
from objslam_mapper.model.slice_model import COMPONENTS, ReducedPrediction, predict_reduced, whitened_slice_error

_BAND = 5  # upper bandwidth of the pose block: pose i couples with pose i+1 only


@dataclass(frozen=True)
class Layout:
    """Index arrays of one association, fixed for the whole solve (measurement axis last)."""

    n_poses: int
    n_calib: int  # 3 with the odometry calibration as a variable, else 0
    groups: tuple[NDArray[np.int64], ...]
    measurements: NDArray[np.int64]  # (A,) assigned measurements, grouped by object
    object_of: NDArray[np.int64]
    pose_of: NDArray[np.int64]
    labels: NDArray[np.int64]  # (K,) label index of each object
    priors: NDArray[np.int64]  # (K,) prior row of each object (its class's unless given)
    pose_bins: NDArray[np.int64]  # (3, 3, A) bins of the per-slice pose blocks in (N, 3, 3)
    pose_grad_bins: NDArray[np.int64]  # (3, A) bins in (N, 3)
    starts: NDArray[np.int64]  # (K,) where each object's run of measurements starts
    cross_bins: NDArray[np.int64]  # (3, 5, A) bins in the (3N, 5K) pose-object block
    cross_unique: bool  # no image saw one object twice: the cross blocks need no summing

    @property
    def n_objects(self) -> int:
        return len(self.groups)

    @functools.cached_property
    def sparse(self) -> _SparsePattern:
        return _SparsePattern.of(self)


@dataclass
class Linearization:
    """Cost and normal equations at one state (``valid`` False: the model is undefined there)."""

    cost: float
    valid: bool
    outliers: int = 0  # slices beyond their (unscaled) outlier cost
    grad_pose: NDArray[np.float64] | None = None  # (3N,)
    grad_object: NDArray[np.float64] | None = None  # (5K,)
    pose_diag: NDArray[np.float64] | None = None  # (N, 3, 3)
    pose_off: NDArray[np.float64] | None = None  # (N-1, 3, 3): block (i, i+1)
    cross: NDArray[np.float64] | None = None  # (3, 5, A) pose-object block of each slice
    object_diag: NDArray[np.float64] | None = None  # (K, 5, 5)
    grad_calib: NDArray[np.float64] | None = None  # (C,) C = 3 with the calibration, else 0
    pose_calib: NDArray[np.float64] | None = None  # (N, 3, C) pose-calibration blocks
    calib_diag: NDArray[np.float64] | None = None  # (C, C)
    _pose_object: NDArray[np.float64] | None = field(default=None, repr=False)

    def pose_object(self, layout: Layout) -> NDArray[np.float64]:
        """The dense (3N, 5K) pose-object block (built once)."""
        if self._pose_object is None:
            shape = (POSE_DIM * layout.n_poses, OBJECT_DIM * layout.n_objects)
            if layout.cross_unique:
                block = np.zeros(shape)
                block.ravel()[layout.cross_bins.ravel()] = self.cross.ravel()
            else:
                block = _bin_sum(layout.cross_bins, self.cross, shape)
            self._pose_object = block
        return self._pose_object

    def diagonal(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Diagonals of the pose (3N,), object (5K,) and calibration (C,) blocks."""
        i3, i5 = np.arange(POSE_DIM), np.arange(OBJECT_DIM)
        return self.pose_diag[:, i3, i3].ravel(), self.object_diag[:, i5, i5].ravel(), np.diag(self.calib_diag)


@dataclass
class Factorization:
    """A solved (damped) system: step, log-determinant, and what the covariances need."""

    log_det: float
    step_pose: NDArray[np.float64]
    step_object: NDArray[np.float64]
    predicted_decrease: float
    step_calib: NDArray[np.float64]  # (C,)
    chol_schur: NDArray[np.float64] | None = None  # dense path: upper Cholesky factor of S (objects, then c)
    chol_pose: NDArray[np.float64] | None = None  # dense path: banded upper Cholesky factor U of the pose block
    w_cross: NDArray[np.float64] | None = None  # dense path: W = U^-T B
    sparse_lu: scipy.sparse.linalg.SuperLU | None = None  # sparse path


def layout_of(problem: GraphProblem, groups: Sequence[ArrayLike], priors: ArrayLike | None = None) -> Layout:
    """Validate an association (one array of measurement indices per object) and index it.

    ``priors[j]`` is the prior row of object j (``problem.prior_mean``); default its class's.
    """
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
    if priors is None:
        prior_rows = labels.copy()
    else:
        prior_rows = np.asarray(priors, dtype=np.int64).reshape(-1)
        if len(prior_rows) != len(arrays):
            raise GraphError(f"{len(prior_rows)} prior rows for {len(arrays)} groups")
        if len(prior_rows) and (prior_rows.min() < 0 or prior_rows.max() >= len(problem.prior_mean)):
            raise GraphError(f"prior rows must lie in [0, {len(problem.prior_mean)})")
    for g in arrays:
        g.flags.writeable = False
    pose_of = problem.measurement_pose[measurements]
    n_cols = OBJECT_DIM * len(arrays)
    p3, o5 = np.arange(POSE_DIM)[:, None], np.arange(OBJECT_DIM)[:, None]
    return Layout(
        n_poses=problem.pose_count,
        n_calib=problem.calibration_dim,
        groups=arrays,
        measurements=measurements,
        object_of=object_of,
        pose_of=pose_of,
        labels=labels,
        priors=prior_rows,
        pose_bins=(POSE_DIM * pose_of + p3)[:, None, :] * POSE_DIM + p3.T[:, :, None],
        pose_grad_bins=POSE_DIM * pose_of + p3,
        starts=np.cumsum(sizes) - sizes,
        cross_bins=(POSE_DIM * pose_of + p3)[:, None, :] * n_cols + (OBJECT_DIM * object_of + o5)[None, :, :],
        cross_unique=not len(measurements) or np.bincount(pose_of * len(arrays) + object_of).max() == 1,
    )


def cap_schedule(
    problem: GraphProblem, layout: Layout, poses: NDArray, objects: NDArray, warm_start: bool
) -> tuple[float, ...]:
    """The outlier caps' multipliers, phase by phase (objslam_mapper.model.outliers)."""
    if warm_start:
        beyond = beyond_cap(problem, layout, poses, objects, WARM_START_CAP_SCALES[0])
        share = np.bincount(layout.object_of, weights=beyond, minlength=layout.n_objects) / np.maximum(
            np.bincount(layout.object_of, minlength=layout.n_objects), 1
        )
        if not len(share) or share.max() <= WARM_START_MAX_BEYOND:
            return WARM_START_CAP_SCALES
    return COLD_START_CAP_SCALES


def beyond_cap(
    problem: GraphProblem, layout: Layout, poses: NDArray, objects: NDArray, cap_scale: float = 1.0
) -> NDArray[np.bool_]:
    """(A,) whether each slice of the association is beyond its outlier cost (times ``cap_scale``)."""
    obj = objects[layout.object_of]
    mounts = problem.mounts(layout.measurements)
    pred = predict_reduced(poses[layout.pose_of], obj[:, :3], obj[:, 3:], mounts, jacobians=False)
    res, _ = whitened_slice_error(
        pred.values,
        problem.measurements[layout.measurements].T,
        1.0 / problem.measurement_stddev[layout.measurements].T,
        problem.measurement_censored_top[layout.measurements],
    )
    return ~pred.valid | (half_chi2(res) > cap_scale * problem.measurement_outlier_cost[layout.measurements])


def count_outliers(
    problem: GraphProblem, layout: Layout, poses: NDArray, objects: NDArray, cap_scale: float = 1.0
) -> int:
    """Slices of the association beyond their outlier cost (times ``cap_scale``) at this state."""
    return int(np.count_nonzero(beyond_cap(problem, layout, poses, objects, cap_scale)))


def graph_log_normalizer(problem: GraphProblem, layout: Layout) -> float:
    """Sum of the log-normalizers of every factor of the association's graph."""
    return (
        problem.trajectory_log_normalizer
        + float(np.sum(problem.measurement_log_normalizer[layout.measurements]))
        + float(np.sum(problem.prior_log_normalizer[layout.priors]))
    )


@dataclass(frozen=True)
class _SparsePattern:
    """CSC structure of the whole of Lambda, and where each block entry's value lands in it.

    The values of one linearization are concatenated in the order of ``_sparse_values``
    and summed into ``data`` by ``slot`` (repeated entries, e.g. two slices of one object
    in one image, add up).
    """

    dimension: int
    indices: NDArray[np.int32]
    indptr: NDArray[np.int32]
    slot: NDArray[np.int64]
    diagonal_slots: NDArray[np.int64]  # data positions of the diagonal, in variable order

    @classmethod
    def of(cls, layout: Layout) -> _SparsePattern:
        n, k, nc = layout.n_poses, layout.n_objects, layout.n_calib
        dim = POSE_DIM * n + OBJECT_DIM * k + nc
        a3 = np.arange(POSE_DIM)
        p = np.arange(n)[:, None, None]
        diag_r, diag_c = 3 * p + a3[None, :, None], 3 * p + a3[None, None, :]
        q = np.arange(max(n - 1, 0))[:, None, None]
        off_r, off_c = 3 * q + a3[None, :, None], 3 * q + 3 + a3[None, None, :]
        cross_r = POSE_DIM * layout.pose_of[None, None, :] + a3[:, None, None]
        cross_c = POSE_DIM * n + OBJECT_DIM * layout.object_of[None, None, :] + np.arange(OBJECT_DIM)[None, :, None]
        cross_r, cross_c = np.broadcast_arrays(cross_r, cross_c)
        o = np.arange(k)[:, None, None]
        a5 = np.arange(OBJECT_DIM)
        obj_r = POSE_DIM * n + OBJECT_DIM * o + a5[None, :, None]
        obj_c = POSE_DIM * n + OBJECT_DIM * o + a5[None, None, :]
        obj_r, obj_c = np.broadcast_arrays(obj_r, obj_c)
        diag_r, diag_c = np.broadcast_arrays(diag_r, diag_c)
        off_r, off_c = np.broadcast_arrays(off_r, off_c)
        ac = POSE_DIM * n + OBJECT_DIM * k + np.arange(nc)
        pc_r, pc_c = np.broadcast_arrays(3 * p + a3[None, :, None], ac[None, None, :])
        cc_r, cc_c = np.broadcast_arrays(ac[:, None], ac[None, :])
        blocks_r = (diag_r, off_r, off_c, cross_r, cross_c, obj_r, pc_r, pc_c, cc_r)
        blocks_c = (diag_c, off_c, off_r, cross_c, cross_r, obj_c, pc_c, pc_r, cc_c)
        rows = np.concatenate([x.ravel() for x in blocks_r])
        cols = np.concatenate([x.ravel() for x in blocks_c])
        keys, slot = np.unique(cols.astype(np.int64) * dim + rows, return_inverse=True)
        indices = (keys % dim).astype(np.int32)
        counts = np.bincount(keys // dim, minlength=dim)
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        diag_keys = np.arange(dim, dtype=np.int64) * (dim + 1)
        return cls(dim, indices, indptr, slot, np.searchsorted(keys, diag_keys))


def _sparse_values(lin: Linearization) -> NDArray[np.float64]:
    """Block values in the order of _SparsePattern's entries."""
    off = lin.pose_off.ravel()
    cross = lin.cross.ravel()
    pc = lin.pose_calib.ravel()
    return np.concatenate(
        [lin.pose_diag.ravel(), off, off, cross, cross, lin.object_diag.ravel(), pc, pc, lin.calib_diag.ravel()]
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
    # bincount of an empty input is int64 whatever the weights: a graph without slices
    # (no objects) would then get integer blocks.
    summed = np.bincount(bins.ravel(), weights=values.ravel(), minlength=size)
    return summed.astype(np.float64, copy=False).reshape(shape)


class AssociationSystem:
    """Residuals and normal equations of one association over a fixed layout."""

    def __init__(self, problem: GraphProblem, layout: Layout, dense_object_limit: int):
        self.problem = problem
        self.layout = layout
        self.dense_object_limit = dense_object_limit
        self.n_poses = problem.pose_count
        self.n_objects = len(layout.labels)
        self.n_calib = problem.calibration_dim
        self.z = np.ascontiguousarray(problem.measurements[layout.measurements].T)  # (4, A)
        self.inv_sigma = np.ascontiguousarray(1.0 / problem.measurement_stddev[layout.measurements].T)
        self.censored_top = problem.measurement_censored_top[layout.measurements]
        self.outlier_cost = problem.measurement_outlier_cost[layout.measurements]
        self.has_outlier_model = bool(np.isfinite(self.outlier_cost).any())
        self.cap_scale = 1.0  # the caps' multiplier (objslam_mapper.model.outliers; inf: every slice Gaussian)
        self.inc_inv_sigma = 1.0 / problem.increment_stddev
        self.calib_inv_sigma = 1.0 / problem.calibration_prior_stddev
        self.prior_mean = problem.prior_mean[layout.priors]
        self.prior_inv_sigma = 1.0 / problem.prior_stddev[layout.priors]
        self.prior_spread = problem.prior_spread[layout.priors]
        self.log_normalizer = graph_log_normalizer(problem, layout)
        self.mounts = problem.mounts(layout.measurements)

    @property
    def dimension(self) -> int:
        return POSE_DIM * self.n_poses + OBJECT_DIM * self.n_objects + self.n_calib

    def _odometry(self, poses: NDArray, calib: NDArray) -> tuple[float, NDArray, NDArray, NDArray, NDArray, tuple]:
        """Odometry factors: cost, and their normal-equation blocks in closed form.

        Error ``e = (k R_i^T (t_j - t_i) - u_xy, wrap(m dtheta + b L - u_theta))`` with
        ``k = 1 + s_d``, ``m = 1 + s_t`` and ``dtheta = wrap(theta_j - theta_i)`` (without the
        calibration ``k = m = 1``, ``b = 0``), whitened by ``w`` (x, y) and ``w_t`` (theta).
        With ``d = t_j - t_i`` the Gram blocks are ``Ji^T Ji = k^2 w^2 [[1, 0, -d_y], [0, 1, d_x],
        [-d_y, d_x, |d|^2]] + m^2 w_t^2 e3 e3^T``, ``Jj^T Jj = diag(k^2 w^2, k^2 w^2, m^2 w_t^2)``,
        ``Ji^T Jj = [[-k^2 w^2, 0, 0], [0, -k^2 w^2, 0], [k^2 w^2 d_y, -k^2 w^2 d_x, -m^2 w_t^2]]``.
        Returns (cost, diag_i, diag_j, off, grad (N, 3), the terms :meth:`_calibration_blocks` needs).
        """
        pi, pj = poses[:-1], poses[1:]
        c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
        dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
        u = self.problem.increments
        w, wt = self.inc_inv_sigma[:, 0], self.inc_inv_sigma[:, 2]
        q1, q2 = c * dx + s * dy, -s * dx + c * dy  # R_i^T d
        if self.n_calib:
            k, m = 1.0 + calib[0], 1.0 + calib[1]
            dtheta = wrap_angle(pj[:, 2] - pi[:, 2])
            e3 = wt * wrap_angle(m * dtheta + calib[2] * self.problem.increment_path_length_m - u[:, 2])
        else:
            k = m = 1.0
            dtheta = None
            e3 = wt * wrap_angle(pj[:, 2] - pi[:, 2] - u[:, 2])
        e1 = w * (k * q1 - u[:, 0])
        e2 = w * (k * q2 - u[:, 1])
        cost = 0.5 * float(np.sum(e1 * e1) + np.sum(e2 * e2) + np.sum(e3 * e3))
        w2, wt2 = w * w * (k * k), wt * wt * (m * m)
        n_factors = len(pi)
        diag_i = np.zeros((n_factors, 3, 3))
        diag_i[:, 0, 0] = diag_i[:, 1, 1] = w2
        diag_i[:, 0, 2] = diag_i[:, 2, 0] = -w2 * dy
        diag_i[:, 1, 2] = diag_i[:, 2, 1] = w2 * dx
        diag_i[:, 2, 2] = w2 * (dx * dx + dy * dy) + wt2
        diag_j = np.zeros((n_factors, 3, 3))
        diag_j[:, 0, 0] = diag_j[:, 1, 1] = w2
        diag_j[:, 2, 2] = wt2
        off = np.zeros((n_factors, 3, 3))
        off[:, 0, 0] = off[:, 1, 1] = -w2
        off[:, 2, 0] = w2 * dy
        off[:, 2, 1] = -w2 * dx
        off[:, 2, 2] = -wt2
        wk, wtm = w * k, wt * m
        a, b = -s * dx + c * dy, -c * dx - s * dy  # d(R_i^T d)/d theta_i
        grad = np.zeros((n_factors + 1, 3))
        grad[:-1, 0] = wk * (-c * e1 + s * e2)
        grad[:-1, 1] = wk * (-s * e1 - c * e2)
        grad[:-1, 2] = wk * (a * e1 + b * e2) - wtm * e3
        grad[1:, 0] += wk * (c * e1 - s * e2)
        grad[1:, 1] += wk * (s * e1 + c * e2)
        grad[1:, 2] += wtm * e3
        return cost, diag_i, diag_j, off, grad, (w, wt, k, m, dx, dy, q1, q2, dtheta, e1, e2, e3)

    def _calibration_blocks(self, calib: NDArray, terms: tuple) -> tuple[float, NDArray, NDArray, NDArray]:
        """Calibration blocks of the odometry factors (``terms`` of :meth:`_odometry`), plus its prior.

        With ``J_c`` the factor's columns of ``(s_d, s_t, b)``: ``w (q, 0, 0)`` on the x, y
        rows (``q = R_i^T d``), ``w_t (0, dtheta, L)`` on the theta row, the pose-calibration
        blocks are ``Ji^T J_c = -Jj^T J_c = -[[k w^2 d_x, 0, 0], [k w^2 d_y, 0, 0],
        [0, m w_t^2 dtheta, m w_t^2 L]]``. Returns (prior cost, grad (C,), pose_calib (N, 3, C),
        calib_diag (C, C)).
        """
        nc = self.n_calib
        if not nc:
            return 0.0, np.zeros(0), np.zeros((self.n_poses, POSE_DIM, 0)), np.zeros((0, 0))
        w, wt, k, m, dx, dy, q1, q2, dtheta, e1, e2, e3 = terms
        length = self.problem.increment_path_length_m
        w2, wt2 = w * w, wt * wt
        prior = calib * self.calib_inv_sigma
        grad = (
            np.array([np.sum(w * (q1 * e1 + q2 * e2)), np.sum(wt * dtheta * e3), np.sum(wt * length * e3)])
            + prior * self.calib_inv_sigma
        )
        calib_diag = np.diag(self.calib_inv_sigma**2)
        calib_diag[0, 0] += np.sum(w2 * (q1 * q1 + q2 * q2))
        calib_diag[1, 1] += np.sum(wt2 * dtheta * dtheta)
        calib_diag[2, 2] += np.sum(wt2 * length * length)
        calib_diag[1, 2] = calib_diag[2, 1] = calib_diag[1, 2] + np.sum(wt2 * dtheta * length)
        block = np.zeros((len(dx), POSE_DIM, CALIBRATION_DIM))
        block[:, 0, 0] = k * w2 * dx
        block[:, 1, 0] = k * w2 * dy
        block[:, 2, 1] = m * wt2 * dtheta
        block[:, 2, 2] = m * wt2 * length
        pose_calib = np.zeros((self.n_poses, POSE_DIM, CALIBRATION_DIM))
        pose_calib[:-1] -= block
        pose_calib[1:] += block
        return 0.5 * float(prior @ prior), grad, pose_calib, calib_diag

    def _whitened_slices(self, poses: NDArray, objects: NDArray) -> tuple[ReducedPrediction, NDArray, NDArray]:
        """The slices' predictions, their whitened residuals (4, A) before any cap, and the
        weights (4, A) that whiten their Jacobians (upper edges a lower bound, slice_model.censor)."""
        obj = objects[self.layout.object_of]
        pred = predict_reduced(poses[self.layout.pose_of], obj[:, :3], obj[:, 3:], self.mounts)
        sl, weight = whitened_slice_error(pred.values, self.z, self.inv_sigma, self.censored_top)
        return pred, sl, weight

    def linearize(self, poses: NDArray, objects: NDArray, calib: NDArray) -> Linearization:
        n, k = self.n_poses, self.n_objects
        lay = self.layout
        pred, sl, weight = self._whitened_slices(poses, objects)
        if not np.all(pred.valid):
            return Linearization(cost=np.inf, valid=False)
        half = half_chi2(sl)
        outliers = int(np.count_nonzero(half > self.outlier_cost))
        if self.has_outlier_model and self.cap_scale < np.inf:
            within = truncate(sl, self.outlier_cost * self.cap_scale, half)
            jac = pred.jacobian * (weight * within)[:, None, :]  # (4, 6, A); capped slices carry no information
        else:
            jac = pred.jacobian * weight[:, None, :]
        jac_pose = jac[:, :3] * _POSE_SIGN[None, :, None]  # (4, 3, A)
        jac_object = jac[:, _OBJECT_COLUMNS]  # (4, 5, A)
        odo_cost, diag_i, diag_j, pose_off, grad_pose, terms = self._odometry(poses, calib)
        calib_cost, grad_calib, pose_calib, calib_diag = self._calibration_blocks(calib, terms)
        first = poses[0] - self.problem.odometry_poses[0]
        first[2] = wrap_angle(first[2])
        first /= self.problem.first_pose_stddev
        pr = (objects - self.prior_mean) * self.prior_inv_sigma
        cost = odo_cost + 0.5 * float(np.sum(first**2) + np.sum(sl**2) + np.sum(pr**2))
        if self.n_calib:
            cost += calib_cost

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
        return Linearization(
            cost,
            True,
            outliers,
            grad_pose.ravel(),
            grad_object.ravel(),
            pose_diag,
            pose_off,
            cross,
            object_diag,
            grad_calib,
            pose_calib,
            calib_diag,
        )

    def _sparse_information(self, lin: Linearization, damping: float = 0.0) -> scipy.sparse.csc_matrix:
        """``Lambda`` of a linearization as a sparse matrix, Marquardt-damped if asked.

        Rows: poses, objects, calibration.
        """
        pattern = self.layout.sparse
        data = np.bincount(pattern.slot, weights=_sparse_values(lin), minlength=len(pattern.indices))
        if damping > 0.0:
            data[pattern.diagonal_slots] *= 1.0 + damping
        return scipy.sparse.csc_matrix((data, pattern.indices, pattern.indptr), shape=(pattern.dimension,) * 2)

    def information_matrix(self, lin: Linearization) -> NDArray[np.float64]:
        """The dense ``Lambda`` of a linearization (rows as in the sparse system)."""
        return self._sparse_information(lin).toarray()

    def inlier_slices(self, poses: NDArray, objects: NDArray) -> NDArray[np.bool_]:
        """(M,) the layout's slices within their cap (``cap_scale``) at this state."""
        return self._within_caps(self._whitened_slices(poses, objects)[1])

    def _within_caps(self, whitened: NDArray) -> NDArray[np.bool_]:
        if not (self.has_outlier_model and self.cap_scale < np.inf):
            return np.ones(whitened.shape[1], dtype=bool)
        return half_chi2(whitened) <= self.outlier_cost * self.cap_scale

    def prior_scale(self) -> NDArray[np.float64]:
        """(n,) per variable, the spread of the truth about its prior's mean over the prior's stddev.

        1 but for the objects' class priors (``problem.prior_spread``): what the error
        covariance scales each prior's information by (:mod:`objslam_mapper.graph.error_covariance`).
        """
        scale = np.ones(self.dimension)
        first = POSE_DIM * self.n_poses
        scale[first : first + OBJECT_DIM * self.n_objects] = (self.prior_spread * self.prior_inv_sigma).ravel()
        return scale

    def noise_groups(
        self,
        poses: NDArray,
        objects: NDArray,
        calib: NDArray,
        object_bias_share: Sequence[float],
        inliers: NDArray[np.bool_] | None = None,
    ) -> list[NoiseGroup]:
        """Whitened rows of the slices (one group per component) and of the odometry (translation, turn).

        Slices beyond their cap (``cap_scale``) are left out, as the information leaves
        them out; ``inliers`` (M,) says which to keep instead (those of another state: the
        rows at the truth of the slices the MAP kept). Slice rows know their object, whose
        slices share a bias of ``object_bias_share`` (one per component) times their
        configured stddev (:mod:`objslam_mapper.graph.error_covariance`).
        """
        n, dim = self.n_poses, self.dimension
        lay = self.layout
        pred, sl, weight = self._whitened_slices(poses, objects)
        kept = np.flatnonzero(self._within_caps(sl) if inliers is None else inliers)
        jac = pred.jacobian[:, :, kept] * weight[:, None, kept]
        columns = np.concatenate(
            [
                POSE_DIM * lay.pose_of[kept, None] + np.arange(POSE_DIM),
                POSE_DIM * n + OBJECT_DIM * lay.object_of[kept, None] + np.arange(OBJECT_DIM),
            ],
            axis=1,
        )
        indptr = np.arange(0, (POSE_DIM + OBJECT_DIM) * len(kept) + 1, POSE_DIM + OBJECT_DIM)
        groups = []
        for c, name in enumerate(COMPONENTS):
            values = np.concatenate([(jac[c, :3] * _POSE_SIGN[:, None]).T, jac[c, _OBJECT_COLUMNS].T], axis=1)
            jacobian = scipy.sparse.csr_matrix((values.ravel(), columns.ravel(), indptr), shape=(len(kept), dim))
            groups.append(NoiseGroup(name, jacobian, sl[c, kept], lay.object_of[kept], float(object_bias_share[c])))
        return groups + self._odometry_groups(poses, calib)

    def _odometry_groups(self, poses: NDArray, calib: NDArray) -> list[NoiseGroup]:
        """The odometry factors' whitened rows: translation (x, y) and turn (:meth:`_odometry`'s error)."""
        n, dim = self.n_poses, self.dimension
        if n < 2:
            return []
        w, wt, k, m, dx, dy, q1, q2, dtheta, e1, e2, e3 = self._odometry(poses, calib)[5]
        c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
        a, b = -s * dx + c * dy, -c * dx - s * dy
        wk, wtm = w * k, wt * m
        i = POSE_DIM * np.arange(n - 1)
        # Per row: columns of pose i (x, y, theta), pose j, then the calibration's.
        xy_cols = [i, i + 1, i + 2, i + 3, i + 4]
        e1_vals = [-wk * c, -wk * s, wk * a, wk * c, wk * s]
        e2_vals = [wk * s, -wk * c, wk * b, -wk * s, wk * c]
        theta_cols = [i + 2, i + 5]
        theta_vals = [-wtm, wtm]
        if self.n_calib:
            first_calib = np.full(n - 1, dim - self.n_calib)
            xy_cols.append(first_calib)
            e1_vals.append(w * q1)
            e2_vals.append(w * q2)
            theta_cols += [first_calib + 1, first_calib + 2]
            theta_vals += [wt * dtheta, wt * self.problem.increment_path_length_m]

        def rows(cols: list[NDArray], vals: list[NDArray]) -> scipy.sparse.csr_matrix:
            width = len(cols)
            indptr = np.arange(0, width * (n - 1) + 1, width)
            values, columns = np.stack(vals, axis=1).ravel(), np.stack(cols, axis=1).ravel()
            return scipy.sparse.csr_matrix((values, columns, indptr), shape=(n - 1, dim))

        translation = scipy.sparse.vstack([rows(xy_cols, e1_vals), rows(xy_cols, e2_vals)]).tocsr()
        return [
            NoiseGroup("odometry_translation", translation, np.concatenate([e1, e2])),
            NoiseGroup("odometry_turn", rows(theta_cols, theta_vals), e3),
        ]

    def factorize(self, lin: Linearization, damping: float) -> Factorization:
        """Solve the normal equations, Marquardt-damped (``diag *= 1 + damping``) if asked.

        Raises LinAlgError if the system is not positive definite.
        """
        if self.n_objects <= self.dense_object_limit:
            fac = self._factorize_schur(lin, damping)
        else:
            fac = self._factorize_sparse(lin, damping)
        # Decrease of the quadratic model: 1/2 (-g^T step + damping step^T diag(Lambda) step).
        predicted = -float(lin.grad_pose @ fac.step_pose + lin.grad_object @ fac.step_object)
        if self.n_calib:
            predicted -= float(lin.grad_calib @ fac.step_calib)
        if damping > 0.0:
            diag_pose, diag_object, diag_calib = lin.diagonal()
            predicted += damping * float(diag_pose @ fac.step_pose**2 + diag_object @ fac.step_object**2)
            if self.n_calib:
                predicted += damping * float(diag_calib @ fac.step_calib**2)
        fac.predicted_decrease = 0.5 * predicted
        return fac

    def _factorize_schur(self, lin: Linearization, damping: float) -> Factorization:
        """Poses first: with A = U^T U, W = U^-T B and w = U^-T g_pose, S = C - W^T W,
        step_dense = S^-1 (W^T w - g_dense), step_pose = -U^-1 (w + W step_dense).

        The dense variables are the objects, then the calibration (if estimated): ``B`` holds
        their pose blocks, ``C`` their own (objects and calibration share no factor)."""
        n, k, nc = self.n_poses, self.n_objects, self.n_calib
        n_object_vars = OBJECT_DIM * k
        diag_at, diag_src, off_at, off_src = _band_index(n)
        pose_diag, object_diag, calib_diag = lin.pose_diag, lin.object_diag, lin.calib_diag
        if damping > 0.0:
            pose_diag, object_diag, calib_diag = pose_diag.copy(), object_diag.copy(), calib_diag.copy()
            i3, i5 = np.arange(POSE_DIM), np.arange(OBJECT_DIM)
            pose_diag[:, i3, i3] *= 1.0 + damping
            object_diag[:, i5, i5] *= 1.0 + damping
            calib_diag[np.diag_indices(nc)] *= 1.0 + damping
        band = np.zeros((_BAND + 1, POSE_DIM * n))
        band[diag_at] = pose_diag.ravel()[diag_src]
        band[off_at] = lin.pose_off.ravel()[off_src]
        chol_pose = scipy.linalg.cholesky_banded(band, lower=False, check_finite=False)
        log_det = 2.0 * float(np.sum(np.log(chol_pose[_BAND])))
        rhs = np.empty((POSE_DIM * n, n_object_vars + nc + 1), order="F")
        rhs[:, :n_object_vars] = lin.pose_object(self.layout)
        rhs[:, n_object_vars:-1] = lin.pose_calib.reshape(POSE_DIM * n, nc)
        rhs[:, -1] = lin.grad_pose
        whitened, info = lapack.dtbtrs(chol_pose, rhs, uplo="U", trans="T", overwrite_b=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
        w_cross, w_grad = whitened[:, :-1], whitened[:, -1]
        chol_schur = None
        step_dense = np.zeros(0)
        if n_object_vars + nc:
            schur = -(w_cross.T @ w_cross)
            schur[_block_diag_index(k, OBJECT_DIM)] += object_diag.ravel()
            schur[n_object_vars:, n_object_vars:] += calib_diag
            grad_dense = np.concatenate([lin.grad_object, lin.grad_calib]) if nc else lin.grad_object
            chol_schur = scipy.linalg.cholesky(schur, lower=False, check_finite=False)
            log_det += 2.0 * float(np.sum(np.log(np.diag(chol_schur))))
            step_dense = scipy.linalg.cho_solve(
                (chol_schur, False), w_cross.T @ w_grad - grad_dense, check_finite=False
            )
        back, info = lapack.dtbtrs(chol_pose, (w_grad + w_cross @ step_dense)[:, None], uplo="U", trans="N")
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
        return Factorization(
            log_det,
            -back[:, 0],
            step_dense[:n_object_vars],
            0.0,
            step_dense[n_object_vars:],
            chol_schur=chol_schur,
            chol_pose=chol_pose,
            w_cross=w_cross,
        )

    def _factorize_sparse(self, lin: Linearization, damping: float) -> Factorization:
        matrix = self._sparse_information(lin, damping)
        try:
            lu = scipy.sparse.linalg.splu(
                matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
            )
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise np.linalg.LinAlgError(str(exc)) from exc
        pivots = lu.U.diagonal()
        if np.any(pivots <= 0.0):
            raise np.linalg.LinAlgError("normal equations are not positive definite")
        step = lu.solve(-np.concatenate([lin.grad_pose, lin.grad_object, lin.grad_calib]))
        split = POSE_DIM * self.n_poses
        split_calib = split + OBJECT_DIM * self.n_objects
        return Factorization(
            float(np.sum(np.log(pivots))),
            step[:split],
            step[split:split_calib],
            0.0,
            step[split_calib:],
            sparse_lu=lu,
        )

    def _dense_inverse_columns(self, fac: Factorization, first: int, count: int) -> NDArray[np.float64]:
        """Rows and columns [first, first + count) of the inverse over the dense variables."""
        if fac.chol_schur is not None:
            unit = np.zeros((len(fac.chol_schur), count))
            unit[first : first + count] = np.eye(count)
            inv = scipy.linalg.cho_solve((fac.chol_schur, False), unit, check_finite=False)
            return inv[first : first + count]
        split = POSE_DIM * self.n_poses
        unit = np.zeros((split + OBJECT_DIM * self.n_objects + self.n_calib, count))
        unit[split + first : split + first + count] = np.eye(count)
        return fac.sparse_lu.solve(unit)[split + first : split + first + count]

    def object_covariance(self, fac: Factorization) -> NDArray[np.float64]:
        """(K, 5, 5) marginal covariance blocks of the objects (undamped factorization)."""
        k = self.n_objects
        if not k:
            return np.zeros((0, OBJECT_DIM, OBJECT_DIM))
        inv = self._dense_inverse_columns(fac, 0, OBJECT_DIM * k)
        blocks = inv.reshape(k, OBJECT_DIM, k, OBJECT_DIM)
        return blocks[np.arange(k), :, np.arange(k), :]

    def solve_pose_rhs(self, fac: Factorization, rhs_pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """``Lambda^-1 [rhs_pose; 0]`` for (3N, m) right-hand sides on the poses only (undamped factorization).

        Dense path, with ``z = U^-T r``: dense part ``x_d = -S^-1 W^T z``, poses
        ``x_p = U^-1 (z - W x_d)``. Rows as in the sparse system: poses, objects, calibration.
        """
        rhs_pose = np.asarray(rhs_pose, dtype=float)
        if fac.sparse_lu is not None:
            rhs = np.zeros((POSE_DIM * self.n_poses + OBJECT_DIM * self.n_objects + self.n_calib, rhs_pose.shape[1]))
            rhs[: len(rhs_pose)] = rhs_pose
            return fac.sparse_lu.solve(rhs)
        z, info = lapack.dtbtrs(fac.chol_pose, rhs_pose, uplo="U", trans="T")
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
        x_dense = np.zeros((fac.w_cross.shape[1], rhs_pose.shape[1]))
        if fac.chol_schur is not None:
            x_dense = -scipy.linalg.cho_solve((fac.chol_schur, False), fac.w_cross.T @ z, check_finite=False)
        x_pose, info = lapack.dtbtrs(fac.chol_pose, z - fac.w_cross @ x_dense, uplo="U", trans="N")
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
        return np.concatenate([x_pose, x_dense])

    def object_covariance_about_trajectory(
        self, fac: Factorization, map_xy_pose: NDArray[np.float64], pose_weights: NDArray[np.float64], objects: NDArray
    ) -> NDArray[np.float64]:
        """(K, 5, 5) object covariances about the trajectory (:mod:`objslam_mapper.graph.gauge`)."""
        marginals = self.object_covariance(fac)
        if not self.n_objects or self.n_poses < 2:
            return marginals
        gauge = trajectory_gauge(map_xy_pose, pose_weights)
        solved = self.solve_pose_rhs(fac, gauge.rows.T)  # Lambda^-1 G^T
        split = POSE_DIM * self.n_poses
        object_gauge_cov = solved[split : split + OBJECT_DIM * self.n_objects]
        gauge_cov = gauge.rows @ solved[:split]
        return about_trajectory(marginals, object_gauge_cov, gauge_cov, np.asarray(objects)[:, :2], gauge.centroid_xy)

    def object_error_covariance_about_trajectory(
        self,
        lin: Linearization,
        state: tuple[NDArray, NDArray, NDArray],
        pose_weights: NDArray[np.float64],
        object_bias_share: Sequence[float],
    ) -> ErrorCovariance:
        """(K, 5, 5) covariances of the objects' errors about the trajectory (:mod:`.error_covariance`).

        ``lin`` is the linearization at ``state`` (poses, objects, calibration), with the
        caps the MAP was solved with. The objects' class priors count with the spread of
        real instances (``problem.prior_spread``). Also in the result: the same rows'
        posterior, per object.
        """
        poses, objects, calib = state
        k, split = self.n_objects, POSE_DIM * self.n_poses
        rows = np.zeros((OBJECT_DIM * k, self.dimension))
        rows[:, split : split + OBJECT_DIM * k] = np.eye(OBJECT_DIM * k)
        if self.n_poses >= 2:
            gauge = trajectory_gauge(poses[:, :2], pose_weights)
            motion = object_motion(objects[:, :2], gauge.centroid_xy, OBJECT_DIM).reshape(-1, GAUGE_DIM)
            rows[:, :split] -= motion @ gauge.rows
        groups = self.noise_groups(poses, objects, calib, object_bias_share)
        result = error_covariance(self.information_matrix(lin), groups, rows, self.prior_scale())
        diagonal = np.arange(k)

        def blocks(cov: NDArray) -> NDArray:
            return cov.reshape(k, OBJECT_DIM, k, OBJECT_DIM)[diagonal, :, diagonal, :]

        return result._replace(covariance=blocks(result.covariance), posterior=blocks(result.posterior))

    def calibration_covariance(self, fac: Factorization) -> NDArray[np.float64]:
        """(C, C) marginal covariance of the odometry calibration (undamped factorization)."""
        if not self.n_calib:
            return np.zeros((0, 0))
        return self._dense_inverse_columns(fac, OBJECT_DIM * self.n_objects, self.n_calib)
