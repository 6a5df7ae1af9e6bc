"""What a map build reports about itself: the map file's ``diagnostics``.

The algorithm does not keep its own books. A :class:`Stopwatch` is passed along: it times
the phases and forwards progress; each chain has a :class:`Work` that its target and
screen count their costly calls in; :func:`chains_diagnostics`, :func:`work_diagnostics`
and :func:`timings` turn what the steps returned into the reported entries.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from objslam_mapper.graph.keyframes import keyframes_of
from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.inference.tracklets import TrackletResult

if TYPE_CHECKING:
    from objslam_mapper.inference.chains import ChainOutcome

PhaseProgress = Callable[[str, int, int], None]  # phase ("tracklets", "sampling", "mapping"), done, total


@dataclass
class Work:
    """Counts and seconds of a build's costly calls, filled in as they happen."""

    solves: int = 0  # graph solves of associations (the chain's and the start's)
    unconverged_solves: int = 0  # of those, the ones that stopped before converging
    settled_solves: int = 0  # unconverged proposals solved on before the chain judged them
    unconverged_settles: int = 0  # of those, the ones that still did not converge
    solve_seconds: float = 0.0
    screens: int = 0  # proposals screened
    screen_seconds: float = 0.0  # the screens' conditional object solves only
    object_solves: int = 0  # conditional object solves
    clutter_solves: int = 0  # one distractor solve per tracklet, ever: it does not depend on J
    clutter_seconds: float = 0.0
    marginal_solves: int = 0  # solves with covariances of the kept states (Algorithm 1)
    marginal_seconds: float = 0.0


@dataclass
class Stopwatch:
    """Phase ends since the build started, progress forwarding and the build's :class:`Work`."""

    progress: PhaseProgress | None = None
    started: float = field(default_factory=time.perf_counter)
    ends: dict[str, float] = field(default_factory=dict)
    work: Work = field(default_factory=Work)

    def report(self, phase: str, done: int, total: int) -> None:
        if self.progress is not None:
            self.progress(phase, done, total)

    def lap(self, phase: str) -> float:
        """Mark the end of ``phase``; seconds it took since the previous mark."""
        previous = max(self.ends.values(), default=self.started)
        self.ends[phase] = time.perf_counter()
        return self.ends[phase] - previous

    def resume(self) -> None:
        """Start the next phase now: the marks shift so the last phase ends now, each phase
        keeping its length (a run prepared in another process, or before other runs)."""
        shift = time.perf_counter() - max(self.ends.values(), default=self.started)
        self.started += shift
        self.ends = {phase: end + shift for phase, end in self.ends.items()}

    def seconds(self, phase: str) -> float:
        """How long ``phase`` took (from the previous phase's end)."""
        ends = list(self.ends.items())
        k = [name for name, _ in ends].index(phase)
        return ends[k][1] - (ends[k - 1][1] if k else self.started)


def inputs_diagnostics(problem: GraphProblem, chained: TrackletResult, seed: int) -> dict[str, Any]:
    """What the build started from."""
    return {
        "seed": seed,
        "poses": problem.pose_count,
        "graph_poses": keyframes_of(problem).problem.pose_count,  # objslam_mapper.graph.keyframes
        "measurements": problem.measurement_count,
        "rejected_images": problem.rejected_image_count,
        "rejected_slices": problem.rejected_slice_count,
        "tracklets": len(chained.tracklets),
        "isolated_dropped": len(chained.dropped_measurements),
    }


def chains_diagnostics(outcomes: Sequence[ChainOutcome]) -> dict[str, Any]:
    """The chains, pooled and one by one: starts, acceptance, states visited, best log target, objects."""
    results = [o.result for o in outcomes]
    proposed = sum(s.proposed for r in results for s in r.moves.values())
    accepted = sum(s.accepted for r in results for s in r.moves.values())
    return {
        "chains": len(outcomes),
        "samples": results[0].samples,
        "burn_in": results[0].burn_in,
        "kept_samples": sum(sum(r.counts.values()) for r in results),
        "acceptance_rate": round(accepted / proposed, 4) if proposed else 0.0,
        "best_log_target": max(float(r.best_log_target) for r in results),
        "chain_runs": [_chain_run(o) for o in outcomes],
    }


def _chain_run(outcome: ChainOutcome) -> dict[str, Any]:
    result, start, work = outcome.result, outcome.start, outcome.work
    kept_objects = [state.n_objects for state in result.trace] or [result.final_state.n_objects]
    return {
        "chain": outcome.spec.index,
        "start": outcome.spec.start,
        "start_objects": start.first_objects,
        "start_clutter_tracklets": start.clutter_tracklets,
        "start_tracklets_cleared": len(start.cleared),
        "start_tracklets_recalled": len(start.recalled),
        **result.diagnostics(),
        "best_state_objects": result.best_state.n_objects,
        "best_state_clutter_tracklets": len(result.best_state.clutter),
        "kept_objects_mean": round(sum(kept_objects) / len(kept_objects), 3),
        "solves": work.solves,
        "unconverged_solves": work.unconverged_solves,
        "settled_solves": work.settled_solves,
        "unconverged_settles": work.unconverged_settles,
        "screens": work.screens,
        "trace": _thinned(result.history),
    }


TRACE_POINTS = 300  # per chain, in the map file: enough for a picture


def _thinned(history: Sequence[tuple[float, int]]) -> dict[str, Any]:
    """Every k-th step's (log target, objects), burn-in included, k so that about TRACE_POINTS remain."""
    every = max(1, -(-len(history) // TRACE_POINTS))
    kept = history[every - 1 :: every]
    return {
        "every_steps": every,
        "log_target": [round(float(v), 2) for v, _ in kept],
        "objects": [int(n) for _, n in kept],
    }


def work_diagnostics(outcomes: Sequence[ChainOutcome]) -> dict[str, int]:
    """The costly calls of all chains."""
    fields = (
        "solves",
        "unconverged_solves",
        "settled_solves",
        "unconverged_settles",
        "screens",
        "object_solves",
        "clutter_solves",
        "marginal_solves",
    )
    return {name: sum(getattr(o.work, name) for o in outcomes) for name in fields}


def timings(watch: Stopwatch, outcomes: Sequence[ChainOutcome]) -> dict[str, Any]:
    """Wall seconds of the phases (``tracklets + sampling + mapping == total``), and where the
    chains' seconds went, summed over the chains (so more than the sampling's wall time when
    they run in parallel): graph solves, screens, clutter solves, the kept states' marginals,
    and the rest (proposals and chain bookkeeping)."""
    work = [o.work for o in outcomes]
    spent = {
        "solving_during_sampling": sum(w.solve_seconds for w in work),
        "screening": sum(w.screen_seconds for w in work),
        "clutter_solves": sum(w.clutter_seconds for w in work),
        "marginals": sum(w.marginal_seconds for w in work),
    }
    chains = sum(o.seconds for o in outcomes)
    return {
        "tracklets": round(watch.seconds("tracklets"), 3),
        "sampling": round(watch.seconds("sampling"), 3),
        "mapping": round(watch.seconds("mapping"), 3),
        "total": round(watch.ends["mapping"] - watch.started, 3),
        "chains": round(chains, 3),
        "chain_seconds": [round(o.seconds, 3) for o in outcomes],
        **{name: round(seconds, 3) for name, seconds in spent.items()},
        "proposals_and_chain": round(chains - sum(spent.values()), 3),
        "map_building": round(watch.seconds("mapping"), 3),
    }
