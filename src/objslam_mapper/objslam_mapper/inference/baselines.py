r"""Baseline data associations, mapped through the same factor graph as the sampler's.

They exist to measure what the MCMC buys: each baseline fixes one association ``J`` of
the same tracklets (:mod:`objslam_mapper.inference.tracklets`), and its map is paper Algorithm 1 with
a single sample -- one known-association solve with marginals. Every object of ``J`` then
has ``P(ID|Z) = 1``, except those spurious by the covariance test
(``sampler.spurious_location_stddev_m``), which are reported as rejected with ``P = 0``.
Only the association differs from the sampler's map; the model, solver and map building
are the same code.

- ``none``: no association across tracklets: every tracklet is its own object, no clutter.
  What a mapper without data association (each detection chain a new landmark) gives.
- ``greedy``: greedy nearest neighbour with Mahalanobis gating, the classic
  online-SLAM association. Tracklets are taken in time order (first image). For each, the
  current association plus the tracklet as a new object is solved with marginals; the
  tracklet joins the same-class object, not seen in any of its images, whose location is
  nearest in Mahalanobis distance

      d^2 = (l_t - l_j)_{xy}^T (C_t + C_j)_{xy}^{-1} (l_t - l_j)_{xy},

  provided ``d^2`` is within the chi-square gate (2 degrees of freedom, probability
  ``gate_probability``); otherwise it stays a new object. The cross-covariance of the two
  estimates through the shared poses is neglected, as is usual for this baseline. A
  tracklet the solve cannot place (no optimum, or an xy stddev over
  ``max_location_stddev_m``) stays a new object and is left out of the later solves.
  Decisions are never revisited and there is no clutter model.

Ground-truth (oracle) association needs the simulator's truth, so it lives in
``objslam_tools.oracle_map``; it uses :func:`map_of_groups` from here.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from objslam_common.catalog import Catalog
from objslam_common.records import ImageSlices, OdometrySample
from objslam_mapper.config import GraphConfig, SamplerConfig
from objslam_mapper.errors import MapperError
from objslam_mapper.graph.problem import GraphProblem, build_problem
from objslam_mapper.inference.algorithm1 import MapOptions, build_from_samples
from objslam_mapper.inference.association import Association
from objslam_mapper.inference.diagnostics import PhaseProgress
from objslam_mapper.inference.start import GreedyOptions, greedy_association, measurement_groups, no_association
from objslam_mapper.inference.target import AssociationTarget, TargetOptions
from objslam_mapper.inference.tracklets import Tracklet, tracklets_of_problem
from objslam_mapper.map_file import BuiltMap

logger = logging.getLogger(__name__)

BASELINES = ("none", "greedy")


class BaselineError(MapperError, ValueError):
    """An unknown baseline or groups that do not make a map."""


def map_of_groups(
    problem: GraphProblem,
    groups: Sequence[ArrayLike],
    config: SamplerConfig,
    diagnostics: dict | None = None,
) -> BuiltMap:
    """Algorithm 1 with one sample: the known association ``groups`` (measurement indices per object).

    Measurements in no group are left out of the graph (clutter).
    """
    members = [np.unique(np.asarray(g, dtype=np.int64)) for g in groups]
    if any(len(m) == 0 for m in members):
        raise BaselineError("an object must own at least one measurement")
    # Each object as one pseudo-tracklet lets the sampler's own summary (solve + marginals) be reused.
    objects = [
        Tracklet(
            label=problem.label_of(int(m[0])),
            measurement_indices=tuple(int(k) for k in m),
            frame_indices=tuple(sorted({int(p) for p in problem.measurement_pose[m]})),
            position_xy_m=(math.nan, math.nan),
        )
        for m in members
    ]
    target = AssociationTarget(problem, objects, TargetOptions(clutter=config.clutter))
    summary = target.summary(Association.of(range(len(objects))))
    return build_from_samples(
        [(summary, 1)],
        problem.stamps_ns,
        MapOptions.of(config),
        diagnostics={**(diagnostics or {}), "map_samples": 1},
    )


def map_of_association(
    problem: GraphProblem,
    tracklets: Sequence[Tracklet],
    state: Association,
    config: SamplerConfig,
    diagnostics: dict | None = None,
) -> BuiltMap:
    """The map of one association of ``tracklets`` (clutter tracklets left out)."""
    return map_of_groups(problem, measurement_groups(tracklets, state.groups), config, diagnostics)


def build_baseline_map(
    odometry: Sequence[OdometrySample],
    images: Sequence[ImageSlices],
    catalog: Catalog,
    association: str,
    *,
    graph: GraphConfig | None = None,
    sampler: SamplerConfig | None = None,
    progress: PhaseProgress | None = None,
    greedy: GreedyOptions | None = None,
) -> BuiltMap:
    """Odometry and slices to the map of a baseline association (``none`` or ``greedy``)."""
    if association not in BASELINES:
        raise BaselineError(f"unknown baseline association {association!r} (choose from {', '.join(BASELINES)})")
    graph = graph or GraphConfig()
    sampler = sampler or SamplerConfig()
    started = time.perf_counter()
    problem = build_problem(odometry, images, graph.camera_mount.to_mount(), catalog, graph)
    chained = tracklets_of_problem(problem, sampler.tracklets)
    if association == "none":
        state = no_association(chained.tracklets)
    else:
        state = greedy_association(problem, chained.tracklets, greedy, progress)
    diagnostics = {
        "association": association,
        "poses": problem.pose_count,
        "measurements": problem.measurement_count,
        "tracklets": len(chained.tracklets),
        "isolated_dropped": len(chained.dropped_measurements),
        "association_objects": state.n_objects,
    }
    if state.n_objects == 0:
        logger.warning("no tracklets (every detection isolated): the map holds no objects")
    built = map_of_association(problem, chained.tracklets, state, sampler, diagnostics)
    built.diagnostics["timings_s"] = {"total": round(time.perf_counter() - started, 3)}
    return built
