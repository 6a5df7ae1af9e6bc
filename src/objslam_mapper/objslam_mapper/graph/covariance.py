"""Covariances of one solved association: object marginals, about the trajectory
(:mod:`.gauge`), of the estimate's error (:mod:`.error_covariance`), and of the odometry calibration."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse
from numpy.typing import NDArray

from objslam_mapper.graph.error_covariance import ErrorCovariance, NoiseGroup, error_covariance
from objslam_mapper.graph.factorize import Factorization, dense_inverse_columns, solve_pose_rhs, sparse_information
from objslam_mapper.graph.gauge import GAUGE_DIM, about_trajectory, object_motion, trajectory_gauge
from objslam_mapper.graph.linearize import OBJECT_COLUMNS, POSE_SIGN, AssociationSystem, Linearization
from objslam_mapper.graph.problem import OBJECT_DIM, POSE_DIM
from objslam_mapper.model.slice_model import COMPONENTS


def object_covariance(system: AssociationSystem, fac: Factorization) -> NDArray[np.float64]:
    """(K, 5, 5) marginal covariance blocks of the objects (undamped factorization)."""
    k = system.n_objects
    if not k:
        return np.zeros((0, OBJECT_DIM, OBJECT_DIM))
    inv = dense_inverse_columns(system, fac, 0, OBJECT_DIM * k)
    blocks = inv.reshape(k, OBJECT_DIM, k, OBJECT_DIM)
    return blocks[np.arange(k), :, np.arange(k), :]


def object_covariance_about_trajectory(
    system: AssociationSystem,
    fac: Factorization,
    map_xy_pose: NDArray[np.float64],
    pose_weights: NDArray[np.float64],
    objects: NDArray,
) -> NDArray[np.float64]:
    """(K, 5, 5) object covariances about the trajectory (:mod:`objslam_mapper.graph.gauge`)."""
    marginals = object_covariance(system, fac)
    if not system.n_objects or system.n_poses < 2:
        return marginals
    gauge = trajectory_gauge(map_xy_pose, pose_weights)
    solved = solve_pose_rhs(system, fac, gauge.rows.T)  # Lambda^-1 G^T
    split = POSE_DIM * system.n_poses
    object_gauge_cov = solved[split : split + OBJECT_DIM * system.n_objects]
    gauge_cov = gauge.rows @ solved[:split]
    return about_trajectory(marginals, object_gauge_cov, gauge_cov, np.asarray(objects)[:, :2], gauge.centroid_xy)


def object_error_covariance_about_trajectory(
    system: AssociationSystem,
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
    k, split = system.n_objects, POSE_DIM * system.n_poses
    rows = np.zeros((OBJECT_DIM * k, system.dimension))
    rows[:, split : split + OBJECT_DIM * k] = np.eye(OBJECT_DIM * k)
    if system.n_poses >= 2:
        gauge = trajectory_gauge(poses[:, :2], pose_weights)
        motion = object_motion(objects[:, :2], gauge.centroid_xy, OBJECT_DIM).reshape(-1, GAUGE_DIM)
        rows[:, :split] -= motion @ gauge.rows
    groups = noise_groups(system, poses, objects, calib, object_bias_share)
    result = error_covariance(sparse_information(system, lin), groups, rows, prior_scale(system))
    diagonal = np.arange(k)

    def blocks(cov: NDArray) -> NDArray:
        return cov.reshape(k, OBJECT_DIM, k, OBJECT_DIM)[diagonal, :, diagonal, :]

    return result._replace(covariance=blocks(result.covariance), posterior=blocks(result.posterior))


def calibration_covariance(system: AssociationSystem, fac: Factorization) -> NDArray[np.float64]:
    """(C, C) marginal covariance of the odometry calibration (undamped factorization)."""
    if not system.n_calib:
        return np.zeros((0, 0))
    return dense_inverse_columns(system, fac, OBJECT_DIM * system.n_objects, system.n_calib)


def prior_scale(system: AssociationSystem) -> NDArray[np.float64]:
    """(n,) per variable, the spread of the truth about its prior's mean over the prior's stddev.

    1 but for the objects' class priors (``problem.prior_spread``): what the error
    covariance scales each prior's information by (:mod:`objslam_mapper.graph.error_covariance`).
    """
    scale = np.ones(system.dimension)
    first = POSE_DIM * system.n_poses
    scale[first : first + OBJECT_DIM * system.n_objects] = (system.prior_spread * system.prior_inv_sigma).ravel()
    return scale


def noise_groups(
    system: AssociationSystem,
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
    n, dim = system.n_poses, system.dimension
    lay = system.layout
    pred, sl, weight = system.whitened_slices(poses, objects)
    kept = np.flatnonzero(system.within_caps(sl) if inliers is None else inliers)
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
        values = np.concatenate([(jac[c, :3] * POSE_SIGN[:, None]).T, jac[c, OBJECT_COLUMNS].T], axis=1)
        jacobian = scipy.sparse.csr_matrix((values.ravel(), columns.ravel(), indptr), shape=(len(kept), dim))
        groups.append(NoiseGroup(name, jacobian, sl[c, kept], lay.object_of[kept], float(object_bias_share[c])))
    return groups + _odometry_groups(system, poses, calib)


def _odometry_groups(system: AssociationSystem, poses: NDArray, calib: NDArray) -> list[NoiseGroup]:
    """The odometry factors' whitened rows: translation (x, y) and turn (:meth:`_odometry`'s error)."""
    n, dim = system.n_poses, system.dimension
    if n < 2:
        return []
    w, wt, k, m, dx, dy, q1, q2, dtheta, e1, e2, e3 = system.odometry_terms(poses, calib)[5]
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
    if system.n_calib:
        first_calib = np.full(n - 1, dim - system.n_calib)
        xy_cols.append(first_calib)
        e1_vals.append(w * q1)
        e2_vals.append(w * q2)
        theta_cols += [first_calib + 1, first_calib + 2]
        theta_vals += [wt * dtheta, wt * system.problem.increment_path_length_m]

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
