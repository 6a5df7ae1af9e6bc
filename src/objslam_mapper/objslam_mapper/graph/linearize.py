r"""Residuals and normal equations of one association, assembled vectorized.

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

The system is solved by :mod:`.factorize`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from objslam_common.geometry import wrap_angle
from objslam_mapper.graph.bins import bin_sum
from objslam_mapper.graph.layout import Layout, graph_log_normalizer
from objslam_mapper.graph.problem import CALIBRATION_DIM, OBJECT_DIM, POSE_DIM, GraphProblem
from objslam_mapper.model.floor import floor_jacobian, floor_residual
from objslam_mapper.model.outliers import (
    COLD_START_CAP_SCALES,
    WARM_START_CAP_SCALES,
    WARM_START_MAX_BEYOND,
    half_chi2,
    truncate,
)
from objslam_mapper.model.slice_model import ReducedPrediction, predict_reduced, whitened_slice_error


def _empty() -> NDArray[np.float64]:
    return np.zeros(0)


@dataclass
class Linearization:
    """Cost and normal equations at one state (``valid`` False: the model is undefined there)."""

    cost: float
    valid: bool
    outliers: int = 0  # slices beyond their (unscaled) outlier cost
    # The blocks are empty where the model is undefined (``valid`` False).
    grad_pose: NDArray[np.float64] = field(default_factory=_empty)  # (3N,)
    grad_object: NDArray[np.float64] = field(default_factory=_empty)  # (5K,)
    pose_diag: NDArray[np.float64] = field(default_factory=_empty)  # (N, 3, 3)
    pose_off: NDArray[np.float64] = field(default_factory=_empty)  # (N-1, 3, 3): block (i, i+1)
    cross: NDArray[np.float64] = field(default_factory=_empty)  # (3, 5, A) pose-object block of each slice
    object_diag: NDArray[np.float64] = field(default_factory=_empty)  # (K, 5, 5)
    grad_calib: NDArray[np.float64] = field(default_factory=_empty)  # (C,) C = 3 with the calibration, else 0
    pose_calib: NDArray[np.float64] = field(default_factory=_empty)  # (N, 3, C) pose-calibration blocks
    calib_diag: NDArray[np.float64] = field(default_factory=_empty)  # (C, C)
    _pose_object: NDArray[np.float64] | None = field(default=None, repr=False)

    def pose_object(self, layout: Layout) -> NDArray[np.float64]:
        """The dense (3N, 5K) pose-object block (built once)."""
        if self._pose_object is None:
            shape = (POSE_DIM * layout.n_poses, OBJECT_DIM * layout.n_objects)
            if layout.cross_unique:
                block = np.zeros(shape)
                block.ravel()[layout.cross_bins.ravel()] = self.cross.ravel()
            else:
                block = bin_sum(layout.cross_bins, self.cross, shape)
            self._pose_object = block
        return self._pose_object

    def diagonal(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Diagonals of the pose (3N,), object (5K,) and calibration (C,) blocks."""
        i3, i5 = np.arange(POSE_DIM), np.arange(OBJECT_DIM)
        return self.pose_diag[:, i3, i3].ravel(), self.object_diag[:, i5, i5].ravel(), np.diag(self.calib_diag)


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
        problem.measurement_bounds[layout.measurements],
    )
    return ~pred.valid | (half_chi2(res) > cap_scale * problem.measurement_outlier_cost[layout.measurements])


def count_outliers(
    problem: GraphProblem, layout: Layout, poses: NDArray, objects: NDArray, cap_scale: float = 1.0
) -> int:
    """Slices of the association beyond their outlier cost (times ``cap_scale``) at this state."""
    return int(np.count_nonzero(beyond_cap(problem, layout, poses, objects, cap_scale)))


POSE_SIGN = np.array([-1.0, -1.0, 1.0])
OBJECT_COLUMNS = np.array([0, 1, 3, 4, 5])


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
        self.bounds = problem.measurement_bounds[layout.measurements]
        self.outlier_cost = problem.measurement_outlier_cost[layout.measurements]
        self.has_outlier_model = bool(np.isfinite(self.outlier_cost).any())
        self.cap_scale = 1.0  # the caps' multiplier (objslam_mapper.model.outliers; inf: every slice Gaussian)
        self.inc_inv_sigma = 1.0 / problem.increment_stddev
        self.calib_inv_sigma = 1.0 / problem.calibration_prior_stddev
        self.prior_mean = problem.prior_mean[layout.priors]
        self.prior_inv_sigma = 1.0 / problem.prior_stddev[layout.priors]
        self.prior_spread = problem.prior_spread[layout.priors]
        self.floor_inv_sigma = 1.0 / problem.prior_floor_stddev[layout.priors]  # 0: no floor factor
        self.log_normalizer = graph_log_normalizer(problem, layout)
        self.mounts = problem.mounts(layout.measurements)

    @property
    def dimension(self) -> int:
        return POSE_DIM * self.n_poses + OBJECT_DIM * self.n_objects + self.n_calib

    def odometry_terms(self, poses: NDArray, calib: NDArray) -> tuple[float, NDArray, NDArray, NDArray, NDArray, tuple]:
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
        """Calibration blocks of the odometry factors (``terms`` of :meth:`odometry_terms`), plus its prior.

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

    def whitened_slices(self, poses: NDArray, objects: NDArray) -> tuple[ReducedPrediction, NDArray, NDArray]:
        """The slices' predictions, their whitened residuals (4, A) before any cap, and the
        weights (4, A) that whiten their Jacobians (upper edges a lower bound, slice_model.censor)."""
        obj = objects[self.layout.object_of]
        pred = predict_reduced(poses[self.layout.pose_of], obj[:, :3], obj[:, 3:], self.mounts)
        sl, weight = whitened_slice_error(pred.values, self.z, self.inv_sigma, self.bounds)
        return pred, sl, weight

    def linearize(self, poses: NDArray, objects: NDArray, calib: NDArray) -> Linearization:
        n, k = self.n_poses, self.n_objects
        lay = self.layout
        pred, sl, weight = self.whitened_slices(poses, objects)
        if not np.all(pred.valid):
            return Linearization(cost=np.inf, valid=False)
        half = half_chi2(sl)
        outliers = int(np.count_nonzero(half > self.outlier_cost))
        if self.has_outlier_model and self.cap_scale < np.inf:
            within = truncate(sl, self.outlier_cost * self.cap_scale, half)
            jac = pred.jacobian * (weight * within)[:, None, :]  # (4, 6, A); capped slices carry no information
        else:
            jac = pred.jacobian * weight[:, None, :]
        jac_pose = jac[:, :3] * POSE_SIGN[None, :, None]  # (4, 3, A)
        jac_object = jac[:, OBJECT_COLUMNS]  # (4, 5, A)
        odo_cost, diag_i, diag_j, pose_off, grad_pose, terms = self.odometry_terms(poses, calib)
        calib_cost, grad_calib, pose_calib, calib_diag = self._calibration_blocks(calib, terms)
        first = poses[0] - self.problem.odometry_poses[0]
        first[2] = wrap_angle(first[2])
        first /= self.problem.first_pose_stddev
        pr = (objects - self.prior_mean) * self.prior_inv_sigma
        z_base = objects[:, 2]  # objects is (K, 5), K = 0 included
        floor, floor_jac = floor_residual(z_base, self.floor_inv_sigma), floor_jacobian(z_base, self.floor_inv_sigma)
        cost = odo_cost + 0.5 * float(np.sum(first**2) + np.sum(sl**2) + np.sum(pr**2) + np.sum(floor**2))
        if self.n_calib:
            cost += calib_cost

        pose_diag = bin_sum(lay.pose_bins, np.einsum("kim,kjm->ijm", jac_pose, jac_pose), (n, 3, 3))
        pose_diag[:-1] += diag_i
        pose_diag[1:] += diag_j
        pose_diag[0] += np.diag(self.problem.first_pose_stddev**-2)
        grad_pose += bin_sum(lay.pose_grad_bins, np.einsum("kim,km->im", jac_pose, sl), (n, 3))
        grad_pose[0] += first / self.problem.first_pose_stddev

        # Measurements are grouped by object: per-object sums are contiguous runs.
        object_diag = np.add.reduceat(np.einsum("kim,kjm->ijm", jac_object, jac_object), lay.starts, axis=2)
        object_diag = np.ascontiguousarray(object_diag.transpose(2, 0, 1)) if k else np.zeros((0, 5, 5))
        object_diag[:, np.arange(OBJECT_DIM), np.arange(OBJECT_DIM)] += self.prior_inv_sigma**2
        object_diag[:, 2, 2] += floor_jac**2
        grad_object = pr * self.prior_inv_sigma
        grad_object[:, 2] += floor * floor_jac
        if k:
            grad_object += np.add.reduceat(np.einsum("kim,km->im", jac_object, sl), lay.starts, axis=1).T
        cross = np.einsum("kim,kjm->ijm", jac_pose, jac_object)
        return Linearization(
            cost=cost,
            valid=True,
            outliers=outliers,
            grad_pose=grad_pose.ravel(),
            grad_object=grad_object.ravel(),
            pose_diag=pose_diag,
            pose_off=pose_off,
            cross=cross,
            object_diag=object_diag,
            grad_calib=grad_calib,
            pose_calib=pose_calib,
            calib_diag=calib_diag,
        )

    def inlier_slices(self, poses: NDArray, objects: NDArray) -> NDArray[np.bool_]:
        """(M,) the layout's slices within their cap (``cap_scale``) at this state."""
        return self.within_caps(self.whitened_slices(poses, objects)[1])

    def within_caps(self, whitened: NDArray) -> NDArray[np.bool_]:
        if not (self.has_outlier_model and self.cap_scale < np.inf):
            return np.ones(whitened.shape[1], dtype=bool)
        return half_chi2(whitened) <= self.outlier_cost * self.cap_scale
