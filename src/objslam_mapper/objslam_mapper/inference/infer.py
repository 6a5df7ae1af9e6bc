"""Unknown data association end to end: paper Algorithm 1 over the samples of Algorithm 2.

:func:`infer_map` reads as the method does. Slices are chained into tracklets (isolated
detections dropped, as the paper does); the chain (:mod:`.chain`) samples associations of
the tracklets from :mod:`.start`'s start state under the target ``log P(J | Z)``
(:mod:`.target`), screening each proposal first (:mod:`.screen`); each kept sample is
solved with its marginals, and Algorithm 1 (:mod:`.algorithm1`) turns the samples into
identities, their existence probabilities and the map. What the build reports about
itself is collected on the way by a :class:`~.diagnostics.Stopwatch`.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterator

import numpy as np

from objslam_mapper.config import SamplerConfig
from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.inference.algorithm1 import SampleSummary, build_from_samples
from objslam_mapper.inference.association import Association
from objslam_mapper.inference.chain import ChainResult, MetropolisHastings
from objslam_mapper.inference.diagnostics import (
    PhaseProgress,
    Stopwatch,
    chain_diagnostics,
    inputs_diagnostics,
    timings,
)
from objslam_mapper.inference.screen import ProposalScreen
from objslam_mapper.inference.start import start_state
from objslam_mapper.inference.target import AssociationTarget, TargetOptions
from objslam_mapper.inference.tracklets import TrackletResult, tracklets_of_problem
from objslam_mapper.map_file import BuiltMap

logger = logging.getLogger(__name__)


def infer_map(problem: GraphProblem, config: SamplerConfig, progress: PhaseProgress | None = None) -> BuiltMap:
    """Tracklets -> chain -> kept samples -> identities -> map, on a built factor-graph problem."""
    watch = Stopwatch(progress)
    watch.report("tracklets", 0, 1)
    chained = tracklets_of_problem(problem, config.tracklets)
    watch.report("tracklets", 1, 1)
    watch.lap("tracklets")
    target = AssociationTarget(problem, chained.tracklets, TargetOptions.of(config), watch.work)
    inputs = inputs_diagnostics(problem, chained, config.seed)
    if not chained.tracklets:
        logger.warning("no tracklets (every detection isolated): the map holds no objects")
        built = build_from_samples([(target.summary(Association(())), 1)], problem.stamps_ns, diagnostics=inputs)
        watch.report("mapping", 1, 1)
        return built

    screen = ProposalScreen(target)
    start = start_state(screen, config)
    chain = run_chain(screen, chained, start.state, config, watch)
    watch.lap("sampling")

    built = build_from_samples(
        kept_sample_summaries(target, chain, watch),
        problem.stamps_ns,
        spurious_location_stddev_m=config.spurious_location_stddev_m,
        existence_threshold=config.existence_threshold,
        report_min_fraction=config.report_min_fraction,
        identity_overlap=config.identity_overlap,
        diagnostics={**inputs, **chain_diagnostics(start, chain, watch.work)},
    )
    watch.lap("mapping")
    diagnostics = {**built.diagnostics, "marginal_solves": watch.work.marginal_solves, "timings_s": timings(watch)}
    logger.info(
        "map: %d objects, %d rejected; %d tracklets, %d distinct associations visited, acceptance %.2f, %.1f s",
        len(built.objects),
        len(built.rejected),
        len(chained.tracklets),
        chain.distinct_visited,
        chain.overall_acceptance_rate,
        diagnostics["timings_s"]["total"],
    )
    return dataclasses.replace(built, diagnostics=diagnostics)


def run_chain(
    screen: ProposalScreen, chained: TrackletResult, start: Association, config: SamplerConfig, watch: Stopwatch
) -> ChainResult:
    """Paper Algorithm 2 from ``start``: ``config.samples`` steps, the last ``samples - burn_in`` kept."""
    target = screen.target
    sampler = MetropolisHastings(
        chained.labels,
        target,
        config.moves,
        positions_xy_m=[t.position_xy_m for t in chained.tracklets],
        tracklet_weights=[len(t) for t in chained.tracklets],
        allow_clutter=config.clutter.enabled,
        screen=screen if config.screen.enabled else None,
        screen_config=config.screen,
    )
    return sampler.run(
        start,
        config.samples,
        config.burn_in,
        np.random.default_rng(config.seed),
        progress=lambda done, total: watch.report("sampling", done, total),
        keep_trace=False,
        on_move=target.move_to,
    )


def kept_sample_summaries(
    target: AssociationTarget, chain: ChainResult, watch: Stopwatch
) -> Iterator[tuple[SampleSummary, int]]:
    """Each distinct kept state's MAP and marginals (Algorithm 1, step 2a), with its multiplicity."""
    for k, (state, count) in enumerate(chain.counts.items()):
        watch.report("mapping", k, len(chain.counts))
        yield target.summary(state), count
    watch.report("mapping", len(chain.counts), len(chain.counts))
