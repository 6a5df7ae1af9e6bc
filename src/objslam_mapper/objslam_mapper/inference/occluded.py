"""Slice edges cut by a nearer thing: bounds on the object's edges, not measurements of them.

The detector sees a colour blob and marks an edge as cut only where the view ends
(:func:`objslam_mapper.model.slice_model.bounds_of_cuts`). An object partly behind a nearer
one, or behind a table, which the detector does not see at all, shows a blob narrower than
itself, and the slice model reads that width as range: the slices put the object farther
and smaller. On ``twins`` (seed 13) a green object seen beside a table on the first and
last passes became a second green object 0.52 m behind the real one, 0.22 m wide where the
class is 0.40, at P = 1.00 in every chain.

So, once per build, the edges of every slice are checked against the things of a reference
map (the heuristic start's association, solved): a slice edge that lies on the silhouette
of a nearer thing of another class, or of a table (every object of a class above the floor
stands on one, docs/design.md), may be the occluder's edge, and is taken as a bound as a
cut view edge is: the object reaches at least that far. The reference is fixed for the
build, so the chains' target stays one function of the association.

"Nearer" is judged against the slice's own range from its width and its class's diameter,
which a cut slice overestimates (it only adds occluders that are nearer still). A thing
whose footprint overlaps the slice's estimated one is its own (the table under an object)
and cuts nothing.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
from numpy.typing import NDArray

from objslam_common.geometry import wrap_angle
from objslam_common.records import CUT_LEFT, CUT_RIGHT
from objslam_mapper.config import DetectionConfig, SamplerConfig
from objslam_mapper.graph.problem import GraphProblem, read_only
from objslam_mapper.inference.chains import ChainSpec
from objslam_mapper.inference.detection import EVERYWHERE, Sight, sight, table_sight
from objslam_mapper.inference.diagnostics import Work
from objslam_mapper.inference.screen import ProposalScreen
from objslam_mapper.inference.start import dispersed_start
from objslam_mapper.inference.target import AssociationTarget, TargetOptions
from objslam_mapper.inference.tracklets import TrackletResult
from objslam_mapper.model.slice_model import BEARING, ELEVATION_BOTTOM, ELEVATION_TOP, WIDTH, with_side_cuts

logger = logging.getLogger(__name__)


def with_occluded_edges(problem: GraphProblem, chained: TrackletResult, config: SamplerConfig) -> GraphProblem:
    """``problem`` with the slice edges that nearer things cut as bounds (module docstring),
    judged at the MAP of the heuristic start's association."""
    target = AssociationTarget(problem, chained.tracklets, TargetOptions.of(config), Work())
    start = dispersed_start(
        "heuristic", ProposalScreen(target), config, ChainSpec(0, "heuristic", config.seed).start_rng()
    )
    map_T_base, things, labels, on_table = target.objects_at_map(start.state)
    cuts = occluded_edges(problem, map_T_base, things, labels, on_table, config.detection)
    if not cuts.any():
        return problem
    logger.info("%d slices have an edge on a nearer thing's silhouette: those edges are bounds", int((cuts > 0).sum()))
    bounds = with_side_cuts(problem.measurement_bounds, cuts)
    return dataclasses.replace(problem, measurement_bounds=read_only(bounds))


def occluded_edges(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    things: NDArray[np.float64],
    thing_labels: NDArray[np.int64],
    on_table: NDArray[np.bool_],
    config: DetectionConfig,
) -> NDArray[np.int64]:
    """(M,) ``CUT_LEFT``/``CUT_RIGHT`` bits of the slice edges that lie within
    ``config.occluded_edge_margin_rad`` of the silhouette of a nearer thing (module
    docstring). ``things`` (K, 5) are (x, y, z_base, diameter, height) of the reference map's
    objects, ``thing_labels`` (K,) their class rows, ``on_table`` (K,) which stand on a table."""
    cuts = np.zeros(problem.measurement_count, dtype=np.int64)
    things = np.asarray(things, dtype=float).reshape(-1, 5)
    if not len(things) or not problem.measurement_count:
        return cuts
    objects = sight(problem, map_T_base, things, config, EVERYWHERE)
    tables = table_sight(problem, map_T_base, things, on_table, config)
    both = Sight.join([objects, tables])
    # A table cuts slices of every class; an object those of other classes (of its own
    # class the detector would see one blob).
    other_class = np.concatenate(
        [
            np.asarray(thing_labels)[None, :] != problem.measurement_label[:, None],
            np.ones((problem.measurement_count, len(things)), dtype=bool),
        ],
        axis=1,
    )  # (M, 2K)
    pose = problem.measurement_pose
    z = problem.measurements
    bearing, width = z[:, BEARING], z[:, WIDTH]
    radius_m = 0.5 * problem.prior_mean[problem.measurement_label, 3]
    range_m = radius_m / np.sin(np.clip(0.5 * width, 1e-6, None))
    footprint_xy = _slice_footprint(problem, map_T_base, bearing, range_m)  # (M, 2)
    apart = np.hypot(
        footprint_xy[:, 0:1] - both.footprint[0][None, :], footprint_xy[:, 1:2] - both.footprint[1][None, :]
    )
    occluder = (
        other_class
        & np.isfinite(both.range_m[pose])
        & (both.range_m[pose] < range_m[:, None])
        & (apart > radius_m[:, None] + both.footprint[2][None, :])
        & (both.bottom[pose] < z[:, ELEVATION_TOP, None])
        & (both.top[pose] > z[:, ELEVATION_BOTTOM, None])
    )
    reach = 0.5 * both.width[pose] + config.occluded_edge_margin_rad
    for bit, edge in ((CUT_LEFT, bearing + 0.5 * width), (CUT_RIGHT, bearing - 0.5 * width)):
        on_silhouette = np.abs(wrap_angle(edge[:, None] - both.bearing[pose])) <= reach
        cuts |= np.where((occluder & on_silhouette).any(axis=1), bit, 0)
    return cuts


def _slice_footprint(
    problem: GraphProblem, map_T_base: NDArray[np.float64], bearing: NDArray, range_m: NDArray
) -> NDArray[np.float64]:
    """(M, 2) where each slice's object stands by its bearing and range, in the map frame
    (the image problem: one mount for every slice)."""
    cameras = np.array([problem.mount.camera_pose(p) for p in map_T_base]).reshape(-1, 3)[problem.measurement_pose]
    azimuth = cameras[:, 2] + bearing
    return cameras[:, :2] + range_m[:, None] * np.column_stack([np.cos(azimuth), np.sin(azimuth)])
