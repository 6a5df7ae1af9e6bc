r"""Objects are solid: the prior that no two of them interpenetrate, under the Laplace posterior.

The paper's ``P(J)`` is uniform, and its objects may lie anywhere. Real objects cannot
share floor space, yet an association can place two of them in one spot: a blob merged
with a same-colour neighbour for a few frames chains into a tracklet that, as an object of
its own, sits 0.1-0.2 m beside the real one and absorbs the slices that fit it worse. The
Gaussian evidence happily pays an Occam factor for that duplicate. With a prior on the
objects' configuration that is uniform except where two footprints (discs of their
diameters) overlap, the evidence of ``J`` becomes the Laplace evidence times the posterior
probability that no two objects of ``J`` overlap (the prior's normalizer, the share of
configurations that overlap nowhere, is close to 1 for objects this small in a room and
is left out). Per pair ``(i, j)``, with the MAP offset ``delta`` of their axes, its length
``D`` and direction ``u``, and the required gap ``g = (d_i + d_j) / 2``:

    P(no overlap of i, j) ~= Phi((D - g) / s),   s^2 = u^T (C_i + C_j) u + (var d_i + var d_j) / 4,

``C`` the horizontal location covariances. The pairs are taken as independent, so
``log P(no overlap | J, Z) = sum over pairs of log Phi(...)``. ``C`` and ``var d`` are each
object's covariance with the robot's poses held at the MAP: the pose errors two nearby
objects share cancel in their offset, and this is what is left. Pairs whose gap is
many standard deviations clear contribute nothing and are not evaluated.

For two real objects 0.7 m apart the term is 0; for a duplicate 0.15 m from its original
(location stddevs ~0.02 m) it is about -60 nats, which outweighs the few tens of nats the
duplicate gains by absorbing a merged blob. Distractors (clutter tracklets explained by a
static thing of unknown shape) are not in it: a poster may hang behind an object.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr

from objslam_mapper.conditional_evidence import object_information
from objslam_mapper.problem import GraphProblem

# Pairs whose MAP footprints are this far apart (m) are not evaluated: with location
# stddevs of centimetres, their term is 0 to many digits.
_EVALUATED_GAP_M = 0.3


def no_overlap_log_probability(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    objects: NDArray[np.float64],
    groups: Sequence[NDArray[np.int64]],
    priors: Sequence[int],
) -> float:
    """``log P(no two objects overlap | J, Z)`` (module docstring).

    ``objects`` (K, 5) are the MAP objects (x, y, z_base, diameter, height) of ``groups``
    (their measurement indices) with prior rows ``priors``, ``map_T_base`` the MAP poses.
    """
    objects = np.asarray(objects, dtype=float).reshape(-1, 5)
    k = len(objects)
    if k < 2:
        return 0.0
    i, j = np.triu_indices(k, 1)
    delta = objects[i, :2] - objects[j, :2]
    dist = np.hypot(delta[:, 0], delta[:, 1])
    gap = 0.5 * (objects[i, 3] + objects[j, 3])
    near = np.flatnonzero(dist - gap < _EVALUATED_GAP_M)
    if not len(near):
        return 0.0
    covariance: dict[int, NDArray[np.float64]] = {}
    for index in np.unique(np.concatenate([i[near], j[near]])):
        info = object_information(problem, map_T_base, groups[index], objects[index], priors[index])
        covariance[int(index)] = np.full((5, 5), np.inf) if info is None else np.linalg.inv(info)
    total = 0.0
    for p in near:
        a, b = int(i[p]), int(j[p])
        u = delta[p] / dist[p] if dist[p] > 0.0 else np.array([1.0, 0.0])
        var = u @ (covariance[a][:2, :2] + covariance[b][:2, :2]) @ u + 0.25 * (
            covariance[a][3, 3] + covariance[b][3, 3]
        )
        if not np.isfinite(var) or var <= 0.0:
            continue  # an object the model cannot place says nothing about overlap
        total += float(log_ndtr((dist[p] - gap[p]) / np.sqrt(var)))
    return total
