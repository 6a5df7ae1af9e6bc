"""The screen of proposals: the first stage of delayed acceptance, at fixed poses.

Most proposals are hopeless (a few percent are accepted), so the chain screens them first
(delayed acceptance, :mod:`objslam_mapper.inference.chain`) with :class:`ProposalScreen`:
with the poses fixed at the current state's MAP the graph splits into one small problem
per object or distractor (:mod:`objslam_mapper.graph.conditional_evidence`), and the difference
of two associations one move apart is the conditional evidence of the few groups the
move changes (each solved from every group that holds some of its slices, the best
kept), plus the exact clutter terms, and the no-overlap and missed-detection
terms of the changed groups at the fixed-pose objects. The screen leaves out how a move
changes what the kept groups hide of each other (where two things stand at one place one
hides the other, and taking the nearer away makes the other pay its misses). Counting that
as well made the screen exact at fixed poses, and the chain then found what the chain
without a screen (``sampler.screen.enabled: false``) finds too on ``twins``: a duplicate beside a
cyan object, which the target prefers to the merged object because the pair hides an
object behind them in more of the images it is missed in. That is a fault of the
detection term (docs/method.md), not of the screen; until it is mended the screen keeps
its blind spot. Only a proposal that passes that screen costs a graph solve, and the second
stage corrects for the screen, so the chain's target is still exactly ``log P(J | Z)``
(the screen is loosened by ``sampler.screen.margin_nats`` and ``relative_margin``
and floored at ``floor``, at ``join_floor`` for moves that join two
objects' tracklets: a loop closure needs the poses to move, which a screen at fixed poses
cannot see). What stays approximate is what was already: each state's value is its
solve's, cached, and the screen's reference poses are those of a state's first solve
(cached for the last 1024 states; an evicted one is re-solved from the chain's current
state, which agrees to the solver's tolerance).
"""

from __future__ import annotations

import time

import numpy as np
from cachetools import FIFOCache, LRUCache
from numpy.typing import NDArray

from objslam_mapper.graph.conditional_evidence import ObjectEvidence, object_evidence
from objslam_mapper.graph.initialization import initial_object
from objslam_mapper.inference.association import Association
from objslam_mapper.inference.caches import fifo, lru, remember
from objslam_mapper.inference.detection import (
    MissTerms,
    Sight,
    count,
    sight,
    table_sight,
    visible,
)
from objslam_mapper.inference.exclusion import near_pairs, no_overlap_log_probability
from objslam_mapper.inference.target import OBJECT, AssociationTarget, GraphGroup, estimates

REFERENCE_CACHE_SIZE = 1024
OBJECT_EVIDENCE_CACHE_SIZE = 100_000


class ProposalScreen:
    """Approximate ``log P(new|Z) - log P(state|Z)`` of a move, poses fixed at ``state``'s MAP; callable.

    ``iterations`` bounds each conditional object solve. The work is counted in the target's.
    """

    def __init__(self, target: AssociationTarget, iterations: int = 20):
        self.target = target
        self.iterations = iterations
        # Per state: the poses and groups its screens are conditioned on (its MAP when first solved).
        self._references: LRUCache[Association, tuple[NDArray, NDArray, NDArray]] = lru(REFERENCE_CACHE_SIZE)
        self._group_evidence: FIFOCache[tuple[Association, GraphGroup], tuple[float, NDArray]] = fifo(
            OBJECT_EVIDENCE_CACHE_SIZE
        )

    def _reference(self, state: Association) -> tuple[NDArray, NDArray, NDArray]:
        """(poses (N, 3), graph group of each measurement (M,), groups (G, 5)) of ``state``'s MAP."""
        cached = self._references.get(state)
        if cached is not None:
            return cached
        if not self.target.graph_groups(state):
            owners = np.full(self.target.problem.measurement_count, -1, dtype=np.int64)
            reference = (np.asarray(self.target.problem.odometry_poses), owners, np.zeros((0, 5)))
        else:
            sol = self.target.solution(state)
            reference = (np.asarray(sol.map_T_base), sol.object_of_measurement, estimates(sol))
        return remember(self._references, state, reference)

    def _conditional(self, state: Association, group: GraphGroup) -> tuple[float, NDArray[np.float64]]:
        """(log e(group), its object) with the poses fixed at ``state``'s MAP (conditional_evidence)."""
        key = (state, group)
        cached = self._group_evidence.get(key)
        if cached is not None:
            return cached
        poses, owners, objects = self._reference(state)
        members = self.target.measurements(group)
        row = self.target.prior_row(group, members)
        owned = owners[members]
        counts = np.bincount(owned[owned >= 0], minlength=len(objects))
        # From every group that holds some of its slices, most first (its own slices' start
        # where none converges): a group that joins things metres apart has an optimum at
        # each, and from the wrong one its other slices lie beyond their caps (converged, and
        # thousands of nats low). From the majority's start alone, the screen judged a
        # tracklet's move to clutter -2992 nats where the target gained 579, and a chain on
        # `loop` stayed in that state. A start within the diameter of an optimum already
        # found lies in its basin and is skipped: joining looks at one thing costs one solve.
        starts: list[NDArray[np.float64] | None] = [objects[k] for k in np.argsort(-counts, kind="stable") if counts[k]]
        starts.append(None)
        found: list[ObjectEvidence] = []  # the optima (finite evidence) reached so far
        evidence: ObjectEvidence | None = None
        for start in starts:
            if start is None:
                if found:
                    break
                start = initial_object(self.target.problem, members, poses)
            if any(np.hypot(*(start[:2] - f.object_state[:2])) < f.object_state[3] for f in found):
                continue
            self.target.work.object_solves += 1
            started = time.perf_counter()
            evidence = object_evidence(
                self.target.problem, poses, members, start, max_iterations=self.iterations, prior=row
            )
            self.target.work.screen_seconds += time.perf_counter() - started
            if np.isfinite(evidence.log_evidence):
                found.append(evidence)
        # The last start always runs when nothing was found: evidence is set.
        best = max(found, key=lambda f: f.log_evidence, default=evidence)
        assert best is not None
        return remember(self._group_evidence, key, (best.log_evidence, best.object_state))

    def _screen_no_overlap(self, state: Association, new: Association) -> float:
        """Change of the no-overlap term from ``state`` to ``new``, objects at the screen's
        fixed-pose estimates (the reference's where ``new`` keeps an object): only pairs
        with an object the move changes differ."""
        poses, _, objects = self._reference(state)
        kept = {g: objects[k] for k, g in enumerate(state.groups)}
        old, fresh = set(state.groups), set(new.groups)

        def term(assoc: Association, changed: set[tuple[int, ...]]) -> float:
            if assoc.n_objects < 2 or not changed:
                return 0.0
            groups = [(OBJECT, g) for g in assoc.groups]
            states = np.array([kept[g[1]] if g[1] in kept else self._conditional(state, g)[1] for g in groups])
            i, j = near_pairs(states)
            involved = np.array([groups[a][1] in changed or groups[b][1] in changed for a, b in zip(i, j, strict=True)])
            if not involved.any():
                return 0.0
            pairs = (i[involved], j[involved])
            needed = set(pairs[0].tolist()) | set(pairs[1].tolist())
            members = [self.target.measurements(g) if k in needed else None for k, g in enumerate(groups)]
            rows = [self.target.prior_row(g, m) if m is not None else -1 for g, m in zip(groups, members, strict=True)]
            return no_overlap_log_probability(
                self.target.problem, poses, states, members, rows, self.target.options.exclusion_floor_nats, pairs=pairs
            )

        return term(new, fresh - old) - term(state, old - fresh)

    def _screen_detection(
        self, state: Association, old_groups: list[GraphGroup], new_groups: list[GraphGroup]
    ) -> float:
        """Change of the detection term from ``state`` (graph groups ``old_groups``) to the
        association of ``new_groups`` over the groups the move changes, and over the kept
        distractors when the move adds or takes one (fragments of one thing: detection.share),
        at the screen's fixed poses and estimates (how the move changes what hides the others
        is left to the target: see the module docstring)."""
        target = self.target
        poses, _, estimates = self._reference(state)
        seen = target.sightings(state, poses, estimates)
        old_set, new_set = set(old_groups), set(new_groups)
        lost = [k for k, g in enumerate(old_groups) if g not in new_set]
        kept = [k for k, g in enumerate(old_groups) if g in new_set]
        gained = [g for g in new_groups if g not in old_set]
        shown = np.zeros((len(poses), 0), dtype=bool)
        fresh = Sight.none_of(len(poses))
        gained_members = [target.measurements(g) for g in gained]
        gained_estimates = np.array([self._conditional(state, g)[1] for g in gained]).reshape(-1, 5)
        gained_kin = target.kin(gained)
        old_kin = seen.kin  # the kin of the state's groups, as its sightings were made with
        touches_kin = bool((old_kin[lost] >= 0).any() or (gained_kin >= 0).any())
        recount = [k for k in kept if old_kin[k] >= 0] if touches_kin else []
        before = seen.terms(target.detection, lost + recount)
        if gained:
            fresh = sight(target.problem, poses, gained_estimates, target.detection, target.view)
            fresh_tables = table_sight(
                target.problem, poses, gained_estimates, target.on_table(gained, gained_members), target.detection
            )
            shown = visible(fresh, Sight.join([seen.occluders(kept), fresh, fresh_tables]), target.detection)
        recounted = [target.measurements(old_groups[k]) for k in recount]
        kin = np.concatenate([old_kin[recount], gained_kin])
        counted = Sight.join([seen.sight.columns(recount), fresh])
        counts = count(
            target.problem,
            recounted + gained_members,
            np.hstack([seen.visible[:, recount], shown]),
            counted,
            kin,
        )
        after = MissTerms.of(
            counts.should, counts.hit, kin >= 0, target.detection, width_rad=counted.width, charged=counts.charged
        )
        return (after - before).log_likelihood(target.detection)

    def __call__(self, state: Association, new: Association) -> float:
        """Approximate ``log P(new|Z) - log P(state|Z)``: poses fixed at ``state``'s MAP.

        The graph groups (objects and distractors) both associations share cancel, so only
        those the move changes are solved (5 variables each); the clutter terms outside
        the graph are the exact ones of the target, the no-overlap term is evaluated at the
        fixed-pose objects. A fixed function of the pair (cached), as delayed acceptance needs.
        """
        self.target.work.screens += 1
        old_list, new_list = self.target.graph_groups(state), self.target.graph_groups(new)
        old_groups, new_groups = set(old_list), set(new_list)
        gained = sum(self._conditional(state, g)[0] for g in new_groups - old_groups)
        lost = sum(self._conditional(state, g)[0] for g in old_groups - new_groups)
        value = gained - lost if np.isfinite(lost) else -np.inf
        value += self.target.clutter_log_likelihood(new) - self.target.clutter_log_likelihood(state)
        if self.target.options.exclusion and np.isfinite(value):
            value += self._screen_no_overlap(state, new)
        if self.target.detection.enabled and np.isfinite(value):
            value += self._screen_detection(state, old_list, new_list)
        return float(value)
