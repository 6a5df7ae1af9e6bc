"""Several chains from dispersed starts: what each one runs, and where they run.

One chain from a strong heuristic start cannot tell a posterior that is certain from a chain
that is stuck. So ``sampler.chains`` chains run, each from its own kind of start
(``sampler.starts``: the heuristic start, every tracklet its own object, the greedy
association, every tracklet clutter, random associations) with its own seed derived from
the one ``sampler.seed``: chain 0 draws from that seed's stream (one chain reproduces the
single-chain maps), chain k from the seed sequence's k-th child. Each chain is one task
(:func:`run_chain_task`): its own target and screen, its start, its steps, and the MAP and
marginals of its kept states (Algorithm 1, step 2a), so that the costly part runs where the
chain ran. Their kept samples are pooled for the map (:mod:`.infer`), and their agreement is
judged by :mod:`.convergence`.

A task is a pure function of the problem, the tracklets, the settings and its spec, so a
chain gives the same samples wherever it runs: in this process (:class:`InProcess`) or as
a Ray task (:mod:`objslam_mapper.parallel`).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np

from objslam_mapper.config import SamplerConfig
from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.inference.algorithm1 import SampleSummary
from objslam_mapper.inference.chain import ChainResult, MetropolisHastings
from objslam_mapper.inference.diagnostics import Work
from objslam_mapper.inference.screen import ProposalScreen
from objslam_mapper.inference.start import StartState, dispersed_start
from objslam_mapper.inference.target import AssociationTarget, TargetOptions
from objslam_mapper.inference.tracklets import TrackletResult

ChainProgress = Callable[[int, int], None]  # (steps done, steps in all) of one chain

# Pooled by target, a kept state this far below its chain's best weighs under exp(-50) = 2e-22
# of it, below the doubles' resolution of the map's sums: its objects' error covariances (the
# costly part of a kept state's summary on a long run; 52 of 68 kept states of a chain on
# ``loop``) cannot change the map, so such states get the marginals only, which the
# spurious test and the chains' identity indicators need.
NEGLIGIBLE_NATS = 50.0


@dataclass(frozen=True)
class ChainSpec:
    """Chain ``index`` of a run: its kind of start and the run's seed."""

    index: int
    start: str
    seed: int

    def chain_rng(self) -> np.random.Generator:
        """The chain's proposals and acceptances."""
        if self.index == 0:
            return np.random.default_rng(self.seed)
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(self.index,)))

    def start_rng(self) -> np.random.Generator:
        """Its random start, apart from the chain's own stream."""
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(self.index, 1)))


def chain_specs(config: SamplerConfig) -> list[ChainSpec]:
    """The chains of a run: ``sampler.starts`` in turn, random starts beyond them."""
    return [
        ChainSpec(k, config.starts[k] if k < len(config.starts) else "random", config.seed)
        for k in range(config.chains)
    ]


class ChainTask(NamedTuple):
    """What one chain needs."""

    problem: GraphProblem
    tracklets: TrackletResult
    config: SamplerConfig
    spec: ChainSpec


@dataclass(frozen=True)
class ChainOutcome:
    """What one chain gives back: its start, its samples, their solutions and its costs."""

    spec: ChainSpec
    start: StartState
    result: ChainResult
    # One per distinct kept state, in the order of ``result.counts`` (without error covariances
    # where the state's weight is nil: NEGLIGIBLE_NATS).
    summaries: tuple[SampleSummary, ...]
    work: Work
    seconds: float

    @property
    def samples(self) -> list[tuple[SampleSummary, int]]:
        """(summary, multiplicity) of the chain's kept states, for Algorithm 1."""
        return list(zip(self.summaries, self.result.counts.values(), strict=True))

    def kept_log_targets(self) -> list[float]:
        """The log target of each kept state, in the order of ``result.counts``."""
        value = self.result.kept_log_target()
        return [value[state] for state in self.result.counts]


def pooled_samples(outcomes: Sequence[ChainOutcome], pooling: str) -> list[tuple[SampleSummary, float]]:
    """The chains' kept states for Algorithm 1 (chain by chain, each in the order of its
    ``result.counts``), weighted by how often they were kept (``counts``) or by their target
    (``target``).

    ``target`` is the renormalized estimator of model-space MCMC (Clyde and Ghosh 2012;
    Garcia-Donato and Martinez-Beneito 2013): every state the chains kept gets
    ``P(J|Z) / sum of P(J'|Z)`` over the distinct kept states, which the chain's target gives
    exactly. Where the chains have mixed it is the posterior the counts estimate, with less
    noise; where they have not, a chain stuck thousands of nats below the others (on the
    ``clutter`` scenario, a chain from singletons 4000 nats below after 6000 steps: its
    wrong joins bend the trajectory, and the screen at those poses condemns the moves that
    would undo them) adds nothing, where the counts gave it a quarter of the map. What it
    cannot mend is mass no chain visited; the convergence diagnostics still say whether the
    chains agree.
    """
    samples = [sample for outcome in outcomes for sample in outcome.samples]
    if pooling == "counts":
        return [(summary, float(count)) for summary, count in samples]
    states = [state for outcome in outcomes for state in outcome.result.counts]
    values = np.array([value for outcome in outcomes for value in outcome.kept_log_targets()])
    holders = Counter(states)  # a state several chains kept is one state of the sum, its weight shared
    weights = np.exp(values - values.max()) / np.array([holders[state] for state in states])
    return [(summary, float(w)) for (summary, _), w in zip(samples, weights, strict=True)]


def run_chain_task(task: ChainTask, progress: ChainProgress | None = None) -> ChainOutcome:
    """One chain: its own target and screen, its start, the steps, its kept states' solutions."""
    started = time.perf_counter()
    problem, chained, config, spec = task
    work = Work()
    target = AssociationTarget(problem, chained.tracklets, TargetOptions.of(config), work)
    screen = ProposalScreen(target)
    start = dispersed_start(spec.start, screen, config, spec.start_rng())
    sampler = MetropolisHastings(
        chained.labels,
        target,
        config.moves,
        positions_xy_m=[t.position_xy_m for t in chained.tracklets],
        sight_lines=sight_lines(chained),
        tracklet_weights=[len(t) for t in chained.tracklets],
        allow_clutter=config.clutter.enabled,
        screen=screen if config.screen.enabled else None,
        screen_config=config.screen,
        clutter_things=target.clutter_things,
        guide=screen,
    )
    result = sampler.run(
        start.state,
        config.samples,
        config.burn_in,
        spec.chain_rng(),
        progress=progress,
        keep_trace=True,
        on_move=target.move_to,
    )
    value = result.kept_log_target()
    best = max(value.values())
    summaries = tuple(
        target.summary(state, error_covariances=config.pooling != "target" or value[state] >= best - NEGLIGIBLE_NATS)
        for state in result.counts
    )
    return ChainOutcome(spec, start, result, summaries, work, time.perf_counter() - started)


def sight_lines(chained: TrackletResult) -> list[tuple[float, float, float]] | None:
    """The tracklets' lines of sight for the proposals (None unless every tracklet has one)."""
    lines = [t.sight_line for t in chained.tracklets]
    return None if any(line is None for line in lines) else lines  # type: ignore[return-value]


class ChainRunner(Protocol):
    """Runs chain tasks; the outcomes in the order of the tasks."""

    def run(self, tasks: Sequence[ChainTask], progress: Callable[[int, int], None] | None = None) -> list[ChainOutcome]:
        """``progress(done, total)`` counts the steps of all chains."""
        ...


class InProcess:
    """The chains one after another in this process."""

    def run(self, tasks: Sequence[ChainTask], progress: Callable[[int, int], None] | None = None) -> list[ChainOutcome]:
        total = sum(task.config.samples for task in tasks)
        outcomes = []
        for k, task in enumerate(tasks):
            before = k * task.config.samples

            def report(done: int, _total: int, before: int = before) -> None:
                if progress is not None:
                    progress(before + done, total)

            outcomes.append(run_chain_task(task, report))
        return outcomes
