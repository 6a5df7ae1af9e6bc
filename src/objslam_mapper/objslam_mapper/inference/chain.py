"""Metropolis-Hastings over data associations (paper Algorithm 2), with delayed acceptance.

The chain targets any distribution given as an unnormalized ``log_target(J)``; its proposals
and their Hastings ratios come from :mod:`objslam_mapper.inference.moves`.

Delayed acceptance (Christen and Fox, 2005). Given a ``screen(J, J')`` approximating
``log pi(J') - log pi(J)`` cheaply (the sampler's target is costly), a proposal first
passes a screening stage with ``alpha_1(J, J') = min(1, exp(screen(J, J')) P(m'|J') q_m' /
(P(m|J) q_m))``; only a proposal that passes has its target computed, and is accepted with

    alpha_2 = min(1, pi(J') P(m'|J') q_m'(J' -> J) alpha_1(J', J) / (pi(J) P(m|J) q_m(J -> J') alpha_1(J, J'))).

The product ``q alpha_1 alpha_2`` satisfies detailed balance for pi itself, whatever the
screen (it may even depend on the current state, as long as it is a fixed function of
the pair), so the chain still targets pi exactly; a good screen only makes it cheaper,
a poor one makes it mix slower. In fact any first stage ``alpha_1`` in (0, 1] works; the
sampler loosens the screen, ``alpha_1 = max(floor, min(1, exp(a + max(margin,
relative_margin |a|))))`` with ``a`` the log ratio above: the margins because a screen that
errs by a few percent on a move worth thousands of nats (a poster leaving the map drags
the whole trajectory) would otherwise make the second stage reject moves the target
loves, the floor because a screen can be wrong in kind (a loop closure needs the poses to
move, which a screen with fixed poses cannot see): a proposal it condemns still reaches
the target now and then, so the chain is never slower than plain MH by more than 1/floor.
The floor may depend on the pair (J, J') as any first stage may: moves that join tracklets
of different objects of J (or a clutter tracklet to an object), the only ones that can
close a loop, and their reverses, which part them (and can open a wrong loop), get
``join_floor``, the others the lower ``floor`` (:class:`~objslam_mapper.config.ScreenConfig`).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from cachetools import LRUCache
from numpy.typing import ArrayLike

from objslam_mapper.config import MoveConfig, ScreenConfig
from objslam_mapper.errors import MapperError
from objslam_mapper.inference.association import CLUTTER, Association
from objslam_mapper.inference.caches import lru, remember
from objslam_mapper.inference.moves import ClutterThings, Guide, Proposal, Proposals

PROGRESS_MAX_STEPS = 500  # a cancelled build stops within this many steps of a chain

LogTarget = Callable[[Association], float]
Screen = Callable[[Association, Association], float]  # approximate log pi(J') - log pi(J)
Progress = Callable[[int, int], None]


class SamplerError(MapperError, RuntimeError):
    """The chain cannot run (invalid start state, impossible target)."""


@dataclass
class MoveStats:
    proposed: int = 0  # proposals that changed the state
    accepted: int = 0
    screened_out: int = 0  # rejected by the screen (delayed acceptance), target never computed
    floor_passes: int = 0  # passed the screen only through its floor (the screen condemned them)
    floor_accepted: int = 0  # ... and were accepted all the same

    @property
    def acceptance_rate(self) -> float:
        return self.accepted / self.proposed if self.proposed else 0.0


@dataclass(frozen=True)
class ChainResult:
    """What a run of the chain produced; ``counts`` and ``trace`` hold the kept samples (after burn-in)."""

    counts: dict[Association, int]
    trace: tuple[Association, ...]
    moves: dict[str, MoveStats]
    distinct_visited: int  # states the chain was in, burn-in included
    target_evaluations: int  # distinct states whose target was computed
    final_state: Association
    best_state: Association
    best_log_target: float
    samples: int
    burn_in: int
    log_targets: tuple[float, ...] = ()  # log target of each state of ``trace``
    history: tuple[tuple[float, int], ...] = ()  # (log target, objects) after every step, burn-in included

    def kept_log_target(self) -> dict[Association, float]:
        """The log target of each distinct kept state (read off the trace)."""
        return dict(zip(self.trace, self.log_targets, strict=True))

    @property
    def acceptance_rates(self) -> dict[str, float]:
        return {kind: stats.acceptance_rate for kind, stats in self.moves.items()}

    @property
    def overall_acceptance_rate(self) -> float:
        proposed = sum(s.proposed for s in self.moves.values())
        return sum(s.accepted for s in self.moves.values()) / proposed if proposed else 0.0

    def diagnostics(self) -> dict[str, object]:
        return {
            "samples": self.samples,
            "burn_in": self.burn_in,
            "kept_samples": sum(self.counts.values()),
            "acceptance_rate": round(self.overall_acceptance_rate, 4),
            "acceptance_rates": {k: round(v, 4) for k, v in self.acceptance_rates.items()},
            "proposals": {k: s.proposed for k, s in self.moves.items()},
            "screened_out": {k: s.screened_out for k, s in self.moves.items()},
            "floor_passes": {k: s.floor_passes for k, s in self.moves.items()},
            "floor_accepted": {k: s.floor_accepted for k, s in self.moves.items()},
            "distinct_associations_visited": self.distinct_visited,
            "distinct_associations_kept": len(self.counts),
            "target_evaluations": self.target_evaluations,
            "best_log_target": float(self.best_log_target),
        }


class CachedLogTarget:
    """A log target remembered per state (LRU): a rejected proposal repeats the current state."""

    def __init__(self, fn: LogTarget, maxsize: int = 1_000_000):
        self._fn = fn
        self._cache: LRUCache[Association, float] = lru(maxsize)
        self.evaluations = 0

    def __call__(self, state: Association) -> float:
        value = self._cache.get(state)
        if value is not None:
            return value
        value = float(self._fn(state))
        if math.isnan(value):
            raise SamplerError(f"log target is NaN for state {state.assignment}")
        self.evaluations += 1
        return remember(self._cache, state, value)


class Acceptance(NamedTuple):
    """The verdict on one proposal."""

    log_alpha: float | None  # log acceptance probability; None: the screen rejected it
    at_floor: bool  # it passed the screen only by the screen's floor


def _joined_parts(state: Association, new: Association) -> list[tuple[list[int], list[int]]]:
    """Pairs of tracklet sets that an object of ``new`` joins: of two objects of ``state``, or an
    object's and a clutter tracklet (each part against the rest of its new object)."""
    joined = []
    for group in new.groups:
        parts: dict[object, list[int]] = {}
        for t in group:
            owner = state.assignment[t]
            parts.setdefault(owner if owner != CLUTTER else (CLUTTER, t), []).append(t)
        if len(parts) > 1:
            sets = list(parts.values())
            joined += [(part, [t for other in sets if other is not part for t in other]) for part in sets[:-1]]
    return joined


class MetropolisHastings:
    """MH sampler over associations of a fixed set of tracklets.

    ``labels``, ``moves``, ``positions_xy_m``, ``tracklet_weights``, ``allow_clutter``,
    ``sight_lines``, ``clutter_things`` and ``guide`` make its
    :class:`~objslam_mapper.inference.moves.Proposals`. ``screen``, if given, makes
    each step a delayed-acceptance step (module docstring), loosened and floored as
    ``screen_config`` says.
    """

    def __init__(
        self,
        labels: Sequence[str],
        log_target: LogTarget,
        moves: MoveConfig | None = None,
        *,
        positions_xy_m: ArrayLike | None = None,
        tracklet_weights: ArrayLike | None = None,
        allow_clutter: bool = True,
        screen: Screen | None = None,
        screen_config: ScreenConfig | None = None,
        sight_lines: ArrayLike | None = None,
        clutter_things: ClutterThings | None = None,
        guide: Guide | None = None,
    ):
        self.proposals = Proposals(
            labels,
            moves,
            positions_xy_m,
            tracklet_weights,
            allow_clutter,
            sight_lines=sight_lines,
            clutter_things=clutter_things,
            guide=guide,
        )
        self.screen = screen
        config = screen_config or ScreenConfig()
        self.screen_margin = config.margin_nats
        self.screen_relative_margin = config.relative_margin
        for name, value in (("floor", config.floor), ("join_floor", config.join_floor)):
            if not 0.0 <= value <= 1.0:
                raise SamplerError(f"screen {name} must lie in [0, 1], got {value}")
        self._log_screen_floor = math.log(config.floor) if config.floor > 0.0 else -math.inf
        self._log_join_floor = math.log(config.join_floor) if config.join_floor > 0.0 else -math.inf
        self._far_join_m = config.far_join_m
        self.target = log_target if isinstance(log_target, CachedLogTarget) else CachedLogTarget(log_target)

    # ---- the chain ---------------------------------------------------------------
    def _log_acceptance(
        self, state: Association, log_p: float, proposal: Proposal, rng: np.random.Generator
    ) -> Acceptance:
        """The verdict on ``proposal`` from ``state`` (whose log target is ``log_p``): the log of
        its acceptance probability, None when the screen rejected it (its target is then never
        computed), and whether it passed the screen only by the floor."""
        new = proposal.view.state
        if self.screen is None:
            if proposal.reversible is not None and not proposal.reversible():
                return Acceptance(-math.inf, False)  # no way back: refused without solving J'
            log_p_new = self.target(new)
            if log_p_new == -math.inf:
                return Acceptance(-math.inf, False)
            return Acceptance(log_p_new - log_p + proposal.reverse_log_q() - proposal.log_q_forward, False)
        # A reverse known only once J' is solved (informed moves) cannot shape the first stage:
        # that stage then judges the screen alone, the same way in both directions.
        log_q_screened = 0.0 if proposal.reverse_later else proposal.log_q_reverse - proposal.log_q_forward
        log_floor = self._log_floor(state, new)
        log_first = self._first_stage(self.screen(state, new) + log_q_screened, log_floor)
        if not (log_first >= 0.0 or math.log(rng.random()) < log_first):
            return Acceptance(None, False)
        at_floor = log_first <= log_floor
        if proposal.reversible is not None and not proposal.reversible():
            # Refused as the second stage would refuse it (its reverse is impossible), without
            # solving J': the chain draws the same random numbers either way.
            return Acceptance(-math.inf, at_floor)
        log_p_new = self.target(new)
        if log_p_new == -math.inf:
            return Acceptance(-math.inf, at_floor)
        log_back = self._first_stage(self.screen(new, state) - log_q_screened, self._log_floor(new, state))
        log_q = proposal.reverse_log_q() - proposal.log_q_forward
        return Acceptance(log_p_new - log_p + log_q + log_back - log_first, at_floor)

    def _log_floor(self, state: Association, new: Association) -> float:
        """The screen's floor for the move ``state -> new``: the join floor when it joins
        tracklets (an object of ``new`` holds tracklets of two objects of ``state``, or an
        object's and a clutter tracklet) or parts them (the same from ``new`` to ``state``).
        A join may close a loop; a part may open a wrong one (on ``office`` a chain from the
        greedy start kept a poster's tracklet in an object 5.5 m away: the screen, at the poses
        that join had bent, judged its leaving -222 nats, the target +1654). Neither shows
        at fixed poses. A move that joins or parts tracklets more than ``far_join_m`` apart is
        always solved: on ``clutter`` chains from the singleton and greedy starts kept a red
        tracklet in an object 6 m away, whose leaving the screen judged -256 nats and the
        target +1467, and stayed 3700 nats below the others after 6000 steps."""
        joined = _joined_parts(state, new) + _joined_parts(new, state)
        if not joined:
            return self._log_screen_floor
        if self._far_join_m > 0.0 and any(
            self.proposals.tracklet_distance_m(a, b) > self._far_join_m for a, b in joined
        ):
            return 0.0
        return self._log_join_floor

    def _first_stage(self, log_ratio: float, log_floor: float) -> float:
        """log alpha_1 of a screen log ratio: loosened by the margins, clamped to [log floor, 0]."""
        if math.isfinite(log_ratio):
            log_ratio += max(self.screen_margin, self.screen_relative_margin * abs(log_ratio))
        elif math.isnan(log_ratio):
            log_ratio = -math.inf
        return max(log_floor, min(0.0, log_ratio))

    def check_state(self, state: Association) -> None:
        if state.n_tracklets != len(self.proposals.labels):
            raise SamplerError(f"state has {state.n_tracklets} tracklets, the sampler {len(self.proposals.labels)}")
        state.validate(self.proposals.labels)
        if state.clutter and not self.proposals.allow_clutter:
            raise SamplerError("start state has clutter tracklets but clutter is disabled")

    def run(
        self,
        initial: Association,
        samples: int,
        burn_in: int,
        rng: np.random.Generator | int,
        *,
        progress: Progress | None = None,
        keep_trace: bool = True,
        on_move: Callable[[Association, float], None] | None = None,
    ) -> ChainResult:
        """Run ``samples`` steps; the states after the first ``burn_in`` steps are kept.

        ``progress(done, total)`` is called about 200 times, and at least every
        PROGRESS_MAX_STEPS steps (where a caller can cancel by raising); ``on_move(state, log_target)``
        with the start state and after every accepted move (e.g. to warm-start the next solves
        from the chain's current state), the value the chain holds for it.
        """
        if not 0 <= burn_in < samples:
            raise SamplerError(f"need 0 <= burn_in < samples, got burn_in={burn_in}, samples={samples}")
        self.check_state(initial)
        rng = np.random.default_rng(rng) if not isinstance(rng, np.random.Generator) else rng
        view = self.proposals.view(initial)
        evaluations_before = self.target.evaluations
        log_p = self.target(initial)
        if not math.isfinite(log_p):
            raise SamplerError(f"log target of the start state is {log_p}")
        if on_move is not None:
            on_move(initial, log_p)
        best_state, best_log_p = initial, log_p
        stats = {kind: MoveStats() for kind in self.proposals.kind_weights}
        visited = {initial}
        counts: Counter[Association] = Counter()
        trace: list[Association] = []
        log_targets: list[float] = []
        history: list[tuple[float, int]] = []
        every = max(1, min(samples // 200, PROGRESS_MAX_STEPS))
        for step in range(samples):
            proposal = self.proposals.propose(view, rng)
            if proposal is not None:
                kind = proposal.kind
                stats[kind].proposed += 1
                log_alpha, at_floor = self._log_acceptance(view.state, log_p, proposal, rng)
                stats[kind].floor_passes += int(at_floor)
                if log_alpha is None:
                    stats[kind].screened_out += 1
                elif log_alpha >= 0.0 or math.log(rng.random()) < log_alpha:
                    stats[kind].accepted += 1
                    stats[kind].floor_accepted += int(at_floor)
                    view, log_p = proposal.view, self.target(proposal.view.state)
                    visited.add(view.state)
                    if on_move is not None:
                        on_move(view.state, log_p)
                    if log_p > best_log_p:
                        best_state, best_log_p = view.state, log_p
            history.append((log_p, view.state.n_objects))
            if step >= burn_in:
                counts[view.state] += 1
                if keep_trace:
                    trace.append(view.state)
                    log_targets.append(log_p)
            if progress is not None and ((step + 1) % every == 0 or step + 1 == samples):
                progress(step + 1, samples)
        return ChainResult(
            counts=dict(counts),
            trace=tuple(trace),
            log_targets=tuple(log_targets),
            history=tuple(history),
            moves=stats,
            distinct_visited=len(visited),
            target_evaluations=self.target.evaluations - evaluations_before,
            final_state=view.state,
            best_state=best_state,
            best_log_target=best_log_p,
            samples=samples,
            burn_in=burn_in,
        )
