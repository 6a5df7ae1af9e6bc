"""Unknown data association end to end: paper Algorithm 1 over the samples of Algorithm 2.

:func:`infer_map` reads as the method does. Slices are chained into tracklets (isolated
detections dropped, as the paper does); several chains (:mod:`.chains`), each from its own
start (:mod:`.start`), sample associations of the tracklets under the target
``log P(J | Z)`` (:mod:`.target`), screening each proposal first (:mod:`.screen`), and
solve their kept states with marginals; Algorithm 1 (:mod:`.algorithm1`) turns the pooled
samples into identities, their existence probabilities and the map; and the chains'
agreement on them is judged (:mod:`.convergence`). What the build reports about itself is
collected on the way by a :class:`~.diagnostics.Stopwatch`.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from objslam_mapper.config import SamplerConfig
from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.inference.algorithm1 import MapOptions, build_from_samples, map_and_yields
from objslam_mapper.inference.association import Association
from objslam_mapper.inference.chains import ChainOutcome, ChainRunner, ChainTask, InProcess, chain_specs, pooled_samples
from objslam_mapper.inference.convergence import chain_convergence
from objslam_mapper.inference.diagnostics import (
    PhaseProgress,
    Stopwatch,
    chains_diagnostics,
    inputs_diagnostics,
    timings,
    work_diagnostics,
)
from objslam_mapper.inference.occluded import with_occluded_edges
from objslam_mapper.inference.target import AssociationTarget, TargetOptions
from objslam_mapper.inference.tracklets import TrackletResult, tracklets_of_problem
from objslam_mapper.map_file import BuiltMap

logger = logging.getLogger(__name__)


def infer_map(
    problem: GraphProblem,
    config: SamplerConfig,
    progress: PhaseProgress | None = None,
    runner: ChainRunner | None = None,
) -> BuiltMap:
    """Tracklets -> chains -> kept samples -> identities -> map, on a built factor-graph problem.

    ``runner`` runs the chains (default: one after another in this process;
    :mod:`objslam_mapper.parallel` runs them as Ray tasks). The map is the same either way.
    """
    inference = prepare(problem, config, progress)
    outcomes = (runner or InProcess()).run(inference.tasks, inference.report_sampling)
    return finish(inference, outcomes)


@dataclass(frozen=True)
class Inference:
    """A problem's tracklets and chain tasks, between :func:`prepare` and :func:`finish` (several
    problems' tasks may run as one batch, e.g. ``objslam map-batch``)."""

    problem: GraphProblem
    config: SamplerConfig
    chained: TrackletResult
    tasks: tuple[ChainTask, ...]
    inputs: dict[str, Any]
    watch: Stopwatch

    def report_sampling(self, done: int, total: int) -> None:
        self.watch.report("sampling", done, total)


def prepare(problem: GraphProblem, config: SamplerConfig, progress: PhaseProgress | None = None) -> Inference:
    """The tracklets, and one chain task per chain (none without tracklets)."""
    watch = Stopwatch(progress)
    watch.report("tracklets", 0, 1)
    chained = tracklets_of_problem(problem, config.tracklets)
    if config.detection.occluded_edges and chained.tracklets:
        problem = with_occluded_edges(problem, chained, config)
    watch.report("tracklets", 1, 1)
    watch.lap("tracklets")
    tasks = (
        tuple(ChainTask(problem, chained, config, spec) for spec in chain_specs(config)) if chained.tracklets else ()
    )
    return Inference(problem, config, chained, tasks, inputs_diagnostics(problem, chained, config.seed), watch)


def finish(inference: Inference, outcomes: Sequence[ChainOutcome]) -> BuiltMap:
    """Algorithm 1 over the chains' pooled samples (``outcomes`` of ``inference.tasks``, in
    their order), and the chains' agreement."""
    problem, config, watch = inference.problem, inference.config, inference.watch
    if not inference.tasks:
        logger.warning("no tracklets (every detection isolated): the map holds no objects")
        target = AssociationTarget(problem, (), TargetOptions.of(config), watch.work)
        samples = [(target.summary(Association(())), 1)]
        built = build_from_samples(
            samples, problem.stamps_ns, MapOptions.of(config), diagnostics={**inference.inputs, "map_samples": 1}
        )
        watch.report("mapping", 1, 1)
        return built
    watch.lap("sampling")

    watch.report("mapping", 0, 1)
    built, yields = map_and_yields(
        pooled_samples(outcomes, config.pooling),
        problem.stamps_ns,
        MapOptions.of(config),
        diagnostics={**inference.inputs, **chains_diagnostics(outcomes)},
    )
    identities = [o.id for o in (*built.objects, *built.rejected)]
    convergence = chain_convergence(outcomes, yields, identities, config.rhat_max)

    def with_chains(objects):  # each identity's P(ID|Z) by chain, beside the pooled one
        return tuple(dataclasses.replace(o, existence_by_chain=convergence.existence_by_chain[o.id]) for o in objects)

    watch.report("mapping", 1, 1)
    watch.lap("mapping")
    diagnostics = {
        **built.diagnostics,
        "map_samples": sum(sum(o.result.counts.values()) for o in outcomes),
        "pooling": config.pooling,
        "convergence": convergence.to_dict(),
        **work_diagnostics(outcomes),
        "timings_s": timings(watch, outcomes),
    }
    logger.info(
        "map: %d objects, %d rejected; %d tracklets, %d chains%s; %.1f s",
        len(built.objects),
        len(built.rejected),
        len(inference.chained.tracklets),
        len(outcomes),
        "" if convergence.converged is None else f", converged: {'yes' if convergence.converged else 'no'}",
        diagnostics["timings_s"]["total"],
    )
    return dataclasses.replace(
        built, objects=with_chains(built.objects), rejected=with_chains(built.rejected), diagnostics=diagnostics
    )
