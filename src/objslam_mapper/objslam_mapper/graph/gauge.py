r"""Object covariances about the trajectory: the gauge a map's covariances are reported in.

The graph anchors its first pose, so its plain marginals say how well each object is
known relative to where the robot *started*: far from the start they hold the drift of
the heading and position on the way there, a gauge choice, not anything about the map.
What a map is judged by (``objslam eval`` fits the whole trajectory to the ground truth
by least squares before it measures object errors) and what a user relates objects to is
the trajectory as a whole. So the reported covariance is that of each object's error
after the small rigid motion that best explains the trajectory's error is taken out.

Linearized: pose positions ``p_i`` (weights ``w_i``, centroid ``p̄``, ``c_i = p_i - p̄``)
with errors ``δp_i``; the least-squares rigid motion of them is the translation
``t = Σ w_i δp_i / Σ w_i`` and the rotation ``φ = Σ w_i (J c_i)·δp_i / Σ w_i |c_i|²``
about ``p̄`` (``J`` the 90° rotation), ``g = G δx`` for the pose rows ``G``. An object at
``o`` moves with it by ``M g``, ``M = [I₂ | J (o - p̄)]`` on its x, y and nothing on
z_base and size, so its error about the trajectory is ``δo - M G δx`` with covariance

    Σ_oo - M Σ_go - Σ_og Mᵀ + M Σ_gg Mᵀ,    Σ_og = E_o Λ⁻¹ Gᵀ,  Σ_gg = G Λ⁻¹ Gᵀ,

three solves with the factorization the marginals already come from. The Laplace
evidence (a determinant) does not depend on this choice; only reported covariances do.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

GAUGE_DIM = 3  # translation x, y and rotation about the trajectory's centroid


class TrajectoryGauge(NamedTuple):
    """The linear functional ``g = rows @ δposes`` and the point the rotation is about."""

    rows: NDArray[np.float64]  # (3, 3 N) over the (x, y, theta) pose variables
    centroid_xy: NDArray[np.float64]  # (2,) m


def trajectory_gauge(map_xy_pose: ArrayLike, weights: ArrayLike | None = None) -> TrajectoryGauge:
    """The rigid motion that best fits (N, 2) pose positions' errors, each weighted (default 1)."""
    xy = np.asarray(map_xy_pose, dtype=float).reshape(-1, 2)
    w = np.ones(len(xy)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    centroid = (w @ xy) / w.sum()
    c = xy - centroid
    spread = float(w @ np.einsum("ni,ni->n", c, c))
    rows = np.zeros((GAUGE_DIM, 3 * len(xy)))
    rows[0, 0::3] = w / w.sum()
    rows[1, 1::3] = w / w.sum()
    if spread > 0.0:  # a robot that never moved: no rotation to fit
        rows[2, 0::3] = -w * c[:, 1] / spread
        rows[2, 1::3] = w * c[:, 0] / spread
    return TrajectoryGauge(rows, centroid)


def object_motion(object_xy: ArrayLike, centroid_xy: ArrayLike, object_dim: int) -> NDArray[np.float64]:
    """(K, object_dim, 3) ``M``: how each object's variables move with the gauge (x, y only)."""
    xy = np.asarray(object_xy, dtype=float).reshape(-1, 2)
    motion = np.zeros((len(xy), object_dim, GAUGE_DIM))
    lever = xy - np.asarray(centroid_xy, dtype=float)
    motion[:, 0, 0] = 1.0
    motion[:, 1, 1] = 1.0
    motion[:, 0, 2] = -lever[:, 1]
    motion[:, 1, 2] = lever[:, 0]
    return motion


def about_trajectory(
    object_cov: ArrayLike,
    object_gauge_cov: ArrayLike,
    gauge_cov: ArrayLike,
    object_xy: ArrayLike,
    centroid_xy: ArrayLike,
) -> NDArray[np.float64]:
    """(K, D, D) covariances about the trajectory of objects at (K, 2) ``object_xy``.

    From their marginals (K, D, D), ``Σ_og`` (the objects' rows of ``Λ⁻¹ Gᵀ``, (K D, 3)
    or (K, D, 3)) and ``Σ_gg`` (3, 3) of the gauge about ``centroid_xy``.
    """
    cov = np.asarray(object_cov, dtype=float)
    cross = np.asarray(object_gauge_cov, dtype=float).reshape(cov.shape[0], cov.shape[1], GAUGE_DIM)
    m = object_motion(object_xy, centroid_xy, cov.shape[1])
    m_cross = np.einsum("kag,kbg->kab", m, cross)  # M Σ_go
    aligned = cov - m_cross - np.swapaxes(m_cross, 1, 2) + m @ np.asarray(gauge_cov, dtype=float) @ np.swapaxes(m, 1, 2)
    return 0.5 * (aligned + np.swapaxes(aligned, 1, 2))
