"""Oracle data association for evaluation: which real object explains each detected slice.

For every image, each ground-truth object of the slice's class is predicted into the
image from the ground-truth pose at the image stamp with
:func:`objslam_mapper.slice_model.predict_slices` (the silhouette's real extremes: bearing
of the axis, width ``2 asin(r/D)``, near/far rims for the elevations). A slice is
explained by a candidate when

- the bearings agree: ``|bearing difference| <= max((slice width + predicted width)/2, bearing_gate_rad)``
  (the sectors overlap, or for thin far objects the bearing is within the gate), and
- the elevation intervals overlap, widened by ``elevation_margin_rad`` (an object on a
  table has its lower edge cut by the table top, so the bottoms can disagree).

Among the candidates the one with the smallest ``|d bearing| + |d elevation top|`` is
chosen, one slice per object and image first (Hungarian, so two slices of two neighbouring
same-class objects do not both go to the nearer one); a slice left over that still
passes the test (an object split in two blobs by an occluder) goes to its best candidate.
Slices that nothing explains (distractors, noise) get ``None``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from objslam_mapper.geometry import wrap_angle
from objslam_mapper.slice_model import BEARING, ELEVATION_BOTTOM, ELEVATION_TOP, WIDTH, predict_slices
from objslam_tools.ground_truth import GroundTruth
from objslam_tools.trajectory import PoseTrack

logger = logging.getLogger(__name__)


class SliceLike(Protocol):
    label: str
    bearing_rad: float
    angular_width_rad: float
    elevation_bottom_rad: float
    elevation_top_rad: float


class ImageSlicesLike(Protocol):
    """E.g. objslam_mapper.records.ImageSlices."""

    stamp_ns: int
    slices: Sequence[SliceLike]


@dataclass(frozen=True)
class OracleOptions:
    bearing_gate_rad: float = 0.1  # bearing agreement accepted even without sector overlap
    elevation_margin_rad: float = 0.1  # widening of the predicted elevation interval


def _measured(slices: Sequence[SliceLike]) -> NDArray[np.float64]:
    return np.array(
        [[s.bearing_rad, s.angular_width_rad, s.elevation_bottom_rad, s.elevation_top_rad] for s in slices],
        dtype=float,
    ).reshape(-1, 4)


def _costs(
    measured: NDArray[np.float64], predicted: NDArray[np.float64], valid: NDArray[np.bool_], options: OracleOptions
) -> NDArray[np.float64]:
    """(slices, candidates) cost, inf where the candidate cannot explain the slice."""
    d_bearing = np.abs(wrap_angle(measured[:, None, BEARING] - predicted[None, :, BEARING]))
    d_bearing = np.atleast_2d(d_bearing)
    bearing_ok = d_bearing <= np.maximum(
        0.5 * (measured[:, None, WIDTH] + predicted[None, :, WIDTH]), options.bearing_gate_rad
    )
    m = options.elevation_margin_rad
    elevation_ok = (measured[:, None, ELEVATION_BOTTOM] <= predicted[None, :, ELEVATION_TOP] + m) & (
        measured[:, None, ELEVATION_TOP] >= predicted[None, :, ELEVATION_BOTTOM] - m
    )
    cost = d_bearing + np.abs(measured[:, None, ELEVATION_TOP] - predicted[None, :, ELEVATION_TOP])
    return np.where(bearing_ok & elevation_ok & valid[None, :], cost, np.inf)


def _assign_label(cost: NDArray[np.float64]) -> list[int | None]:
    """Per slice: a column index or None (module docstring: Hungarian first, then leftovers)."""
    n_slices, n_cands = cost.shape
    out: list[int | None] = [None] * n_slices
    if n_cands == 0:
        return out
    finite = np.isfinite(cost)
    big = (cost[finite].max() + 1.0) * 1e3 if finite.any() else 1.0
    rows, cols = linear_sum_assignment(np.where(finite, cost, big))
    for r, c in zip(rows, cols, strict=True):
        if finite[r, c]:
            out[r] = int(c)
    for r in range(n_slices):
        if out[r] is None and finite[r].any():
            out[r] = int(np.argmin(cost[r]))
    return out


def oracle_assignment(
    images: Sequence[ImageSlicesLike],
    ground_truth: GroundTruth,
    ground_truth_track: PoseTrack,
    options: OracleOptions | None = None,
) -> list[tuple[int | None, ...]]:
    """For each image, for each of its slices, the id of the real object that explains it, or None.

    ``ground_truth_track`` is ``/ground_truth/odom`` (the ground truth's frame); images whose
    stamp lies outside it get None for every slice. The camera mount is the ground truth's.
    """
    options = options or OracleOptions()
    objects = ground_truth.objects
    result: list[tuple[int | None, ...]] = []
    outside = 0
    for image in images:
        slices = list(image.slices)
        ids: list[int | None] = [None] * len(slices)
        if not slices or not objects:
            result.append(tuple(ids))
            continue
        if not ground_truth_track.covers([image.stamp_ns])[0]:
            outside += 1
            result.append(tuple(ids))
            continue
        pose = ground_truth_track.interpolate([image.stamp_ns])[0]
        for label in sorted({s.label for s in slices}):
            rows = [k for k, s in enumerate(slices) if s.label == label]
            cands = [o for o in objects if o.label == label]
            if not cands:
                continue
            pred = predict_slices(
                pose, [o.position_m for o in cands], [o.size_m for o in cands], ground_truth.mount, jacobians=False
            )
            cost = _costs(_measured([slices[k] for k in rows]), pred.values, pred.valid, options)
            for k, c in zip(rows, _assign_label(cost), strict=True):
                ids[k] = None if c is None else cands[c].id
        result.append(tuple(ids))
    if outside:
        logger.warning("%d images lie outside the ground-truth trajectory: their slices are unassigned", outside)
    return result
