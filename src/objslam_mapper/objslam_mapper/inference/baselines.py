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
  estimates through the shared poses is neglected, as is usual for this baseline.
  Decisions are never revisited and there is no clutter model.

Ground-truth (oracle) association needs the simulator's truth, so it lives in
``objslam_tools.oracle_map``; it uses :func:`map_of_groups` from here.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.catalog import Catalog
from objslam_common.records import ImageSlices, OdometrySample
from objslam_mapper.config import GraphConfig, SamplerConfig
from objslam_mapper.errors import MapperError
from objslam_mapper.graph.backends import solve_with_backend
from objslam_mapper.graph.problem import GraphProblem, build_problem
from objslam_mapper.graph.solver import GraphSolution
from objslam_mapper.inference.algorithm1 import build_from_samples
from objslam_mapper.inference.association import Association
from objslam_mapper.inference.diagnostics import PhaseProgress
from objslam_mapper.inference.target import AssociationTarget, TargetOptions
from objslam_mapper.inference.tracklets import Tracklet, tracklets_of_problem
from objslam_mapper.map_file import BuiltMap

logger = logging.getLogger(__name__)

BASELINES = ("none", "greedy")


class BaselineError(MapperError, ValueError):
    """An unknown baseline or groups that do not make a map."""


@dataclass(frozen=True)
class GreedyOptions:
    gate_probability: float = 0.99  # chi-square gate of the Mahalanobis distance (2 dof)

    @property
    def gate_chi2(self) -> float:
        # Chi-square with 2 dof has the closed-form quantile -2 ln(1 - p).
        return -2.0 * math.log1p(-self.gate_probability)


def no_association(tracklets: Sequence[Tracklet]) -> Association:
    """Every tracklet its own object; nothing is clutter."""
    return Association.of(range(len(tracklets)))


def _measurement_groups(tracklets: Sequence[Tracklet], groups: Sequence[Sequence[int]]) -> list[NDArray[np.int64]]:
    return [np.sort(np.concatenate([tracklets[t].measurement_indices for t in g])).astype(np.int64) for g in groups]


def _mahalanobis2_xy(a_m: NDArray, a_cov: NDArray | None, b_m: NDArray, b_cov: NDArray | None) -> float:
    if a_cov is None or b_cov is None:
        return math.inf
    cov = np.asarray(a_cov)[:2, :2] + np.asarray(b_cov)[:2, :2]
    diff = np.asarray(a_m)[:2] - np.asarray(b_m)[:2]
    if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(diff))):
        return math.inf
    try:
        return float(diff @ np.linalg.solve(cov, diff))
    except np.linalg.LinAlgError:
        return math.inf


def greedy_association(
    problem: GraphProblem,
    tracklets: Sequence[Tracklet],
    options: GreedyOptions | None = None,
    progress: PhaseProgress | None = None,
) -> Association:
    """Greedy nearest-neighbour association with Mahalanobis gating (module docstring)."""
    options = options or GreedyOptions()
    gate = options.gate_chi2
    report = progress or (lambda _phase, _done, _total: None)
    order = sorted(range(len(tracklets)), key=lambda t: (tracklets[t].frame_indices[0], t))
    groups: list[list[int]] = []
    frames: list[set[int]] = []
    warm: GraphSolution | None = None
    for done, t in enumerate(order):
        report("association", done, len(order))
        tracklet = tracklets[t]
        seen = set(tracklet.frame_indices)
        candidates = [
            j for j, g in enumerate(groups) if tracklets[g[0]].label == tracklet.label and not frames[j] & seen
        ]
        best = None
        if candidates:
            solution = solve_with_backend(
                problem,
                _measurement_groups(tracklets, [*groups, [t]]),
                warm_start=warm,
                with_covariances=True,
            )
            if solution.converged:
                warm = solution
                new = solution.objects[-1]
                best_d2 = gate
                for j in candidates:
                    obj = solution.objects[j]
                    d2 = _mahalanobis2_xy(new.location_m, new.location_cov, obj.location_m, obj.location_cov)
                    if d2 <= best_d2:
                        best, best_d2 = j, d2
            else:
                logger.warning("greedy: solve with tracklet %d did not converge; it stays a new object", t)
        if best is None:
            groups.append([t])
            frames.append(set(seen))
        else:
            groups[best].append(t)
            frames[best] |= seen
    report("association", len(order), len(order))
    return Association.from_groups(len(tracklets), groups)


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
        spurious_location_stddev_m=config.spurious_location_stddev_m,
        existence_threshold=config.existence_threshold,
        report_min_fraction=config.report_min_fraction,
        diagnostics=diagnostics,
    )


def map_of_association(
    problem: GraphProblem,
    tracklets: Sequence[Tracklet],
    state: Association,
    config: SamplerConfig,
    diagnostics: dict | None = None,
) -> BuiltMap:
    """The map of one association of ``tracklets`` (clutter tracklets left out)."""
    return map_of_groups(problem, _measurement_groups(tracklets, state.groups), config, diagnostics)


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
