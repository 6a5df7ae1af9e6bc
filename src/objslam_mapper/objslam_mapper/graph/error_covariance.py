r"""Covariance of the estimate's error: the noise as the residuals show it, and a bias per object.

The posterior covariance ``Λ⁻¹`` is exact only when the configured noise is the real
one. It is not, on purpose: the association needs slice noise several times the
detector's (a tracklet must still join its object through merged and cut blobs), and
the odometry noise is a guess at an unknown robot. On ground-truth association the
configured noise makes ``Λ⁻¹`` several times too large. So the covariances a map reports
are those of the error of the estimate actually computed, the MAP under the configured
weights ``x̂ = x + Λ⁻¹ Jᵀ e`` (whitened, linearized), under the noise the data show:
``Cov = Λ⁻¹ B Λ⁻¹`` with ``B = Jᵀ Cov(e) J`` plus the priors' part. A sandwich, as in
M-estimation (Huber 1967, White 1980). A prior adds the spread of the truth about its
mean: its information scaled by ``(spread / stddev)²``, which is 1 where the prior is the
spread of real instances (sizes, table heights) and 0 for a floor object's base height,
whose truth is the prior's mean (it stands on the floor) and whose stddev is slack for the
MAP (a floor prior as tight as the floor turns the detector's lower-edge bias into range
error). ``Cov(e)`` of the measurements is made of two parts:

- **White noise, each measurement's own**: the heteroscedasticity-consistent estimate
  ``r_i² / (1 - h_ii)`` (MacKinnon and White's HC2; ``h_ii`` the row's leverage
  ``J_i Λ⁻¹ J_iᵀ``, so each term is unbiased for its variance). It needs no noise level
  per kind of measurement, and a slice of a merged blob that stays within its outlier cap
  weighs what its residual says, not what the configured noise says. For the slices the
  residuals are taken about each object's mean: that part is the bias below, not noise.
- **A bias per object**: the detector's edges are off by about the same amount in every
  image of one object (the colour blend against that floor, its shading, a neighbour that
  keeps cutting it), and hundreds of slices do not average that away. Each slice
  component carries an error common to all slices of its object with standard deviation
  ``share_k`` times the slice's configured stddev (``solver.error_covariance.*_bias_share``),
  so cut blobs (4x) and the hidden lower edge of raised objects get their larger biases;
  an object whose own residual mean shows a larger bias, beyond what chance gives the
  configured one, gets that (:func:`bias_shares`).

With whitened Jacobians ``J_k`` per noise group (bearing, width, lower edge, upper edge,
odometry translation, odometry turn), the weights ``W_k = diag(r_i² / (1 - h_ii))`` and
per-object indicator rows ``S_k`` (the object's share on its slices),
``B = D Λ_rest D + Σ_k (J_kᵀ W_k J_k + (S_k J_k)ᵀ(S_k J_k))``, ``Λ_rest`` the priors'
information (diagonal) and ``D`` their spread over their stddev. For reported rows ``R`` (the
objects about the trajectory, :mod:`objslam_mapper.graph.gauge`), with ``X = Λ⁻¹ Rᵀ`` that is
``Xᵀ B X``. The MAP, the evidence and the existence test are unchanged: they are the model's.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import scipy.linalg
import scipy.sparse
from numpy.typing import NDArray

from objslam_mapper.errors import MapperError

logger = logging.getLogger(__name__)

# A row that determines its own fit almost alone (leverage near 1) says little about its noise;
# its HC2 weight is capped at this many times its squared residual.
MAX_INFLATION = 100.0
# An object's own bias counts where its residual mean squared is this many times what the
# configured bias and the white noise explain (chi-square of 1 dof at two sigma: 4.6 % of
# objects at the configured bias pass by chance).
OWN_BIAS_SIGNIFICANCE = 4.0
# An object's residual mean shows at least this share of its bias (the state took up the rest):
# below it, the estimate of the bias from the mean would be mostly noise.
MIN_VISIBLE = 0.05


class ErrorCovarianceError(MapperError, ValueError):
    """The information matrix the error covariance needs is not positive definite."""


class NoiseGroup(NamedTuple):
    """Whitened residuals of one kind of measurement, and which object each belongs to."""

    name: str
    jacobian: scipy.sparse.csr_matrix  # (m, n) whitened, over the whole state
    residual: NDArray[np.float64]  # (m,) whitened
    owner: NDArray[np.int64] | None = None  # (m,) object of each row, whose rows share a bias; None: no bias
    bias_share: float = 0.0  # stddev of that bias, in units of the rows' configured stddev


class ErrorCovariance(NamedTuple):
    covariance: NDArray[np.float64]  # (r, r) of the reported rows
    posterior: NDArray[np.float64]  # (r, r) R Λ⁻¹ Rᵀ, the same rows under the configured noise
    levels: dict[str, float]  # per group, the mean white noise variance over the configured


def row_leverages(jacobian: scipy.sparse.csr_matrix, inverse: NDArray[np.float64]) -> NDArray[np.float64]:
    """``diag(J Λ⁻¹ Jᵀ)`` of a Jacobian with the same number of entries in every row.

    ``inverse`` may hold ``Λ⁻¹`` in its upper triangle only (LAPACK's ``potri``): every
    entry is read there, at (min, max) of its row and column.
    """
    m = jacobian.shape[0]
    if m == 0:
        return np.zeros(0)
    width = jacobian.indptr[1] - jacobian.indptr[0]
    if not np.all(np.diff(jacobian.indptr) == width):
        raise ValueError("row_leverages needs the same number of entries in every row")
    columns = jacobian.indices.reshape(m, width)
    values = jacobian.data.reshape(m, width)
    first, second = columns[:, :, None], columns[:, None, :]
    block = inverse[np.minimum(first, second), np.maximum(first, second)]
    return np.einsum("ma,mab,mb->m", values, block, values)


def white_weights(group: NoiseGroup, inverse: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each row's white noise variance over the configured, ``r_i² / (1 - h_ii)`` (HC2).

    With objects, ``r`` is taken about its object's mean, which takes ``1 / n_j`` more of
    each row's redundancy.
    """
    r = np.asarray(group.residual, dtype=float)
    if not len(r):
        return np.zeros(0)
    redundancy = 1.0 - row_leverages(group.jacobian, inverse)
    if group.owner is not None:
        count = np.bincount(group.owner).astype(float)
        r = r - (np.bincount(group.owner, weights=r) / np.maximum(count, 1.0))[group.owner]
        redundancy -= 1.0 / count[group.owner]
    return r * r / np.maximum(redundancy, 1.0 / MAX_INFLATION)


def owner_rows(group: NoiseGroup, values: NDArray[np.float64]) -> scipy.sparse.csr_matrix:
    """(G, m): row j holds ``values`` (m,) on the rows of object j and zeros elsewhere."""
    owner = _owners(group)
    m = len(group.residual)
    return scipy.sparse.csr_matrix((values, (owner, np.arange(m))), shape=(int(owner.max()) + 1, m))


def _owners(group: NoiseGroup) -> NDArray[np.int64]:
    if group.owner is None:
        raise ValueError(f"noise group {group.name} has no objects")
    return group.owner


def bias_shares(group: NoiseGroup, inverse: NDArray[np.float64], weights: NDArray[np.float64]) -> NDArray[np.float64]:
    """(G,) each object's bias share: the configured one, or more where its own residuals show more.

    ``inverse``: ``Λ⁻¹``, its upper triangle read (:func:`row_leverages`).

    A bias ``b`` on object ``j``'s rows leaves ``v_j b`` in the mean of its residuals, where
    ``v_j = 1 - g_jᵀ Λ⁻¹ g_j / n_j`` (``g_j = J_jᵀ 1``) is the part the state does not take
    up; the white noise adds its mean weight over ``n_j``. So ``(r̄_j² - w̄_j / n_j) / v_j²``
    estimates ``b²`` from the one object (``v_j`` at least ``MIN_VISIBLE``), and the share
    is the larger of that and the configured ``bias_share``: an object that is cut or merged
    for much of its track (a bias many times the typical) says so, the others keep the
    detector's typical bias. Divided by ``v_j²``, the estimate is noisy where the state
    takes up most of a bias, so it counts only where ``r̄_j²`` exceeds
    ``OWN_BIAS_SIGNIFICANCE`` times what the configured bias and the white noise explain
    (``v_j² share² + w̄_j / n_j``): a test at two standard deviations. Without it a quarter
    of the objects of a synthetic run at the configured bias got more, and the oracle maps'
    covariances were pessimistic (``twins`` mean NEES xyz 1.66 against a band from 1.73).
    """
    owner = _owners(group)
    owners = int(owner.max()) + 1
    count = np.maximum(np.bincount(owner, minlength=owners).astype(float), 1.0)
    mean = np.bincount(owner, weights=group.residual, minlength=owners) / count
    white = np.bincount(owner, weights=weights, minlength=owners) / count
    totals = (owner_rows(group, np.ones(len(group.residual))) @ group.jacobian).toarray()  # g_j
    solved = scipy.linalg.blas.dsymm(1.0, inverse, totals.T, lower=0)  # Λ⁻¹ g_j, its upper triangle read
    taken = np.sum(solved.T * totals, axis=1)  # g_jᵀ Λ⁻¹ g_j
    visible = np.clip(1.0 - taken / count, MIN_VISIBLE, 1.0)
    own = (mean**2 - white / count) / visible**2
    # Under the configured bias the mean is N(0, v² share² + w̄ / n): only a mean far outside
    # that says the object is worse (dividing by v² makes the estimate noisy where v is small).
    expected = visible**2 * group.bias_share**2 + white / count
    worse = mean**2 > OWN_BIAS_SIGNIFICANCE * expected
    return np.sqrt(np.where(worse, np.maximum(group.bias_share**2, own), group.bias_share**2))


def error_covariance(
    information: NDArray[np.float64] | scipy.sparse.spmatrix,
    groups: Sequence[NoiseGroup],
    rows: NDArray[np.float64],
    prior_scale: NDArray[np.float64] | None = None,
) -> ErrorCovariance:
    """Covariance of the error of ``rows @ state`` (module docstring).

    ``information`` is the ``Λ`` the MAP was solved with (dense or sparse): the groups'
    ``J_kᵀ J_k`` plus the priors' (the rest), at the MAP. ``prior_scale`` (n,) is, per state
    variable, the spread of the truth about its prior's mean over the prior's stddev (``D``;
    default 1: every prior as stated).

    The rows' leverages need entries of ``Λ⁻¹`` all over it, so it is inverted densely
    (``potri``, its upper triangle read in place); everything else stays sparse: the
    priors' part is a diagonal, and built dense it took a third of the time on a
    2800-variable graph.
    """
    sparse = scipy.sparse.csr_matrix(information)
    dense = sparse.toarray() if scipy.sparse.issparse(information) else np.asarray(information, dtype=float)
    try:
        factor = scipy.linalg.cho_factor(dense, lower=False, check_finite=False)
    except np.linalg.LinAlgError as exc:
        raise ErrorCovarianceError(f"information matrix is not positive definite: {exc}") from exc
    inverse, info = scipy.linalg.lapack.dpotri(factor[0], lower=False)  # its upper triangle only
    if info != 0:
        raise ErrorCovarianceError(f"information matrix could not be inverted (LAPACK info {info})")
    solved = scipy.linalg.cho_solve(factor, rows.T, check_finite=False)  # X = Λ⁻¹ Rᵀ
    posterior = rows @ solved
    rest = sparse
    covariance = np.zeros_like(posterior)
    levels = {}
    for group in groups:
        rest = rest - group.jacobian.T @ group.jacobian
        if not len(group.residual):
            continue
        weights = white_weights(group, inverse)
        levels[group.name] = float(weights.mean())
        projected = group.jacobian @ solved  # J_k X
        covariance += (weights[:, None] * projected).T @ projected
        if group.owner is not None and group.bias_share > 0.0:
            share = bias_shares(group, inverse, weights)
            common = owner_rows(group, share[group.owner]) @ projected  # S_k J_k X
            covariance += common.T @ common
    if prior_scale is not None:
        scale = scipy.sparse.diags(np.asarray(prior_scale, dtype=float))
        rest = scale @ rest @ scale
    covariance += solved.T @ (rest @ solved)
    logger.debug("white noise over the configured: %s", ", ".join(f"{k} {v:.3g}" for k, v in levels.items()))
    return ErrorCovariance(0.5 * (covariance + covariance.T), 0.5 * (posterior + posterior.T), levels)
