"""Metropolis-Hastings over data associations (paper Algorithm 2, section 4).

The chain walks over states J (objslam_mapper.inference.association) and targets any distribution
given as an unnormalized ``log_target(J)``. Moves, in the spirit of Ranganathan (2008),
come in reverse pairs so every proposal has an exact Hastings ratio:

- ``merge`` two objects of one class  <->  ``split`` one object in two,
- ``reassign`` one tracklet to another object or to a new object (its own reverse),
- ``to_clutter`` a tracklet  <->  ``from_clutter`` a tracklet into an object or a new one.

The move kind is drawn among the kinds possible in the current state (nothing to split,
no clutter...) in proportion to configured weights, so P(m | J) depends on J. With a move m
taking J to J' and its reverse m' taking J' back, the acceptance is

    alpha = min(1, pi(J') P(m' | J') q_m'(J' -> J) / (pi(J) P(m | J) q_m(J -> J'))),

which gives detailed balance move pair by move pair, so the chain's stationary law is pi
(Green, 1995). Reverse proposal probabilities are always computed in the proposed state.

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
close a loop, get ``screen_join_floor``, the others the lower ``screen_floor``.

Proposals are geometry aware when rough tracklet positions are given: merges and
reassignments prefer nearby objects, splits separate tracklets that are far apart. The
weights only depend on the state and the fixed tracklet positions, and a floor keeps every
move possible, so the chain stays irreducible and the ratio exact.
"""

from __future__ import annotations

import logging
import math
from bisect import bisect_right
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from itertools import accumulate
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from objslam_common.config import setting
from scipy.special import expit

from objslam_mapper.errors import MapperError
from objslam_mapper.inference.association import CLUTTER, Association

logger = logging.getLogger(__name__)

LogTarget = Callable[[Association], float]
Screen = Callable[[Association, Association], float]  # approximate log pi(J') - log pi(J)
Progress = Callable[[int, int], None]

MOVE_KINDS = ("merge", "split", "reassign", "to_clutter", "from_clutter")
REVERSE_MOVE = {
    "merge": "split",
    "split": "merge",
    "reassign": "reassign",
    "to_clutter": "from_clutter",
    "from_clutter": "to_clutter",
}
_NEW = -2  # destination key: a new object
_CACHE_SIZE = 20_000  # per-state proposal weights kept


def _logsumexp(values: NDArray[np.float64]) -> float:
    m = float(values.max())
    return m + math.log(float(np.exp(values - m).sum()))


class _Choice:
    """Keys with positive weights: draw one in proportion, or give one's log probability."""

    __slots__ = ("cdf", "index", "keys", "total", "weights")

    def __init__(self, keys: Sequence[Any], weights: Iterable[float]):
        self.keys = list(keys)
        self.weights = [float(w) for w in weights]
        self.cdf = list(accumulate(self.weights))
        self.total = self.cdf[-1] if self.cdf else 0.0
        self.index = {k: i for i, k in enumerate(self.keys)}

    def __len__(self) -> int:
        return len(self.keys)

    def draw(self, rng: np.random.Generator) -> Any:
        i = bisect_right(self.cdf, rng.random() * self.total)
        return self.keys[min(i, len(self.keys) - 1)]

    def log_prob(self, key: Any) -> float:
        return math.log(self.weights[self.index[key]] / self.total)


class SamplerError(MapperError, RuntimeError):
    """The chain cannot run (invalid start state, impossible target)."""


@dataclass(frozen=True)
class MoveConfig:
    """How the chain proposes new associations (probabilities are normalized over the usable kinds)."""

    merge: float = setting(0.2, "probability of proposing to merge two objects of one class", minimum=0.0)
    split: float = setting(0.2, "probability of proposing to split one object in two", minimum=0.0)
    reassign: float = setting(0.3, "probability of moving one tracklet to another or a new object", minimum=0.0)
    to_clutter: float = setting(0.15, "probability of moving one tracklet to the clutter set", minimum=0.0)
    from_clutter: float = setting(0.15, "probability of moving a clutter tracklet into an object", minimum=0.0)
    distance_scale_m: float = setting(
        1.0, "merges and reassignments prefer objects within about this distance (m)", minimum=1e-3
    )
    weight_floor: float = setting(
        0.01, "proposal weight of an object however far away (keeps every move possible)", minimum=1e-9
    )
    new_object_weight: float = setting(
        0.2, "proposal weight of 'a new object' (an existing object at distance 0 weighs 1)", minimum=1e-9
    )
    split_randomness: float = setting(
        0.2,
        "share of a split decided by a coin flip instead of by distance to the two seeds",
        minimum=1e-3,
        maximum=1.0,
    )

    def __post_init__(self) -> None:
        if self.merge + self.split + self.reassign <= 0.0:
            raise ValueError("merge, split and reassign probabilities cannot all be zero")
        if (self.merge > 0.0) != (self.split > 0.0):
            raise ValueError("merge and split are each other's reverse: both or neither must be > 0")
        if (self.to_clutter > 0.0) != (self.from_clutter > 0.0):
            raise ValueError("to_clutter and from_clutter are each other's reverse: both or neither must be > 0")


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
        self._maxsize = maxsize
        self._cache: OrderedDict[Association, float] = OrderedDict()
        self.evaluations = 0

    def __call__(self, state: Association) -> float:
        value = self._cache.get(state)
        if value is not None:
            self._cache.move_to_end(state)
            return value
        value = float(self._fn(state))
        if math.isnan(value):
            raise SamplerError(f"log target is NaN for state {state.assignment}")
        self.evaluations += 1
        self._cache[state] = value
        if len(self._cache) > self._maxsize:
            self._cache.popitem(last=False)
        return value


@dataclass
class _View:
    """One state with what the proposals need: object members, classes and centroids."""

    state: Association
    groups: tuple[tuple[int, ...], ...]
    labels: list[str]  # per object
    centroids: NDArray[np.float64]  # (K, 2) per object
    # Proposal weights, filled on first use: after a rejection the chain proposes from here again.
    kinds: _Choice | None = None  # the move kinds possible here
    merges: _Choice | None = None  # keys: object pairs (i, j), i < j, of one class
    movable: list[int] | None = None  # tracklets in objects that another object (or a new one) can take
    destinations: dict[int, _Choice] = field(default_factory=dict)  # per tracklet

    @property
    def assignment(self) -> tuple[int, ...]:
        return self.state.assignment

    def others_in_object(self, t: int) -> list[int]:
        return [u for u in self.groups[self.assignment[t]] if u != t]


@dataclass(frozen=True)
class Proposal:
    kind: str
    view: _View
    log_q_forward: float  # log P(kind | J) q(J -> J'), in the current state
    log_q_reverse: float  # log P(reverse kind | J') q(J' -> J), in the proposed state


class Acceptance(NamedTuple):
    """The verdict on one proposal."""

    log_alpha: float | None  # log acceptance probability; None: the screen rejected it
    at_floor: bool  # it passed the screen only by the screen's floor


class MetropolisHastings:
    """MH sampler over associations of a fixed set of tracklets.

    ``positions_xy_m`` (T, 2) are rough tracklet positions used only to shape proposals,
    ``tracklet_weights`` (T,) weigh them in object centroids (e.g. slices per tracklet).
    ``screen``, if given, makes each step a delayed-acceptance step (module docstring).
    """

    def __init__(
        self,
        labels: Sequence[str],
        log_target: LogTarget,
        moves: MoveConfig | None = None,
        positions_xy_m: ArrayLike | None = None,
        tracklet_weights: ArrayLike | None = None,
        allow_clutter: bool = True,
        screen: Screen | None = None,
        screen_margin: float = 0.0,
        screen_relative_margin: float = 0.0,
        screen_floor: float = 0.0,
        screen_join_floor: float | None = None,
    ):
        self.labels = list(labels)
        self.screen = screen
        self.screen_margin = screen_margin
        self.screen_relative_margin = screen_relative_margin
        join_floor = screen_floor if screen_join_floor is None else screen_join_floor
        for name, value in (("screen_floor", screen_floor), ("screen_join_floor", join_floor)):
            if not 0.0 <= value <= 1.0:
                raise SamplerError(f"{name} must lie in [0, 1], got {value}")
        self._log_screen_floor = math.log(screen_floor) if screen_floor > 0.0 else -math.inf
        self._log_join_floor = math.log(join_floor) if join_floor > 0.0 else -math.inf
        self.moves = moves or MoveConfig()
        n = len(self.labels)
        self.positions = np.zeros((n, 2)) if positions_xy_m is None else np.asarray(positions_xy_m, float).reshape(n, 2)
        self.weights = np.ones(n) if tracklet_weights is None else np.asarray(tracklet_weights, float).reshape(n)
        if np.any(self.weights <= 0.0):
            raise SamplerError("tracklet weights must be positive")
        self.target = log_target if isinstance(log_target, CachedLogTarget) else CachedLogTarget(log_target)
        self.allow_clutter = allow_clutter
        probs = {kind: float(getattr(self.moves, kind)) for kind in MOVE_KINDS}
        if not allow_clutter:
            probs["to_clutter"] = probs["from_clutter"] = 0.0
        self.kind_weights = {k: p for k, p in probs.items() if p > 0.0}
        self._inv_two_scale2 = 0.5 / self.moves.distance_scale_m**2
        self._views: OrderedDict[Association, _View] = OrderedDict()
        self._bipartitions: dict[tuple[tuple[int, ...], bytes], float] = {}

    # ---- state views -------------------------------------------------------------
    def view(self, state: Association) -> _View:
        cached = self._views.get(state)
        if cached is not None:
            self._views.move_to_end(state)
            return cached
        groups = state.groups
        centroids = np.zeros((len(groups), 2))
        for j, g in enumerate(groups):
            w = self.weights[list(g)]
            centroids[j] = w @ self.positions[list(g)] / w.sum()
        view = _View(state, groups, [self.labels[g[0]] for g in groups], centroids)
        self._views[state] = view
        if len(self._views) > _CACHE_SIZE:
            self._views.popitem(last=False)
        return view

    def _view_of(self, assignment: list[int]) -> _View:
        return self.view(Association.of(assignment))

    # ---- proposal weights (shared by forward and reverse computations) -----------
    def _closeness(self, d2: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.moves.weight_floor + np.exp(-d2 * self._inv_two_scale2)

    def _merges(self, view: _View) -> _Choice:
        """Every pair of objects of one class, weighted by the closeness of their centroids."""
        if view.merges is None:
            pairs = [
                (i, j)
                for i in range(len(view.groups))
                for j in range(i + 1, len(view.groups))
                if view.labels[i] == view.labels[j]
            ]
            idx = np.array(pairs, dtype=int).reshape(-1, 2)
            d2 = ((view.centroids[idx[:, 0]] - view.centroids[idx[:, 1]]) ** 2).sum(-1)
            view.merges = _Choice(pairs, self._closeness(d2))
        return view.merges

    def _kinds(self, view: _View) -> _Choice:
        """The move kinds possible in this state, weighted as configured."""
        if view.kinds is None:
            possible = {
                "merge": len(self._merges(view)) > 0,
                "split": any(len(g) > 1 for g in view.groups),
                "reassign": len(self._movable(view)) > 0,
                "to_clutter": len(view.state.clutter) < view.state.n_tracklets,
                "from_clutter": len(view.state.clutter) > 0,
            }
            kinds = [k for k in self.kind_weights if possible[k]]
            view.kinds = _Choice(kinds, [self.kind_weights[k] for k in kinds])
        return view.kinds

    def _movable(self, view: _View) -> list[int]:
        """Tracklets in an object that can be reassigned: to a new object if they share
        theirs, else to another object of their class."""
        if view.movable is None:
            per_class = Counter(view.labels)
            view.movable = [
                t
                for t, a in enumerate(view.assignment)
                if a != CLUTTER and (len(view.groups[a]) > 1 or per_class[view.labels[a]] > 1)
            ]
        return view.movable

    def _destinations(self, view: _View, t: int) -> _Choice:
        """Where tracklet t may go (object indices, or _NEW), weighted by closeness.

        Same for ``reassign`` (t in an object) and ``from_clutter`` (t in clutter): every
        other object of t's class, plus a new object unless t already is alone in one.
        """
        if t not in view.destinations:
            own = view.assignment[t]
            keys = [j for j, lab in enumerate(view.labels) if lab == self.labels[t] and j != own]
            weights = list(self._closeness(((view.centroids[keys] - self.positions[t]) ** 2).sum(-1)))
            if own == CLUTTER or len(view.groups[own]) > 1:
                keys.append(_NEW)
                weights.append(self.moves.new_object_weight)
            view.destinations[t] = _Choice(keys, weights)
        return view.destinations[t]

    def _seed_side_probs(self, xy: NDArray[np.float64], d2_a: NDArray, d2_b: NDArray) -> NDArray[np.float64]:
        """P(member joins seed a's side) from squared distances to the seeds a and b.

        Symmetric in the seeds (swapping them gives 1 - p), which the bipartition sum uses.
        """
        mix = self.moves.split_randomness
        return 0.5 * mix + (1.0 - mix) * expit((d2_b - d2_a) * self._inv_two_scale2)

    def _log_bipartition(self, members: Sequence[int], side_p: NDArray[np.bool_]) -> float:
        """log q of splitting ``members`` into (side_p, ~side_p), summed over every seed pair.

        The split draws ordered seeds (a, b) uniformly, then sends every other member to
        a's side with probability p_a(i), else to b's. As p_a is symmetric in the seeds, the
        unordered bipartition {P, Q} has probability 2 / (n (n - 1)) * sum over a in P,
        b in Q of prod_{i in P \\ a} p_a(i) prod_{i in Q \\ b} (1 - p_a(i)).
        """
        key = (tuple(members), side_p.tobytes())
        cached = self._bipartitions.get(key)
        if cached is None:
            n = len(members)
            xy = self.positions[list(members)]
            d2 = ((xy[:, None, :] - xy[None, :, :]) ** 2).sum(-1)
            p_idx, q_idx = np.flatnonzero(side_p), np.flatnonzero(~side_p)
            p_a = self._seed_side_probs(xy, d2[p_idx][:, None, :], d2[q_idx][None, :, :])  # (|P|, |Q|, n)
            log_side = np.where(side_p, np.log(p_a), np.log1p(-p_a))
            rows, cols = np.arange(len(p_idx))[:, None], np.arange(len(q_idx))[None, :]
            log_side[rows, cols, p_idx[:, None]] = 0.0  # the seeds are placed, not drawn
            log_side[rows, cols, q_idx[None, :]] = 0.0
            cached = math.log(2.0 / (n * (n - 1))) + _logsumexp(log_side.sum(-1))
            if len(self._bipartitions) >= _CACHE_SIZE:
                self._bipartitions.clear()
            self._bipartitions[key] = cached
        return cached

    # ---- moves -------------------------------------------------------------------
    def _propose_merge(self, view: _View, rng: np.random.Generator) -> Proposal:
        merges = self._merges(view)
        i, j = merges.draw(rng)
        new = self._view_of([i if a == j else a for a in view.assignment])
        merged = new.groups[new.assignment[view.groups[i][0]]]
        side_p = np.array([view.assignment[t] == i for t in merged])
        n_splittable = sum(len(g) > 1 for g in new.groups)
        log_f = self._kinds(view).log_prob("merge") + merges.log_prob((i, j))
        log_r = self._kinds(new).log_prob("split") - math.log(n_splittable) + self._log_bipartition(merged, side_p)
        return Proposal("merge", new, log_f, log_r)

    def _propose_split(self, view: _View, rng: np.random.Generator) -> Proposal:
        splittable = [j for j, g in enumerate(view.groups) if len(g) > 1]
        members = view.groups[splittable[int(rng.integers(len(splittable)))]]
        n = len(members)
        a = int(rng.integers(n))
        b = int(rng.integers(n - 1))
        b += b >= a
        xy = self.positions[list(members)]
        p_a = self._seed_side_probs(xy, ((xy - xy[a]) ** 2).sum(-1), ((xy - xy[b]) ** 2).sum(-1))
        side_p = rng.random(n) < p_a
        side_p[a], side_p[b] = True, False
        assignment = list(view.assignment)
        for t, on_p in zip(members, side_p, strict=True):
            if not on_p:
                assignment[t] = len(view.groups)
        new = self._view_of(assignment)
        pair = tuple(sorted((new.assignment[members[a]], new.assignment[members[b]])))
        log_f = self._kinds(view).log_prob("split") - math.log(len(splittable))
        log_f += self._log_bipartition(members, side_p)
        log_r = self._kinds(new).log_prob("merge") + self._merges(new).log_prob(pair)
        return Proposal("split", new, log_f, log_r)

    def _move_tracklet(self, view: _View, t: int, rng: np.random.Generator) -> tuple[_View, int]:
        """Move t to a drawn destination: the new view and the destination key."""
        dest = self._destinations(view, t).draw(rng)
        assignment = list(view.assignment)
        assignment[t] = len(view.groups) if dest == _NEW else dest
        return self._view_of(assignment), dest

    def _way_back(self, view: _View, new: _View, t: int) -> int:
        """The destination key, in ``new``, that returns t to where it was in ``view``."""
        rest = view.others_in_object(t)
        return new.assignment[rest[0]] if rest else _NEW

    def _log_reassign(self, view: _View, t: int, dest: int) -> float:
        """log q of the state reached by reassigning t to ``dest``, without the kind factor.

        Two tracklets t, u lead to the same state in two ways: merging singletons {t} and
        {u} (t joins u, or u joins t) and splitting {t, u} (t leaves, or u leaves); q sums
        both. Every other reassignment reaches its state in exactly one way.
        """
        log_q = self._destinations(view, t).log_prob(dest)
        own = view.groups[view.assignment[t]]
        twin: tuple[int, int] | None = None
        if len(own) == 1 and dest != _NEW and len(view.groups[dest]) == 1:
            twin = (view.groups[dest][0], view.assignment[t])
        elif len(own) == 2 and dest == _NEW:
            twin = (own[0] if own[1] == t else own[1], _NEW)
        if twin is not None:
            log_q = float(np.logaddexp(log_q, self._destinations(view, twin[0]).log_prob(twin[1])))
        return log_q - math.log(len(self._movable(view)))

    def _propose_reassign(self, view: _View, rng: np.random.Generator) -> Proposal:
        movable = self._movable(view)
        t = movable[int(rng.integers(len(movable)))]
        new, dest = self._move_tracklet(view, t, rng)
        log_f = self._kinds(view).log_prob("reassign") + self._log_reassign(view, t, dest)
        log_r = self._kinds(new).log_prob("reassign") + self._log_reassign(new, t, self._way_back(view, new, t))
        return Proposal("reassign", new, log_f, log_r)

    def _propose_to_clutter(self, view: _View, rng: np.random.Generator) -> Proposal:
        in_objects = [t for t, a in enumerate(view.assignment) if a != CLUTTER]
        t = in_objects[int(rng.integers(len(in_objects)))]
        assignment = list(view.assignment)
        assignment[t] = CLUTTER
        new = self._view_of(assignment)
        log_f = self._kinds(view).log_prob("to_clutter") - math.log(len(in_objects))
        log_r = self._kinds(new).log_prob("from_clutter") - math.log(len(new.state.clutter))
        log_r += self._destinations(new, t).log_prob(self._way_back(view, new, t))
        return Proposal("to_clutter", new, log_f, log_r)

    def _propose_from_clutter(self, view: _View, rng: np.random.Generator) -> Proposal:
        clutter = view.state.clutter
        t = clutter[int(rng.integers(len(clutter)))]
        new, dest = self._move_tracklet(view, t, rng)
        n_in_objects = new.state.n_tracklets - len(new.state.clutter)
        log_f = self._kinds(view).log_prob("from_clutter") - math.log(len(clutter))
        log_f += self._destinations(view, t).log_prob(dest)
        log_r = self._kinds(new).log_prob("to_clutter") - math.log(n_in_objects)
        return Proposal("from_clutter", new, log_f, log_r)

    def propose(self, view: _View, rng: np.random.Generator) -> Proposal | None:
        """A proposal from ``view``'s state, or None when no move is possible there."""
        kinds = self._kinds(view)
        if not kinds:
            return None
        return getattr(self, f"_propose_{kinds.draw(rng)}")(view, rng)

    # ---- the chain ---------------------------------------------------------------
    def _log_acceptance(
        self, state: Association, log_p: float, proposal: Proposal, rng: np.random.Generator
    ) -> Acceptance:
        """The verdict on ``proposal`` from ``state`` (whose log target is ``log_p``): the log of
        its acceptance probability, None when the screen rejected it (its target is then never
        computed), and whether it passed the screen only by the floor."""
        new = proposal.view.state
        log_q = proposal.log_q_reverse - proposal.log_q_forward
        if self.screen is None:
            return Acceptance(self.target(new) - log_p + log_q, False)
        log_floor = self._log_floor(state, new)
        log_first = self._first_stage(self.screen(state, new) + log_q, log_floor)
        if not (log_first >= 0.0 or math.log(rng.random()) < log_first):
            return Acceptance(None, False)
        at_floor = log_first <= log_floor
        log_p_new = self.target(new)
        if log_p_new == -math.inf:
            return Acceptance(-math.inf, at_floor)
        log_back = self._first_stage(self.screen(new, state) - log_q, self._log_floor(new, state))
        return Acceptance(log_p_new - log_p + log_q + log_back - log_first, at_floor)

    def _log_floor(self, state: Association, new: Association) -> float:
        """The screen's floor for the move ``state -> new``: the join floor when an object of
        ``new`` holds tracklets of two objects of ``state`` (or an object's and a clutter
        tracklet): such a move may close a loop, which the screen cannot see."""
        for group in new.groups:
            owners = {state.assignment[t] if state.assignment[t] != CLUTTER else (CLUTTER, t) for t in group}
            if len(owners) > 1:
                return self._log_join_floor
        return self._log_screen_floor

    def _first_stage(self, log_ratio: float, log_floor: float) -> float:
        """log alpha_1 of a screen log ratio: loosened by the margins, clamped to [log floor, 0]."""
        if math.isfinite(log_ratio):
            log_ratio += max(self.screen_margin, self.screen_relative_margin * abs(log_ratio))
        elif math.isnan(log_ratio):
            log_ratio = -math.inf
        return max(log_floor, min(0.0, log_ratio))

    def check_state(self, state: Association) -> None:
        if state.n_tracklets != len(self.labels):
            raise SamplerError(f"state has {state.n_tracklets} tracklets, the sampler {len(self.labels)}")
        state.validate(self.labels)
        if state.clutter and not self.allow_clutter:
            raise SamplerError("start state has clutter tracklets but clutter is disabled")

    def run(
        self,
        initial: Association,
        samples: int,
        burn_in: int,
        rng: np.random.Generator | int,
        progress: Progress | None = None,
        keep_trace: bool = True,
        on_move: Callable[[Association], None] | None = None,
    ) -> ChainResult:
        """Run ``samples`` steps; the states after the first ``burn_in`` steps are kept.

        ``progress(done, total)`` is called about 200 times; ``on_move(state)`` with the
        start state and after every accepted move (e.g. to warm-start the next solves
        from the chain's current state).
        """
        if not 0 <= burn_in < samples:
            raise SamplerError(f"need 0 <= burn_in < samples, got burn_in={burn_in}, samples={samples}")
        self.check_state(initial)
        rng = np.random.default_rng(rng) if not isinstance(rng, np.random.Generator) else rng
        view = self.view(initial)
        evaluations_before = self.target.evaluations
        log_p = self.target(initial)
        if not math.isfinite(log_p):
            raise SamplerError(f"log target of the start state is {log_p}")
        if on_move is not None:
            on_move(initial)
        best_state, best_log_p = initial, log_p
        stats = {kind: MoveStats() for kind in self.kind_weights}
        visited = {initial}
        counts: Counter[Association] = Counter()
        trace: list[Association] = []
        every = max(1, samples // 200)
        for step in range(samples):
            proposal = self.propose(view, rng)
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
                        on_move(view.state)
                    if log_p > best_log_p:
                        best_state, best_log_p = view.state, log_p
            if step >= burn_in:
                counts[view.state] += 1
                if keep_trace:
                    trace.append(view.state)
            if progress is not None and ((step + 1) % every == 0 or step + 1 == samples):
                progress(step + 1, samples)
        return ChainResult(
            counts=dict(counts),
            trace=tuple(trace),
            moves=stats,
            distinct_visited=len(visited),
            target_evaluations=self.target.evaluations - evaluations_before,
            final_state=view.state,
            best_state=best_state,
            best_log_target=best_log_p,
            samples=samples,
            burn_in=burn_in,
        )


@dataclass(frozen=True)
class ExactDistribution:
    """A target normalized by enumeration (for tests and tiny problems)."""

    states: tuple[Association, ...]
    probabilities: NDArray[np.float64] = field(repr=False)

    @classmethod
    def of(cls, states: Sequence[Association], log_target: LogTarget) -> ExactDistribution:
        logs = np.array([log_target(s) for s in states])
        return cls(tuple(states), np.exp(logs - _logsumexp(logs)))

    def total_variation(self, counts: dict[Association, int]) -> float:
        """TV distance between visit frequencies and this distribution (states outside count fully)."""
        total = sum(counts.values())
        index = {s: i for i, s in enumerate(self.states)}
        empirical = np.zeros(len(self.states))
        outside = 0.0
        for state, c in counts.items():
            if state in index:
                empirical[index[state]] += c / total
            else:
                outside += c / total
        return 0.5 * (float(np.abs(empirical - self.probabilities).sum()) + outside)
