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

    P(no overlap of i, j) ~= Phi((D - g) / s),

``s^2`` the variance of ``D - g`` linearized at the MAP (each object's location, diameter
and their correlation). The pairs are taken as independent, so
``log P(no overlap | J, Z) = sum over pairs of log Phi(...)``. The covariances are each
object's with the robot's poses held at the MAP: the pose errors two nearby
objects share cancel in their offset, and this is what is left. Pairs whose gap is
many standard deviations clear contribute nothing and are not evaluated.

For two real objects 0.7 m apart the term is 0; for a duplicate 0.15 m from its original
(location stddevs ~0.02 m) it is hundreds of nats, far more than the 20-40 nats the
duplicate gains by absorbing a merged blob. The prior holds with probability
``1 - exp(floor)`` only (``sampler.exclusion_floor_nats``, -60): one object may stand on
another, and a term without a floor is a wall the chain cannot cross. Out and back with
drift, the start state can join the wrong tracklets (one object's outward tracklet with
its neighbour's return), and every single move towards the truth first makes a duplicate;
at -60 nats a pair, a duplicate still loses to a merge but the path stays open.
Distractors (clutter tracklets explained by a static thing of unknown shape) are not in
it: a poster may hang behind an object.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr

from objslam_mapper.graph.conditional_evidence import object_information
from objslam_mapper.graph.problem import GraphProblem

# With this log probability (nats) a pair may overlap all the same (DEFAULT_FLOOR below).
DEFAULT_FLOOR = -60.0
# Pairs whose MAP footprints are this far apart (m) are not evaluated: with location
# stddevs of centimetres, their term is 0 to many digits.
_EVALUATED_GAP_M = 0.3


def near_pairs(objects: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs (i < j) of (K, 5) objects whose MAP footprints are within the evaluated gap."""
    objects = np.asarray(objects, dtype=float).reshape(-1, 5)
    i, j = np.triu_indices(len(objects), 1)
    dist = np.hypot(*(objects[i, :2] - objects[j, :2]).T)
    near = dist - 0.5 * (objects[i, 3] + objects[j, 3]) < _EVALUATED_GAP_M
    return i[near], j[near]


def pairs_log_probability(
    objects: NDArray[np.float64],
    covariances: dict[int, NDArray[np.float64]],
    pairs: tuple[NDArray[np.int64], NDArray[np.int64]],
    floor: float = -np.inf,
) -> float:
    """Sum over ``pairs`` of ``max(log Phi((D - g) / s), floor)`` (module docstring).

    ``objects`` (K, 5) as (x, y, z_base, diameter, height), ``covariances[k]`` the (5, 5)
    covariance of object k; a pair with an undetermined object (no finite variance) counts 0.
    """
    objects = np.asarray(objects, dtype=float).reshape(-1, 5)
    total = 0.0
    for a, b in zip(*pairs, strict=True):
        delta = objects[a, :2] - objects[b, :2]
        dist = float(np.hypot(*delta))
        u = delta / dist if dist > 0.0 else np.array([1.0, 0.0])
        # Linearized: d (D - g) / d object a = (u, 0, -1/2, 0), / d object b = (-u, 0, -1/2, 0).
        grad_a = np.array([u[0], u[1], 0.0, -0.5, 0.0])
        grad_b = np.array([-u[0], -u[1], 0.0, -0.5, 0.0])
        var = grad_a @ covariances[a] @ grad_a + grad_b @ covariances[b] @ grad_b
        if not np.isfinite(var) or var <= 0.0:
            continue  # an object the model cannot place says nothing about overlap
        gap = 0.5 * (objects[a, 3] + objects[b, 3])
        total += max(float(log_ndtr((dist - gap) / np.sqrt(var))), floor)
    return total


def no_overlap_log_probability(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    objects: NDArray[np.float64],
    groups: Sequence[NDArray[np.int64] | None],
    priors: Sequence[int],
    floor: float = DEFAULT_FLOOR,
    *,
    pairs: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None,
) -> float:
    """``log P(no two objects overlap | J, Z)`` (module docstring), each pair's term at least
    ``floor``; over ``pairs`` (default: every pair near enough to matter).

    ``objects`` (K, 5) are the MAP objects (x, y, z_base, diameter, height) of ``groups``
    (their measurement indices) with prior rows ``priors``, ``map_T_base`` the MAP poses;
    each near object's covariance is its information's inverse with the poses held there.
    """
    objects = np.asarray(objects, dtype=float).reshape(-1, 5)
    pairs = near_pairs(objects) if pairs is None else pairs
    if not len(pairs[0]):
        return 0.0
    covariances: dict[int, NDArray[np.float64]] = {}
    for k in np.unique(np.concatenate(pairs)):
        group = groups[k]
        if group is None:
            raise ValueError(f"object {k} is in a pair but its measurements were not given")
        info = object_information(problem, map_T_base, group, objects[k], priors[k])
        covariances[int(k)] = np.full((5, 5), np.inf) if info is None else np.asarray(np.linalg.inv(info), dtype=float)
    return pairs_log_probability(objects, covariances, pairs, floor)
