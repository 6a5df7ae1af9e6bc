r"""Missed detections: an object must also explain the images it is absent from.

The paper's likelihood (and the evidence of :mod:`objslam_mapper.solver`) scores the
slices an object owns and nothing else, as if an object were detected exactly where it was
seen. Then two short tracklets far apart in time can together pin a confident *ghost*: on
a rendered office, six slices of a cyan object blurred with a poster behind it, on the
first pass, and eight of the poster alone, 390 images later, made a cyan object where
there was none, which the robot faced in 190 images without ever detecting it.

The detector is modelled instead: in every image, each thing the camera should see is
detected with probability ``P_d`` (``detection.probability``), independently of the other
images and things. A detection costs ``log P_d`` whatever explains it (an object or a
distractor: both are things that are there), so those terms are the same in every
association and drop out (for the slices of independent false alarms, a small bias of
0.36 nats per slice at the default, against the ~20 nats a slice is worth to an object).
What differs is the misses: the likelihood of ``J`` gains, per object and per distractor
(the cylinder it is fitted as),

    n_miss log(1 - P_d),

``n_miss`` the images where it should be seen and has none of its slices. "Should be
seen", at the MAP of ``J`` (:func:`sightings`):

- its predicted angular width is at least ``detection.min_angular_width_rad`` (twice the
  detector's narrowest blob by default: marginal blobs are not counted as misses), and it
  is no farther than ``detection.max_range_m``;
- its lower edge is below the top of the camera's view, read off the data: the
  ``detection.view_top_quantile`` quantile of every slice's upper edge (a slice of an
  object cut by the edge of the view has its upper edge there);
- no nearer object or distractor covers more than half of its bearing interval.

Distractors pay their misses as objects do: otherwise clutter would be an escape from the
term (an object split in two across a loop misses in the images of the other half; as a
distractor it would not), and the chain would clear real objects into it. A flat poster
is not seen from behind, which a cylinder is: such misses make independent false alarms
(no misses) more attractive for it, which keeps it in clutter all the same. What the
visibility test gets wrong (tables hiding objects, lighting) shows up as a
few misses of real objects; at the default ``P_d = 0.7`` a miss costs 1.2 nats, a slice an
object owns is worth about 20 to it, so a real object is never lost to them, while a ghost
in view of hundreds of images without a detection pays hundreds of nats.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from objslam_mapper.config import setting
from objslam_mapper.geometry import wrap_angle
from objslam_mapper.problem import GraphProblem
from objslam_mapper.slice_model import BEARING, ELEVATION_BOTTOM, WIDTH, predict_reduced


@dataclass(frozen=True)
class DetectionConfig:
    """The detector's detection probability and when an object counts as in view."""

    enabled: bool = setting(True, "objects pay for the images where they should be seen and are not")
    probability: float = setting(
        0.7, "probability that an object in view is detected in an image", minimum=1e-6, maximum=1.0 - 1e-6
    )
    min_angular_width_rad: float = setting(
        0.035, "an object counts as in view only when its predicted width is at least this (rad)", minimum=0.0
    )
    max_range_m: float = setting(
        10.0,
        "... and no farther than this (m): beyond it a detector may lose small or dim objects for reasons "
        "this model does not know, and a real object must not pay for that",
        minimum=0.0,
    )
    view_top_quantile: float = setting(
        0.995,
        "the top of the camera's view is this quantile of all slices' upper edges",
        minimum=0.5,
        maximum=1.0,
    )
    occlusion_cover: float = setting(
        0.5, "an object is hidden when a nearer object covers more than this share of its bearing interval", minimum=0.0
    )


def view_top_elevation(problem: GraphProblem, config: DetectionConfig) -> float:
    """The top of the camera's view (rad), from the slices' upper edges."""
    if problem.measurement_count == 0:
        return math.inf
    return float(np.quantile(problem.measurements[:, 3], config.view_top_quantile))


@dataclass(frozen=True)
class Sight:
    """How K things appear from N poses: (N, K) bearing, width and range, and ``in_view``
    (valid, wide enough, near enough, below the top of the view), before occlusion."""

    bearing: NDArray[np.float64]
    width: NDArray[np.float64]
    range_m: NDArray[np.float64]
    in_view: NDArray[np.bool_]

    def columns(self, index: Sequence[int]) -> Sight:
        index = np.asarray(index, dtype=np.int64)
        return Sight(*(getattr(self, f)[:, index] for f in Sight.__dataclass_fields__))

    @staticmethod
    def join(parts: Sequence[Sight]) -> Sight:
        return Sight(*(np.concatenate([getattr(p, f) for p in parts], axis=1) for f in Sight.__dataclass_fields__))


def sight(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    things: NDArray[np.float64],
    config: DetectionConfig,
    view_top_rad: float,
) -> Sight:
    """The :class:`Sight` of (K, 5) things (x, y, z_base, diameter, height) from the poses."""
    things = np.asarray(things, dtype=float).reshape(-1, 5)
    poses = np.asarray(map_T_base, dtype=float)
    n, k = len(poses), len(things)
    if k == 0:
        empty = np.zeros((n, 0))
        return Sight(empty, empty, empty, empty.astype(bool))
    pred = predict_reduced(
        np.repeat(poses, k, axis=0),
        np.tile(things[:, :3], (n, 1)),
        np.tile(things[:, 3:], (n, 1)),
        problem.mount,
        jacobians=False,
    )
    values = pred.values.reshape(4, n, k)
    dist = pred.range_m.reshape(n, k)
    in_view = pred.valid.reshape(n, k) & (values[WIDTH] >= config.min_angular_width_rad)
    in_view &= (dist <= config.max_range_m) & (values[ELEVATION_BOTTOM] < view_top_rad)
    return Sight(values[BEARING], values[WIDTH], dist, in_view)


def hidden(rows: Sight, occluders: Sight, config: DetectionConfig) -> NDArray[np.bool_]:
    """(N, R) whether some thing of ``occluders`` hides each thing of ``rows`` where it is in
    view (False elsewhere): nearer, and covering more than ``occlusion_cover`` of its bearing
    interval (a thing does not hide itself: it is not nearer than itself)."""
    out = np.zeros(rows.in_view.shape, dtype=bool)
    if not occluders.bearing.shape[1]:
        return out
    # Only the (pose, thing) pairs in view matter: (P, M) against every occluder.
    pose, row = np.nonzero(rows.in_view)
    w = rows.width[pose, row][:, None]
    w_occ = occluders.width[pose]
    offset = np.abs(wrap_angle(rows.bearing[pose, row][:, None] - occluders.bearing[pose]))
    overlap = np.minimum(np.clip(0.5 * (w + w_occ) - offset, 0.0, None), np.minimum(w, w_occ))
    covers = (occluders.range_m[pose] < rows.range_m[pose, row][:, None]) & (overlap > config.occlusion_cover * w)
    out[pose, row] = covers.any(axis=1)
    return out


def visible(rows: Sight, occluders: Sight, config: DetectionConfig) -> NDArray[np.bool_]:
    """(N, R) whether each thing of ``rows`` is in view and hidden by no nearer one of ``occluders``."""
    return rows.in_view & ~hidden(rows, occluders, config)


def hit_matrix(problem: GraphProblem, n_poses: int, groups: Sequence[NDArray[np.int64]]) -> NDArray[np.bool_]:
    """(N, R) whether image n holds a slice of group r (measurement indices)."""
    hit = np.zeros((n_poses, len(groups)), dtype=bool)
    for r, group in enumerate(groups):
        hit[problem.measurement_pose[np.asarray(group, dtype=np.int64)], r] = True
    return hit


@dataclass(frozen=True)
class Sightings:
    """K things with their slices, from N poses: the :class:`Sight`, where the others hide
    each one (``hidden``, (N, K)) and where each has a slice (``hit``, (N, K))."""

    sight: Sight
    hidden: NDArray[np.bool_]
    hit: NDArray[np.bool_]

    @property
    def missed(self) -> NDArray[np.bool_]:
        """(N, K) images where a thing should be seen and has no slice."""
        return self.sight.in_view & ~self.hidden & ~self.hit


def sightings(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    things: NDArray[np.float64],
    groups: Sequence[NDArray[np.int64]],
    config: DetectionConfig,
    view_top_rad: float,
) -> Sightings:
    """The :class:`Sightings` of (K, 5) ``things`` and their ``groups`` (measurement indices)."""
    seen = sight(problem, map_T_base, things, config, view_top_rad)
    return Sightings(seen, hidden(seen, seen, config), hit_matrix(problem, len(seen.in_view), groups))


def miss_count_log_likelihood(n_miss: int, config: DetectionConfig) -> float:
    """``n_miss log(1 - P_d)``."""
    return n_miss * math.log1p(-config.probability)


def detection_log_likelihood(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    things: NDArray[np.float64],
    groups: Sequence[NDArray[np.int64]],
    config: DetectionConfig,
    view_top_rad: float,
) -> float:
    """``sum of n_miss log(1 - P_d)`` over ``things`` (K, 5) and their ``groups``
    (measurement indices; module docstring)."""
    if not config.enabled or not len(groups):
        return 0.0
    seen = sightings(problem, map_T_base, things, groups, config, view_top_rad)
    return miss_count_log_likelihood(int(np.count_nonzero(seen.missed)), config)
