"""What a map build reports about itself: the map file's ``diagnostics``.

The algorithm does not keep its own books. A :class:`Stopwatch` is passed along: it times
the phases, forwards progress, and holds the :class:`Work` that the target and the screen
count their costly calls in; :func:`chain_diagnostics` and :func:`timings` turn what the
steps returned into the reported entries, in the order the map file lists them.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from objslam_mapper.graph.keyframes import keyframes_of
from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.inference.chain import ChainResult
from objslam_mapper.inference.tracklets import TrackletResult

PhaseProgress = Callable[[str, int, int], None]  # phase ("tracklets", "sampling", "mapping"), done, total


@dataclass
class Work:
    """Counts and seconds of a build's costly calls, filled in as they happen."""

    solves: int = 0  # graph solves of associations (the chain's and the start's)
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


def chain_diagnostics(start: Any, chain: ChainResult, work: Work) -> dict[str, Any]:
    """The start state (:class:`~objslam_mapper.inference.start.StartState`), the chain and the solves."""
    return {
        "start_objects": start.first_objects,
        **chain.diagnostics(),
        "start_clutter_tracklets": start.clutter_tracklets,
        "start_tracklets_cleared": len(start.cleared),
        "start_tracklets_recalled": len(start.recalled),
        "best_state_objects": chain.best_state.n_objects,
        "best_state_clutter_tracklets": len(chain.best_state.clutter),
        "solves": work.solves,
        "screens": work.screens,
        "object_solves": work.object_solves,
        "clutter_solves": work.clutter_solves,
    }


def timings(watch: Stopwatch) -> dict[str, float]:
    """Phases that add up to the total; the chain's solves are timed where they happen (a screen
    may need its reference state's solve, counted under solves)."""
    work = watch.work
    tracklets, sampling, mapping = (watch.seconds(p) for p in ("tracklets", "sampling", "mapping"))
    return {
        "tracklets": round(tracklets, 3),
        "sampling": round(sampling, 3),
        "solving_during_sampling": round(work.solve_seconds, 3),
        "screening": round(work.screen_seconds, 3),
        "clutter_solves": round(work.clutter_seconds, 3),
        "proposals_and_chain": round(sampling - work.solve_seconds - work.screen_seconds - work.clutter_seconds, 3),
        "mapping": round(mapping, 3),
        "marginals": round(work.marginal_seconds, 3),
        "map_building": round(mapping - work.marginal_seconds, 3),
        "total": round(watch.ends["mapping"] - watch.started, 3),
    }
