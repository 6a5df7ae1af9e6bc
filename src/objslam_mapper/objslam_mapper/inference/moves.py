"""The proposal distribution over associations: which moves, and their exact probabilities.

The chain (:mod:`objslam_mapper.inference.chain`) walks over states J
(:mod:`objslam_mapper.inference.association`). Moves, in the spirit of Ranganathan (2008),
come in reverse pairs so every proposal has an exact Hastings ratio:

- ``merge`` two objects of one class  <->  ``split`` one object in two,
- ``reassign`` one tracklet to another object or to a new object (its own reverse),
- ``to_clutter`` a tracklet  <->  ``from_clutter`` a tracklet into an object or a new one,
- ``dissolve`` an object of two or more tracklets into clutter  <->  ``gather`` two or more
  clutter tracklets of one class into a new object: half the time (when the target says which
  clutter tracklets are one thing, :meth:`.target.AssociationTarget.clutter_things`) exactly
  the tracklets of one such thing, else a seed and others drawn by closeness,
- ``dissolve_pair``: two objects of one class (drawn as a merge draws them) into clutter
  <->  ``gather_pair``: clutter tracklets gathered as a gather does, split in two new objects
  as a split does.
- ``gather_into``: clutter tracklets gathered as a gather does, into an existing object of
  their class (drawn by closeness to the nearest of them)  <->  ``shed``: an object of three
  or more tracklets split as a split splits it, one side (by a coin, two or more
  tracklets) to clutter.

The dissolve and gather pair moves a group at once, which single moves cannot do when the missed-detection
term stands between: an object that is a poster seen in five tracklets loses hits (so pays
misses) with each tracklet taken from it, and each such tracklet pays the misses of the others
as a distractor. On ``clutter``, chains from the singleton and greedy starts held objects whose
whole move to clutter the target preferred by 300 to 2800 nats while every single tracklet's
move cost 40 to 390, and they stayed 8500 nats below the other chains after 6000 steps.

A real object and the same tracklets as one distractor differ by the Occam factor of the
distractor's broad priors, a few nats, so the chain must cross between them often; a gather
drawn by closeness rarely picks exactly a thing's tracklets among a dozen clutter tracklets
of its class nearby, and on ``clutter`` (seed 1) two chains held two real objects as
distractors for 6000 steps, 8 to 9 nats below the states with them as objects.

The pair moves take a thing held as two objects: on ``office`` seed 13, two chains (from
singletons and greedy) held a poster seen in two tracklets 1.1 m apart as two objects,
408 nats below the other chains' state with both tracklets one distractor, for 6000
steps: either tracklet alone to clutter cost 34 or 218 nats, and merging the two objects
first (then dissolving them) 158.

``gather_into`` takes a part of an object held as clutter: on ``office`` seed 15 two of four
chains held three red tracklets (5, 13 and 12 slices) of a real object as distractors, 305
nats below the state with them in the object, for 6000 steps: any one of them joining it
cost 124 to 313 nats, any two -122 to +107 (the screen never let those through), the three
as a new object 108.

- ``informed`` (its own reverse): one tracklet, drawn uniformly among all, sent to another
  object of its class, a new object or the clutter set, each destination weighted by
  sqrt(pi(J')/pi(J)) as a guide judges it (the screen: a locally balanced proposal, Zanella
  2020), mixed with a uniform share. The other moves find destinations by rough geometry,
  which misleads for short tracklets: on ``twins`` seed 15 a chain from the clutter start
  held two 3-slice red tracklets in an object 2 m and 3.5 m from their rough positions,
  17 nats below the other chains' state (one of them alone: +16 nats), and was never
  proposed the better object in 6000 steps. The reverse probability needs the guide from
  J', hence J' solved: it is computed only once the screen let the proposal through
  (:meth:`Proposal.reverse_log_q`).
- ``informed_group`` (its own reverse): a clutter thing (two or more tracklets,
  :meth:`.target.AssociationTarget.clutter_things`) gathered into a new object, or an object
  dissolved into clutter where its tracklets then are exactly one thing, each choice weighted
  as the informed move weighs destinations. ``gather`` draws a whole thing uniformly half
  the time: on ``clutter`` seed 13 a chain from singletons ended 6000 steps with a red object
  seen in five tracklets (263 slices) held as one distractor among 18 clutter things, the
  state with it gathered +8.6 nats (the screen said +10), which ``gather`` proposed about
  once in 1150 steps and this move proposes once in 18; that chain's state led the pooled
  map, which then lacked the object.

- ``balanced`` (its own reverse): one short tracklet (at most ``balanced_max_weight`` slices)
  sent to one of the nearest objects of its class, a new object or the clutter set, the
  tracklet and its destination drawn together among all such moves, each weighted as the
  informed move weighs destinations. The informed move draws its tracklet uniformly, so a
  short tracklet whose place the data leave open (two placements a few nats apart) is
  taken once in as many informed moves as there are tracklets, and chains switch between
  those placements rarely: on ``twins`` seed 11 four chains agreed on every identity, but a
  2-slice cyan tracklet sat in an object (3.9 nats below clutter) for runs of 200 to 500
  steps, and the log target's R-hat was 1.12. With the move the best move from either
  placement is drawn most of the time. A way back that lies beyond the nearest objects
  from J' (the leaving moved its object's centroid) does not exist: the move is refused.

A drawn move that cannot be made (a gather whose class has no object, a shed whose drawn
side is one tracklet) proposes nothing: the chain stays, which leaves every ratio exact.

The move kind is drawn among the kinds possible in the current state (nothing to split,
no clutter...) in proportion to configured weights, so P(m | J) depends on J. With a move m
taking J to J' and its reverse m' taking J' back, the acceptance is

    alpha = min(1, pi(J') P(m' | J') q_m'(J' -> J) / (pi(J) P(m | J) q_m(J -> J'))),

which gives detailed balance move pair by move pair, so the chain's stationary law is pi
(Green, 1995). Reverse proposal probabilities are always computed in the proposed state.

Proposals are geometry aware when rough tracklet positions are given: merges and
reassignments prefer nearby objects, splits separate tracklets that are far apart. Where
each tracklet's line of sight is given too, a tracklet's distance to an object is the
smaller of the distance to its rough position and to its line of sight: a short tracklet's
range (from its size) can be metres off while its bearing is not, and on ``office`` a
5-slice tracklet 3.3 m from its object's centroid, on that object's line of sight, was
proposed there about twice in 6000 steps; chains from other starts stayed 80 nats below.
The weights only depend on the state and the fixed tracklet data, and a floor keeps every
move possible, so the chain stays irreducible and the ratio exact.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from itertools import accumulate
from typing import Any

import numpy as np
from cachetools import LRUCache
from numpy.typing import ArrayLike, NDArray
from scipy.special import expit

from objslam_mapper.config import MoveConfig
from objslam_mapper.errors import MapperError
from objslam_mapper.inference.association import CLUTTER, Association
from objslam_mapper.inference.caches import lru, remember

MOVE_KINDS = (
    "merge",
    "split",
    "reassign",
    "to_clutter",
    "from_clutter",
    "dissolve",
    "gather",
    "dissolve_pair",
    "gather_pair",
    "gather_into",
    "shed",
    "informed",
    "informed_group",
    "balanced",
)
REVERSE_MOVE = {
    "merge": "split",
    "split": "merge",
    "reassign": "reassign",
    "to_clutter": "from_clutter",
    "from_clutter": "to_clutter",
    "dissolve": "gather",
    "gather": "dissolve",
    "dissolve_pair": "gather_pair",
    "gather_pair": "dissolve_pair",
    "gather_into": "shed",
    "shed": "gather_into",
    "informed": "informed",
    "informed_group": "informed_group",
    "balanced": "balanced",
}
CLUTTER_MOVES = (
    "to_clutter",
    "from_clutter",
    "dissolve",
    "gather",
    "dissolve_pair",
    "gather_pair",
    "gather_into",
    "shed",
    "informed_group",
)
_NEW = -2  # destination key: a new object
_GATHER, _DISSOLVE = "gather", "dissolve"  # informed group moves: a clutter thing to an object, or back
THING_GATHER_SHARE = 0.5  # of gathers: exactly one clutter thing's tracklets (module docstring)
# Of an informed move's destinations: the share drawn uniformly whatever the guide says, so a
# guide that errs (the screen at fixed poses cannot see a loop close) never makes a move
# impossible, and the reverse of a move the guide loved keeps a fair probability.
INFORMED_UNIFORM_SHARE = 0.1
_CACHE_SIZE = 20_000  # per-state proposal weights kept


def logsumexp(values: NDArray[np.float64]) -> float:
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


@dataclass
class StateView:
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
    things: list[tuple[int, ...]] | None = None  # clutter things of two or more tracklets
    informed: dict[int, _Choice] = field(default_factory=dict)  # per tracklet: informed destinations
    # Informed group moves: keys (_GATHER, thing) and (_DISSOLVE, members); None: not yet weighed.
    informed_groups: _Choice | None = None
    balanced: _Choice | None = None  # keys: every state a balanced move reaches
    balanced_reach: dict[Association, StateView] | None = None  # those states, not yet weighed

    @property
    def assignment(self) -> tuple[int, ...]:
        return self.state.assignment

    def others_in_object(self, t: int) -> list[int]:
        return [u for u in self.groups[self.assignment[t]] if u != t]


@dataclass(frozen=True)
class Proposal:
    kind: str
    view: StateView
    log_q_forward: float  # log P(kind | J) q(J -> J'), in the current state
    log_q_reverse: float  # log P(reverse kind | J') q(J' -> J), in the proposed state
    # An informed move's reverse needs the guide from J', which needs J' solved: computed on
    # demand (then ``log_q_reverse`` is NaN), after the screen let the proposal through.
    reverse_later: Callable[[], float] | None = None
    # Whether J' has a way back to J at all, known without solving J' (None: it has): a move
    # without one is refused before its target is computed.
    reversible: Callable[[], bool] | None = None

    def reverse_log_q(self) -> float:
        """log P(reverse kind | J') q(J' -> J)."""
        return self.reverse_later() if self.reverse_later is not None else self.log_q_reverse


class ProposalError(MapperError, ValueError):
    """Proposal settings or tracklets that cannot make a chain."""


# Which clutter tracklets of a state are one thing: a fixed function of the state.
ClutterThings = Callable[[Association], Sequence[tuple[int, ...]]]
# Approximate log pi(J') - log pi(J) of one move, a fixed function of the pair: what informed moves follow.
Guide = Callable[[Association, Association], float]


class Proposals:
    """The moves from a state and their probabilities, over a fixed set of tracklets.

    ``positions_xy_m`` (T, 2) are rough tracklet positions used only to shape proposals,
    ``tracklet_weights`` (T,) weigh them in object centroids (e.g. slices per tracklet),
    ``clutter_things`` says which clutter tracklets are one thing (gathered whole),
    ``guide`` what informed moves follow (without it they are not made).
    """

    def __init__(
        self,
        labels: Sequence[str],
        moves: MoveConfig | None = None,
        positions_xy_m: ArrayLike | None = None,
        tracklet_weights: ArrayLike | None = None,
        allow_clutter: bool = True,
        *,
        sight_lines: ArrayLike | None = None,
        clutter_things: ClutterThings | None = None,
        guide: Guide | None = None,
    ):
        self.labels = list(labels)
        self.clutter_things = clutter_things
        self.guide = guide
        self.moves = moves or MoveConfig()
        n = len(self.labels)
        self.positions = np.zeros((n, 2)) if positions_xy_m is None else np.asarray(positions_xy_m, float).reshape(n, 2)
        # (T, 4): camera x, y and the unit direction of each tracklet's line of sight (None: not used).
        self.sight_lines = None
        if sight_lines is not None:
            lines = np.asarray(sight_lines, float).reshape(n, 3)
            self.sight_lines = np.column_stack([lines[:, :2], np.cos(lines[:, 2]), np.sin(lines[:, 2])])
        self.weights = np.ones(n) if tracklet_weights is None else np.asarray(tracklet_weights, float).reshape(n)
        if np.any(self.weights <= 0.0):
            raise ProposalError("tracklet weights must be positive")
        self.allow_clutter = allow_clutter
        probs = {kind: float(getattr(self.moves, kind)) for kind in MOVE_KINDS}
        if not allow_clutter:
            probs.update(dict.fromkeys(CLUTTER_MOVES, 0.0))
        if guide is None:
            probs.update(informed=0.0, balanced=0.0)
        if guide is None or clutter_things is None:
            probs["informed_group"] = 0.0
        self.kind_weights = {k: p for k, p in probs.items() if p > 0.0}
        self._inv_two_scale2 = 0.5 / self.moves.distance_scale_m**2
        self._short = [t for t in range(n) if self.weights[t] <= self.moves.balanced_max_weight]
        self._views: LRUCache[Association, StateView] = lru(_CACHE_SIZE)
        self._bipartitions: dict[tuple[tuple[int, ...], bytes], float] = {}

    # ---- state views -------------------------------------------------------------
    def view(self, state: Association) -> StateView:
        cached = self._views.get(state)
        if cached is not None:
            return cached
        groups = state.groups
        centroids = np.zeros((len(groups), 2))
        for j, g in enumerate(groups):
            w = self.weights[list(g)]
            centroids[j] = w @ self.positions[list(g)] / w.sum()
        view = StateView(state, groups, [self.labels[g[0]] for g in groups], centroids)
        return remember(self._views, state, view)

    def _view_of(self, assignment: list[int]) -> StateView:
        return self.view(Association.of(assignment))

    # ---- proposal weights (shared by forward and reverse computations) -----------
    def _closeness(self, d2: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.moves.weight_floor + np.exp(-d2 * self._inv_two_scale2)

    def _merges(self, view: StateView) -> _Choice:
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

    def _kinds(self, view: StateView) -> _Choice:
        """The move kinds possible in this state, weighted as configured."""
        if view.kinds is None:
            possible = {
                "merge": len(self._merges(view)) > 0,
                "split": len(self._shared_objects(view)) > 0,
                "reassign": len(self._movable(view)) > 0,
                "to_clutter": len(view.state.clutter) < view.state.n_tracklets,
                "from_clutter": len(view.state.clutter) > 0,
                "dissolve": len(self._shared_objects(view)) > 0,
                "gather": len(self._gather_seeds(view)) > 0,
                "dissolve_pair": len(self._merges(view)) > 0,
                "gather_pair": len(self._gather_seeds(view)) > 0,
                "gather_into": len(self._gather_seeds(view)) > 0 and bool(view.groups),
                "shed": len(self._shedding(view)) > 0,
                "informed": True,  # some tracklet may have nowhere to go: that draw proposes nothing
                # A group move may have nothing to take (no object dissolves into one thing): the chain stays.
                # Shared objects first: finding the clutter things costs the target a pass.
                "informed_group": len(self._shared_objects(view)) > 0 or bool(self._things(view)),
                "balanced": True,  # there may be no short tracklet: that draw proposes nothing
            }
            kinds = [k for k in self.kind_weights if possible[k]]
            view.kinds = _Choice(kinds, [self.kind_weights[k] for k in kinds])
        return view.kinds

    @staticmethod
    def _shared_objects(view: StateView) -> list[int]:
        """Objects of two or more tracklets: what a split or a dissolve takes."""
        return [j for j, g in enumerate(view.groups) if len(g) > 1]

    def _movable(self, view: StateView) -> list[int]:
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

    def _destinations(self, view: StateView, t: int) -> _Choice:
        """Where tracklet t may go (object indices, or _NEW), weighted by closeness.

        Same for ``reassign`` (t in an object) and ``from_clutter`` (t in clutter): every
        other object of t's class, plus a new object unless t already is alone in one.
        """
        if t not in view.destinations:
            own = view.assignment[t]
            keys = [j for j, lab in enumerate(view.labels) if lab == self.labels[t] and j != own]
            weights = list(self._closeness(self._tracklet_distance2(t, view.centroids[keys])))
            if own == CLUTTER or len(view.groups[own]) > 1:
                keys.append(_NEW)
                weights.append(self.moves.new_object_weight)
            view.destinations[t] = _Choice(keys, weights)
        return view.destinations[t]

    def _tracklet_distance2(self, t: int, points_xy: NDArray[np.float64]) -> NDArray[np.float64]:
        """Squared distance of (K, 2) points to tracklet t: to its rough position, or to its line
        of sight (a ray: behind the camera, to the camera) where that is nearer."""
        d2 = ((points_xy - self.positions[t]) ** 2).sum(-1)
        if self.sight_lines is None:
            return d2
        origin, direction = self.sight_lines[t, :2], self.sight_lines[t, 2:]
        offset = points_xy - origin
        along = np.maximum(offset @ direction, 0.0)
        to_ray = ((offset - along[:, None] * direction) ** 2).sum(-1)
        return np.minimum(d2, to_ray)

    def tracklet_distance_m(self, a: Sequence[int], b: Sequence[int]) -> float:
        """The least distance between a tracklet of ``a`` and one of ``b``, each way as
        :meth:`_tracklet_distance2` measures it (rough positions, lines of sight)."""
        there = min(float(self._tracklet_distance2(t, self.positions[list(b)]).min()) for t in a)
        back = min(float(self._tracklet_distance2(t, self.positions[list(a)]).min()) for t in b)
        return math.sqrt(min(there, back))

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
            cached = math.log(2.0 / (n * (n - 1))) + logsumexp(log_side.sum(-1))
            if len(self._bipartitions) >= _CACHE_SIZE:
                self._bipartitions.clear()
            self._bipartitions[key] = cached
        return cached

    # ---- moves -------------------------------------------------------------------
    def _propose_merge(self, view: StateView, rng: np.random.Generator) -> Proposal:
        merges = self._merges(view)
        i, j = merges.draw(rng)
        new = self._view_of([i if a == j else a for a in view.assignment])
        merged = new.groups[new.assignment[view.groups[i][0]]]
        side_p = np.array([view.assignment[t] == i for t in merged])
        n_splittable = len(self._shared_objects(new))
        log_f = self._kinds(view).log_prob("merge") + merges.log_prob((i, j))
        log_r = self._kinds(new).log_prob("split") - math.log(n_splittable) + self._log_bipartition(merged, side_p)
        return Proposal("merge", new, log_f, log_r)

    def _draw_bipartition(self, members: Sequence[int], rng: np.random.Generator) -> NDArray[np.bool_]:
        """Two seeds drawn among ``members``, every other member sent to the nearer one's side
        (:meth:`_seed_side_probs`): which members are on the first seed's side."""
        n = len(members)
        a = int(rng.integers(n))
        b = int(rng.integers(n - 1))
        b += b >= a
        xy = self.positions[list(members)]
        p_a = self._seed_side_probs(xy, ((xy - xy[a]) ** 2).sum(-1), ((xy - xy[b]) ** 2).sum(-1))
        side_p = rng.random(n) < p_a
        side_p[a], side_p[b] = True, False
        return side_p

    @staticmethod
    def _pair_of(new: StateView, members: Sequence[int], side_p: NDArray[np.bool_]) -> tuple[int, int]:
        """The two objects of ``new`` that hold the two sides of ``members``."""
        first = int(np.flatnonzero(side_p)[0])
        second = int(np.flatnonzero(~side_p)[0])
        i, j = sorted((new.assignment[members[first]], new.assignment[members[second]]))
        return i, j

    def _propose_split(self, view: StateView, rng: np.random.Generator) -> Proposal:
        splittable = self._shared_objects(view)
        members = view.groups[splittable[int(rng.integers(len(splittable)))]]
        side_p = self._draw_bipartition(members, rng)
        assignment = list(view.assignment)
        for t, on_p in zip(members, side_p, strict=True):
            if not on_p:
                assignment[t] = len(view.groups)
        new = self._view_of(assignment)
        log_f = self._kinds(view).log_prob("split") - math.log(len(splittable))
        log_f += self._log_bipartition(members, side_p)
        log_r = self._kinds(new).log_prob("merge") + self._merges(new).log_prob(self._pair_of(new, members, side_p))
        return Proposal("split", new, log_f, log_r)

    def _move_tracklet(self, view: StateView, t: int, rng: np.random.Generator) -> tuple[StateView, int]:
        """Move t to a drawn destination: the new view and the destination key."""
        dest = self._destinations(view, t).draw(rng)
        return self._sent(view, t, dest), dest

    def _way_back(self, view: StateView, new: StateView, t: int) -> int:
        """The destination key, in ``new``, that returns t to where it was in ``view``."""
        if view.assignment[t] == CLUTTER:
            return CLUTTER
        rest = view.others_in_object(t)
        return new.assignment[rest[0]] if rest else _NEW

    @staticmethod
    def _twin_way(view: StateView, t: int, dest: int) -> tuple[int, int] | None:
        """The other (tracklet, destination) whose move reaches the state of t sent to ``dest``.

        Two tracklets t, u lead to the same state in two ways: merging singletons {t} and
        {u} (t joins u, or u joins t) and splitting {t, u} (t leaves, or u leaves). Every
        other move of one tracklet (to or from clutter among them) reaches its state in
        exactly one way: None.
        """
        own = view.assignment[t]
        if own == CLUTTER or dest == CLUTTER:
            return None
        if len(view.groups[own]) == 1 and dest != _NEW and len(view.groups[dest]) == 1:
            return view.groups[dest][0], own
        if len(view.groups[own]) == 2 and dest == _NEW:
            return view.others_in_object(t)[0], _NEW
        return None

    def _log_reassign(self, view: StateView, t: int, dest: int) -> float:
        """log q of the state reached by reassigning t to ``dest``, without the kind factor,
        summed over both ways where two lead there (:meth:`_twin_way`)."""
        log_q = self._destinations(view, t).log_prob(dest)
        twin = self._twin_way(view, t, dest)
        if twin is not None:
            log_q = float(np.logaddexp(log_q, self._destinations(view, twin[0]).log_prob(twin[1])))
        return log_q - math.log(len(self._movable(view)))

    def _propose_reassign(self, view: StateView, rng: np.random.Generator) -> Proposal:
        movable = self._movable(view)
        t = movable[int(rng.integers(len(movable)))]
        new, dest = self._move_tracklet(view, t, rng)
        log_f = self._kinds(view).log_prob("reassign") + self._log_reassign(view, t, dest)
        log_r = self._kinds(new).log_prob("reassign") + self._log_reassign(new, t, self._way_back(view, new, t))
        return Proposal("reassign", new, log_f, log_r)

    def _propose_to_clutter(self, view: StateView, rng: np.random.Generator) -> Proposal:
        in_objects = [t for t, a in enumerate(view.assignment) if a != CLUTTER]
        t = in_objects[int(rng.integers(len(in_objects)))]
        assignment = list(view.assignment)
        assignment[t] = CLUTTER
        new = self._view_of(assignment)
        log_f = self._kinds(view).log_prob("to_clutter") - math.log(len(in_objects))
        log_r = self._kinds(new).log_prob("from_clutter") - math.log(len(new.state.clutter))
        log_r += self._destinations(new, t).log_prob(self._way_back(view, new, t))
        return Proposal("to_clutter", new, log_f, log_r)

    def _propose_from_clutter(self, view: StateView, rng: np.random.Generator) -> Proposal:
        clutter = view.state.clutter
        t = clutter[int(rng.integers(len(clutter)))]
        new, dest = self._move_tracklet(view, t, rng)
        n_in_objects = new.state.n_tracklets - len(new.state.clutter)
        log_f = self._kinds(view).log_prob("from_clutter") - math.log(len(clutter))
        log_f += self._destinations(view, t).log_prob(dest)
        log_r = self._kinds(new).log_prob("to_clutter") - math.log(n_in_objects)
        return Proposal("from_clutter", new, log_f, log_r)

    def _gather_seeds(self, view: StateView) -> list[int]:
        """Clutter tracklets with another clutter tracklet of their class: where a gather starts."""
        per_class = Counter(self.labels[t] for t in view.state.clutter)
        return [t for t in view.state.clutter if per_class[self.labels[t]] > 1]

    def _gather_parts(self, view: StateView, a: int) -> tuple[list[int], _Choice, NDArray[np.float64]]:
        """From seed a: the other clutter tracklets of its class, the choice of the second
        (by closeness to a) and each one's probability of joining after that."""
        others = [t for t in view.state.clutter if t != a and self.labels[t] == self.labels[a]]
        d2 = self._tracklet_distance2(a, self.positions[others])
        second = _Choice(others, self._closeness(d2))
        joins = self.moves.split_randomness * 0.5 + (1.0 - self.moves.split_randomness) * np.exp(
            -d2 * self._inv_two_scale2
        )
        return others, second, joins

    def _log_gather(self, view: StateView, members: Sequence[int]) -> float:
        """log q of gathering exactly ``members`` (clutter tracklets of one class in ``view``),
        without the kind factor: summed over every ordered (seed, second) pair that gives it."""
        seeds = self._gather_seeds(view)
        chosen = set(members)
        terms = []
        for a in members:
            others, second, joins = self._gather_parts(view, a)
            inside = np.array([t in chosen for t in others])
            log_rest = np.where(inside, np.log(joins), np.log1p(-joins))
            for k, b in enumerate(others):
                if inside[k]:
                    terms.append(second.log_prob(b) + float(log_rest.sum() - log_rest[k]))
        drawn = logsumexp(np.array(terms)) - math.log(len(seeds))
        things = self._things(view)
        if not things:
            return drawn
        whole = math.log(THING_GATHER_SHARE / len(things)) if tuple(sorted(members)) in things else -math.inf
        return float(np.logaddexp(math.log1p(-THING_GATHER_SHARE) + drawn, whole))

    def _things(self, view: StateView) -> list[tuple[int, ...]]:
        """The state's clutter things of two or more tracklets (none without ``clutter_things``)."""
        if view.things is None:
            found = [] if self.clutter_things is None else self.clutter_things(view.state)
            view.things = [tuple(sorted(th)) for th in found if len(th) > 1]
        return view.things

    def _propose_dissolve(self, view: StateView, rng: np.random.Generator) -> Proposal:
        dissolvable = self._shared_objects(view)
        members = view.groups[dissolvable[int(rng.integers(len(dissolvable)))]]
        new = self._grouped(view, (_DISSOLVE, members))
        log_f = self._kinds(view).log_prob("dissolve") - math.log(len(dissolvable))
        log_r = self._kinds(new).log_prob("gather") + self._log_gather(new, members)
        return Proposal("dissolve", new, log_f, log_r)

    def _draw_gather(self, view: StateView, rng: np.random.Generator) -> list[int]:
        """Clutter tracklets of one class to gather: a whole thing, or a seed and others by closeness."""
        things = self._things(view)
        if things and rng.random() < THING_GATHER_SHARE:
            return list(things[int(rng.integers(len(things)))])
        seeds = self._gather_seeds(view)
        a = seeds[int(rng.integers(len(seeds)))]
        others, second, joins = self._gather_parts(view, a)
        b = second.draw(rng)
        drawn = rng.random(len(others)) < joins
        return sorted({a, b} | {t for t, on in zip(others, drawn, strict=True) if on})

    def _propose_gather(self, view: StateView, rng: np.random.Generator) -> Proposal:
        members = self._draw_gather(view, rng)
        new = self._grouped(view, (_GATHER, members))
        log_f = self._kinds(view).log_prob("gather") + self._log_gather(view, members)
        log_r = self._kinds(new).log_prob("dissolve") - math.log(len(self._shared_objects(new)))
        return Proposal("gather", new, log_f, log_r)

    def _propose_dissolve_pair(self, view: StateView, rng: np.random.Generator) -> Proposal:
        merges = self._merges(view)
        i, j = merges.draw(rng)
        members = sorted(view.groups[i] + view.groups[j])
        new = self._view_of([CLUTTER if a in (i, j) else a for a in view.assignment])
        side_p = np.array([view.assignment[t] == i for t in members])
        log_f = self._kinds(view).log_prob("dissolve_pair") + merges.log_prob((i, j))
        log_r = self._kinds(new).log_prob("gather_pair") + self._log_gather(new, members)
        log_r += self._log_bipartition(members, side_p)
        return Proposal("dissolve_pair", new, log_f, log_r)

    def _propose_gather_pair(self, view: StateView, rng: np.random.Generator) -> Proposal:
        members = self._draw_gather(view, rng)
        side_p = self._draw_bipartition(members, rng)
        assignment = list(view.assignment)
        for t, on_p in zip(members, side_p, strict=True):
            assignment[t] = len(view.groups) + int(not on_p)
        new = self._view_of(assignment)
        log_f = self._kinds(view).log_prob("gather_pair") + self._log_gather(view, members)
        log_f += self._log_bipartition(members, side_p)
        pair = self._pair_of(new, members, side_p)
        log_r = self._kinds(new).log_prob("dissolve_pair") + self._merges(new).log_prob(pair)
        return Proposal("gather_pair", new, log_f, log_r)

    @staticmethod
    def _shedding(view: StateView) -> list[int]:
        """Objects of three or more tracklets: what a shed takes (two or more go, one stays)."""
        return [j for j, g in enumerate(view.groups) if len(g) > 2]

    def _hosts(self, view: StateView, members: Sequence[int]) -> _Choice:
        """The objects that clutter tracklets ``members`` (of one class) may join, weighted by
        closeness to the nearest of them; empty when their class has no object."""
        keys = [j for j, lab in enumerate(view.labels) if lab == self.labels[members[0]]]
        if not keys:
            return _Choice([], [])
        d2 = np.min([self._tracklet_distance2(t, view.centroids[keys]) for t in members], axis=0)
        return _Choice(keys, self._closeness(d2))

    def _log_shed(self, view: StateView, j: int, leaving: Sequence[int]) -> float:
        """log q of object j shedding ``leaving`` to clutter, without the kind factor: the object,
        the bipartition {leaving, rest} and the coin that sends ``leaving``."""
        members = view.groups[j]
        side_p = np.array([t in leaving for t in members])
        return -math.log(len(self._shedding(view))) + self._log_bipartition(members, side_p) - math.log(2.0)

    def _propose_gather_into(self, view: StateView, rng: np.random.Generator) -> Proposal | None:
        members = self._draw_gather(view, rng)
        hosts = self._hosts(view, members)
        if not hosts:
            return None
        host = hosts.draw(rng)
        new = self._view_of([host if t in members else a for t, a in enumerate(view.assignment)])
        log_f = self._kinds(view).log_prob("gather_into") + self._log_gather(view, members) + hosts.log_prob(host)
        j = new.assignment[members[0]]
        log_r = self._kinds(new).log_prob("shed") + self._log_shed(new, j, members)
        return Proposal("gather_into", new, log_f, log_r)

    def _propose_shed(self, view: StateView, rng: np.random.Generator) -> Proposal | None:
        shedding = self._shedding(view)
        j = shedding[int(rng.integers(len(shedding)))]
        members = view.groups[j]
        side_p = self._draw_bipartition(members, rng)
        if rng.random() < 0.5:
            side_p = ~side_p
        leaving = [t for t, on in zip(members, side_p, strict=True) if on]
        if len(leaving) < 2:
            return None
        new = self._view_of([CLUTTER if t in leaving else a for t, a in enumerate(view.assignment)])
        log_f = self._kinds(view).log_prob("shed") + self._log_shed(view, j, leaving)
        staying = next(t for t in members if t not in leaving)
        log_r = self._kinds(new).log_prob("gather_into") + self._log_gather(new, leaving)
        log_r += self._hosts(new, leaving).log_prob(new.assignment[staying])
        return Proposal("shed", new, log_f, log_r)

    # ---- informed moves -------------------------------------------------------------
    def _informed(self, view: StateView, t: int) -> _Choice:
        """Where an informed move may send tracklet t (object indices, _NEW, CLUTTER), each
        destination weighted by sqrt(pi(J')/pi(J)) as the guide judges it (locally balanced,
        Zanella 2020), mixed with a uniform share (INFORMED_UNIFORM_SHARE)."""
        if t not in view.informed:
            keys = self._informed_keys(view, t)
            view.informed[t] = self._guided(view, keys, lambda dest: self._sent(view, t, dest))
        return view.informed[t]

    def _informed_keys(self, view: StateView, t: int) -> list[int]:
        """Where a move of tracklet t alone may send it: another object of its class, a new
        object (unless t is alone in its own), the clutter set (unless it is there)."""
        own = view.assignment[t]
        keys = [j for j, lab in enumerate(view.labels) if lab == self.labels[t] and j != own]
        if own == CLUTTER or len(view.groups[own]) > 1:
            keys.append(_NEW)
        if self.allow_clutter and own != CLUTTER:
            keys.append(CLUTTER)
        return keys

    def _balanced_keys(self, view: StateView, t: int) -> list[int]:
        """Where the balanced move may send short tracklet t: the ``balanced_objects`` objects of
        its class nearest to it (as the geometric moves measure), a new object, the clutter set."""
        keys = self._informed_keys(view, t)
        objects = [j for j in keys if j >= 0]
        if len(objects) > self.moves.balanced_objects:
            d2 = self._tracklet_distance2(t, view.centroids[objects])
            nearest = {objects[i] for i in np.argsort(d2, kind="stable")[: self.moves.balanced_objects]}
            keys = [j for j in keys if j < 0 or j in nearest]
        return keys

    def _balanced(self, view: StateView) -> _Choice:
        """Every state a short tracklet's move reaches from here (each tracklet of at most
        ``balanced_max_weight``, each destination of :meth:`_balanced_keys`), weighted as
        :meth:`_informed` weighs destinations: the locally balanced proposal over that whole
        neighbourhood (Zanella 2020), which picks the tracklet by the guide too. Keys are the
        states, so two ways to one state count once."""
        if view.balanced is None:
            reached = self._balanced_reach(view)
            view.balanced = self._guided(view, list(reached), reached.__getitem__)
        return view.balanced

    def _balanced_reach(self, view: StateView) -> dict[Association, StateView]:
        """The states of :meth:`_balanced`'s neighbourhood, in its order, without the guide's weights."""
        if view.balanced_reach is None:
            reached: dict[Association, StateView] = {}
            for t in self._short:
                for dest in self._balanced_keys(view, t):
                    new = self._sent(view, t, dest)
                    reached.setdefault(new.state, new)
            view.balanced_reach = reached
        return view.balanced_reach

    def _informed_groups(self, view: StateView) -> _Choice:
        """What an informed group move may do here, each weighted as :meth:`_informed` weighs
        destinations: gather a clutter thing (of two or more tracklets) into a new object, or
        dissolve an object into clutter where its tracklets are then exactly one thing (so the
        gather takes it back)."""
        if view.informed_groups is None:
            keys: list[tuple[str, tuple[int, ...]]] = [(_GATHER, thing) for thing in self._things(view)]
            for j in self._shared_objects(view):
                if view.groups[j] in self._things(self._grouped(view, (_DISSOLVE, view.groups[j]))):
                    keys.append((_DISSOLVE, view.groups[j]))
            view.informed_groups = self._guided(view, keys, lambda key: self._grouped(view, key))
        return view.informed_groups

    def _grouped(self, view: StateView, key: tuple[str, Sequence[int]]) -> StateView:
        """``view``'s state with the tracklets of ``key`` gathered into a new object (_GATHER)
        or dissolved into clutter (_DISSOLVE): what gather, dissolve and the informed group
        move make."""
        kind, members = key
        assignment = list(view.assignment)
        for t in members:
            assignment[t] = len(view.groups) if kind == _GATHER else CLUTTER
        return self._view_of(assignment)

    def _guided(self, view: StateView, keys: list[Any], reach: Callable[[Any], StateView]) -> _Choice:
        """``keys`` weighted by sqrt(pi(J')/pi(J)) as the guide judges the state each reaches,
        mixed with a uniform share (INFORMED_UNIFORM_SHARE); uniform where the guide condemns all."""
        probs = np.zeros(len(keys))
        if keys:
            assert self.guide is not None
            half = 0.5 * np.array([self.guide(view.state, reach(key).state) for key in keys])
            half = np.where(np.isnan(half), -np.inf, half)
            if np.isfinite(half.max()):
                probs = np.exp(half - half.max())
                probs *= (1.0 - INFORMED_UNIFORM_SHARE) / probs.sum()
                probs += INFORMED_UNIFORM_SHARE / len(keys)
            else:
                probs[:] = 1.0 / len(keys)
        return _Choice(keys, probs)

    def _propose_informed_group(self, view: StateView, rng: np.random.Generator) -> Proposal | None:
        choice = self._informed_groups(view)
        if not choice:
            return None
        key = choice.draw(rng)
        new = self._grouped(view, key)
        log_f = self._kinds(view).log_prob("informed_group") + choice.log_prob(key)
        back = (_DISSOLVE if key[0] == _GATHER else _GATHER, key[1])

        def reverse() -> float:
            return self._kinds(new).log_prob("informed_group") + self._informed_groups(new).log_prob(back)

        return Proposal("informed_group", new, log_f, math.nan, reverse)

    def _sent(self, view: StateView, t: int, dest: int) -> StateView:
        """``view``'s state with t sent to ``dest`` (an object index, _NEW or CLUTTER)."""
        assignment = list(view.assignment)
        assignment[t] = len(view.groups) if dest == _NEW else dest
        return self._view_of(assignment)

    def _log_informed(self, view: StateView, t: int, dest: int) -> float:
        """log q of the state reached by sending t to ``dest``, without the kind factor: the
        uniform draw of t among all tracklets and its destination, summed over both ways where
        two lead there (:meth:`_twin_way`)."""
        log_q = self._informed(view, t).log_prob(dest)
        twin = self._twin_way(view, t, dest)
        if twin is not None:
            log_q = float(np.logaddexp(log_q, self._informed(view, twin[0]).log_prob(twin[1])))
        return log_q - math.log(len(self.labels))

    def _propose_informed(self, view: StateView, rng: np.random.Generator) -> Proposal | None:
        t = int(rng.integers(len(self.labels)))
        choice = self._informed(view, t)
        if not choice:
            return None
        dest = choice.draw(rng)
        new = self._sent(view, t, dest)
        log_f = self._kinds(view).log_prob("informed") + self._log_informed(view, t, dest)
        back = self._way_back(view, new, t)

        def reverse() -> float:
            return self._kinds(new).log_prob("informed") + self._log_informed(new, t, back)

        return Proposal("informed", new, log_f, math.nan, reverse)

    def _propose_balanced(self, view: StateView, rng: np.random.Generator) -> Proposal | None:
        choice = self._balanced(view)
        if not choice:
            return None
        state = choice.draw(rng)
        new = self.view(state)
        log_f = self._kinds(view).log_prob("balanced") + choice.log_prob(state)

        def reversible() -> bool:
            # The way back can lie beyond the nearest objects from J' (the tracklet's leaving
            # moved its object's centroid): then there is none, and the move is refused.
            return view.state in self._balanced_reach(new)

        def reverse() -> float:
            if not reversible():
                return -math.inf
            return self._kinds(new).log_prob("balanced") + self._balanced(new).log_prob(view.state)

        return Proposal("balanced", new, log_f, math.nan, reverse, reversible)

    def propose(self, view: StateView, rng: np.random.Generator) -> Proposal | None:
        """A proposal from ``view``'s state, or None when no move is possible there or the
        drawn one cannot be made (the chain then stays)."""
        kinds = self._kinds(view)
        if not kinds:
            return None
        return getattr(self, f"_propose_{kinds.draw(rng)}")(view, rng)
