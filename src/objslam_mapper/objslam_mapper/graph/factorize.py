"""Solving one association's normal equations: the Gauss-Newton step, ``log|Lambda|``, and the
solves the covariances need (docs/method.md, "Why it is fast").

Two ways, both exact (``log|Lambda|`` is what GTSAM's ``2 log|R|`` gives):

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
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg
from numpy.typing import NDArray
from scipy.linalg import lapack

from objslam_mapper.graph.bins import bin_sum
from objslam_mapper.graph.fold import POSE_BAND, FoldPlan, folded_steps
from objslam_mapper.graph.fold import fold as fold_objects
from objslam_mapper.graph.linearize import AssociationSystem, Linearization
from objslam_mapper.graph.problem import OBJECT_DIM, POSE_DIM


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
    folded: bool = False  # dense path with objects folded into the pose band: steps and log|Lambda| only


def _sparse_values(lin: Linearization) -> NDArray[np.float64]:
    """Block values in the order of _SparsePattern's entries."""
    off = lin.pose_off.ravel()
    cross = lin.cross.ravel()
    pc = lin.pose_calib.ravel()
    return np.concatenate(
        [lin.pose_diag.ravel(), off, off, cross, cross, lin.object_diag.ravel(), pc, pc, lin.calib_diag.ravel()]
    )


@functools.lru_cache(maxsize=8)
def _band_index(
    n_poses: int, half_width: int = POSE_BAND
) -> tuple[tuple[NDArray, NDArray], NDArray, tuple[NDArray, NDArray], NDArray]:
    """Where the pose blocks go in LAPACK upper banded storage ab[half_width + i - j, j]."""
    p, a, b = np.meshgrid(np.arange(n_poses), np.arange(3), np.arange(3), indexing="ij")
    upper = (a <= b).ravel()
    diag_at = ((half_width + a - b).ravel()[upper], (3 * p + b).ravel()[upper])
    diag_src = (9 * p + 3 * a + b).ravel()[upper]
    p, a, b = np.meshgrid(np.arange(max(n_poses - 1, 0)), np.arange(3), np.arange(3), indexing="ij")
    off_at = ((half_width + a - b - 3).ravel(), (3 * p + 3 + b).ravel())
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


def sparse_information(system: AssociationSystem, lin: Linearization, damping: float = 0.0) -> scipy.sparse.csc_matrix:
    """``Lambda`` of a linearization as a sparse matrix, Marquardt-damped if asked.

    Rows: poses, objects, calibration.
    """
    pattern = system.layout.sparse
    data = np.bincount(pattern.slot, weights=_sparse_values(lin), minlength=len(pattern.indices)).astype(
        float, copy=False
    )
    if damping > 0.0:
        data[pattern.diagonal_slots] *= 1.0 + damping
    return scipy.sparse.csc_matrix((data, pattern.indices, pattern.indptr), shape=(pattern.dimension,) * 2)


def information_matrix(system: AssociationSystem, lin: Linearization) -> NDArray[np.float64]:
    """The dense ``Lambda`` of a linearization (rows as in the sparse system)."""
    return sparse_information(system, lin).toarray()


def factorize(system: AssociationSystem, lin: Linearization, damping: float, *, fold: bool = True) -> Factorization:
    """Solve the normal equations, Marquardt-damped (``diag *= 1 + damping``) if asked.

    ``fold``: the dense path may fold short-lived objects into the pose band
    (:mod:`.fold`); the covariances need it off (they read the whole complement).
    Raises LinAlgError if the system is not positive definite.
    """
    if system.n_objects <= system.dense_object_limit:
        fac = _factorize_schur(system, lin, damping, system.layout.fold_plan if fold else None)
    else:
        fac = _factorize_sparse(system, lin, damping)
    # Decrease of the quadratic model: 1/2 (-g^T step + damping step^T diag(Lambda) step).
    predicted = -float(lin.grad_pose @ fac.step_pose + lin.grad_object @ fac.step_object)
    if system.n_calib:
        predicted -= float(lin.grad_calib @ fac.step_calib)
    if damping > 0.0:
        diag_pose, diag_object, diag_calib = lin.diagonal()
        predicted += damping * float(diag_pose @ fac.step_pose**2 + diag_object @ fac.step_object**2)
        if system.n_calib:
            predicted += damping * float(diag_calib @ fac.step_calib**2)
    fac.predicted_decrease = 0.5 * predicted
    return fac


def _factorize_schur(
    system: AssociationSystem, lin: Linearization, damping: float, plan: FoldPlan | None
) -> Factorization:
    """Poses first: with A = U^T U, W = U^-T B and w = U^-T g_pose, S = C - W^T W,
    step_dense = S^-1 (W^T w - g_dense), step_pose = -U^-1 (w + W step_dense).

    The dense variables are the objects, then the calibration (if estimated): ``B`` holds
    their pose blocks, ``C`` their own (objects and calibration share no factor). With a
    ``plan``, its folded objects are eliminated into ``A`` and ``g_pose`` first (:mod:`.fold`)
    and the dense variables are the objects it keeps."""
    n, k, nc = system.n_poses, system.n_objects, system.n_calib
    pose_diag, object_diag, calib_diag = lin.pose_diag, lin.object_diag, lin.calib_diag
    if damping > 0.0:
        pose_diag, object_diag, calib_diag = pose_diag.copy(), object_diag.copy(), calib_diag.copy()
        i3, i5 = np.arange(POSE_DIM), np.arange(OBJECT_DIM)
        pose_diag[:, i3, i3] *= 1.0 + damping
        object_diag[:, i5, i5] *= 1.0 + damping
        calib_diag[np.diag_indices(nc)] *= 1.0 + damping
    half_width = POSE_BAND if plan is None else plan.half_width
    diag_at, diag_src, off_at, off_src = _band_index(n, half_width)
    band = np.zeros((half_width + 1, POSE_DIM * n))
    band[diag_at] = pose_diag.ravel()[diag_src]
    band[off_at] = lin.pose_off.ravel()[off_src]
    grad_pose, grad_object = lin.grad_pose, lin.grad_object
    folded = None
    if plan is not None:
        folded = fold_objects(plan, lin.cross, object_diag, grad_object.reshape(k, OBJECT_DIM), n)
        band -= folded.band
        grad_pose = grad_pose - folded.grad_pose
        k = len(plan.kept)
        object_diag = object_diag[plan.kept]
        grad_object = grad_object.reshape(-1, OBJECT_DIM)[plan.kept].ravel()
    n_object_vars = OBJECT_DIM * k
    chol_pose = scipy.linalg.cholesky_banded(band, lower=False, check_finite=False)
    log_det = 2.0 * float(np.sum(np.log(chol_pose[half_width])))
    if folded is not None:
        log_det += folded.log_det
    rhs = np.empty((POSE_DIM * n, n_object_vars + nc + 1), order="F")
    if plan is None:
        rhs[:, :n_object_vars] = lin.pose_object(system.layout)
    else:
        rhs[:, :n_object_vars] = bin_sum(
            plan.kept_bins, lin.cross[:, :, plan.kept_slices], (POSE_DIM * n, n_object_vars)
        )
    rhs[:, n_object_vars:-1] = lin.pose_calib.reshape(POSE_DIM * n, nc)
    rhs[:, -1] = grad_pose
    start_rows = None
    # Rows above each object's first sighting are zero; with a few objects one plain solve
    # costs less than the bookkeeping of skipping them.
    if _staircase_groups(rhs.shape[1]) > 1:
        first_pose = system.layout.first_pose if plan is None else system.layout.first_pose[plan.kept]
        start_rows = np.concatenate([np.repeat(POSE_DIM * first_pose, OBJECT_DIM), np.zeros(nc + 1, dtype=np.int64)])
    whitened, gram = _whiten(chol_pose, rhs, start_rows)
    w_cross, w_grad = whitened[:, :-1], whitened[:, -1]
    chol_schur = None
    step_dense = np.zeros(0)
    if n_object_vars + nc:
        schur = -gram[:-1, :-1]
        schur[_block_diag_index(k, OBJECT_DIM)] += object_diag.ravel()
        schur[n_object_vars:, n_object_vars:] += calib_diag
        grad_dense = np.concatenate([grad_object, lin.grad_calib]) if nc else grad_object
        chol_schur = scipy.linalg.cholesky(schur, lower=False, check_finite=False)
        log_det += 2.0 * float(np.sum(np.log(np.diag(chol_schur))))
        step_dense = scipy.linalg.cho_solve((chol_schur, False), w_cross.T @ w_grad - grad_dense, check_finite=False)
    back, info = lapack.dtbtrs(chol_pose, (w_grad + w_cross @ step_dense)[:, None], uplo="U", trans="N")
    if info != 0:
        raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
    step_pose = -back[:, 0]
    step_object = step_dense[:n_object_vars]
    if plan is not None and folded is not None:  # the folded objects' steps from the poses'; no complement kept
        steps = np.empty((system.n_objects, OBJECT_DIM))
        steps[plan.kept] = step_object.reshape(-1, OBJECT_DIM)
        steps[plan.folded] = folded_steps(plan, folded, step_pose)
        return Factorization(
            log_det=log_det,
            step_pose=step_pose,
            step_object=steps.ravel(),
            predicted_decrease=0.0,
            step_calib=step_dense[n_object_vars:],
            folded=True,
        )
    return Factorization(
        log_det=log_det,
        step_pose=step_pose,
        step_object=step_object,
        predicted_decrease=0.0,
        step_calib=step_dense[n_object_vars:],
        chol_schur=chol_schur,
        chol_pose=chol_pose,
        w_cross=w_cross,
    )


# Column groups of the staircase in _whiten: 4 to 16 took the same time on ``loop``'s
# many-object states; fewer leave rows of zeros in, more pay numpy's per-call overhead,
# which on a state of a few objects is more than the rows saved.
_STAIRCASE_GROUPS = 8
_STAIRCASE_MIN_COLUMNS = 40


def _staircase_groups(columns: int) -> int:
    """How many column groups :func:`_whiten` takes (1: one plain solve)."""
    return max(1, min(_STAIRCASE_GROUPS, columns // _STAIRCASE_MIN_COLUMNS))


def _whiten(
    chol_pose: NDArray[np.float64], rhs: NDArray[np.float64], start_rows: NDArray[np.int64] | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``X = U^-T rhs`` and its Gram matrix ``X^T X``, skipping rows known to be zero.

    Column c of ``rhs`` is zero above ``start_rows[c]`` (an object's pose-object block starts
    at the first pose that saw it), and so is column c of X, ``U^T`` being lower triangular.
    The columns are taken in groups in order of their start: each group is solved on the
    band's trailing part only, and two groups' product runs over the rows both can be
    nonzero in (docs/method.md, "Why it is fast"). Without ``start_rows`` (the caller's
    choice, :func:`_staircase_groups`), one plain solve."""
    if start_rows is None:
        whitened, info = lapack.dtbtrs(chol_pose, rhs, uplo="U", trans="T", overwrite_b=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
        return whitened, whitened.T @ whitened
    order = np.argsort(start_rows, kind="stable")
    whitened = np.zeros(rhs.shape, order="F")
    groups = []
    for columns in np.array_split(order, _staircase_groups(len(start_rows))):
        first = int(start_rows[columns[0]])
        # Through the transposes: Fortran-ordered columns picked and written without a copy.
        part = rhs.T[columns, first:].T
        solved, info = lapack.dtbtrs(chol_pose[:, first:], part, uplo="U", trans="T", overwrite_b=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
        whitened.T[columns, first:] = solved.T
        groups.append((first, columns, solved))
    gram = np.empty((rhs.shape[1],) * 2)
    for i, (first, columns, solved) in enumerate(groups):
        gram[np.ix_(columns, columns)] = solved.T @ solved
        for later_first, later_columns, later_solved in groups[i + 1 :]:
            product = solved[later_first - first :].T @ later_solved
            gram[np.ix_(columns, later_columns)] = product
            gram[np.ix_(later_columns, columns)] = product.T
    return whitened, gram


def _factorize_sparse(system: AssociationSystem, lin: Linearization, damping: float) -> Factorization:
    matrix = sparse_information(system, lin, damping)
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
    split = POSE_DIM * system.n_poses
    split_calib = split + OBJECT_DIM * system.n_objects
    return Factorization(
        log_det=float(np.sum(np.log(pivots))),
        step_pose=step[:split],
        step_object=step[split:split_calib],
        predicted_decrease=0.0,
        step_calib=step[split_calib:],
        sparse_lu=lu,
    )


def dense_inverse_columns(system: AssociationSystem, fac: Factorization, first: int, count: int) -> NDArray[np.float64]:
    """Rows and columns [first, first + count) of the inverse over the dense variables."""
    if fac.chol_schur is not None:
        unit = np.zeros((len(fac.chol_schur), count))
        unit[first : first + count] = np.eye(count)
        inv = scipy.linalg.cho_solve((fac.chol_schur, False), unit, check_finite=False)
        return inv[first : first + count]
    split = POSE_DIM * system.n_poses
    unit = np.zeros((split + OBJECT_DIM * system.n_objects + system.n_calib, count))
    unit[split + first : split + first + count] = np.eye(count)
    # A folded factorization keeps no inverse: the covariances factorize with fold=False.
    assert fac.sparse_lu is not None and not fac.folded
    return fac.sparse_lu.solve(unit)[split + first : split + first + count]


def solve_pose_rhs(system: AssociationSystem, fac: Factorization, rhs_pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """``Lambda^-1 [rhs_pose; 0]`` for (3N, m) right-hand sides on the poses only (undamped factorization).

    Dense path, with ``z = U^-T r``: dense part ``x_d = -S^-1 W^T z``, poses
    ``x_p = U^-1 (z - W x_d)``. Rows as in the sparse system: poses, objects, calibration.
    """
    rhs_pose = np.asarray(rhs_pose, dtype=float)
    if fac.sparse_lu is not None:
        rhs = np.zeros((POSE_DIM * system.n_poses + OBJECT_DIM * system.n_objects + system.n_calib, rhs_pose.shape[1]))
        rhs[: len(rhs_pose)] = rhs_pose
        return fac.sparse_lu.solve(rhs)
    assert fac.chol_pose is not None and fac.w_cross is not None  # the dense path's, not folded
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
