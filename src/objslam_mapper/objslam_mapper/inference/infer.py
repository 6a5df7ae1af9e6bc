r"""Unknown data association end to end: tracklets -> MH over associations -> Algorithm 1.

The target of the chain (paper eq. 25, extended with clutter and solid objects) is, up to
a constant,

    log P(J | Z) = log P(Z | J) + sum over clutter tracklets tau of log w(tau)
                   + log P(no two objects of J overlap | J, Z) + log P(J),

where ``log P(Z | J)`` is the Laplace evidence of J's factor graph
(:func:`objslam_mapper.graph.solver.solve`, every Gaussian normalizer included): its objects
(one per group of tracklets, with its class priors) and its distractors (each clutter
tracklet that a static thing of unknown shape explains, with broad priors;
:mod:`objslam_mapper.inference.clutter`). ``log w(tau)`` is the rest of a clutter tracklet's
likelihood: the distractor component's weight, or, for a tracklet of independent false
alarms (outside the graph), that weight times its uniform density. Each slice's factor
is the max-mixture of :mod:`objslam_mapper.model.outliers` (a merged or cut blob costs a capped
amount). The no-overlap term is :mod:`objslam_mapper.inference.exclusion` (real objects do not
share floor space; without it a blob merged with a neighbour becomes a duplicate beside
the real object), and ``P(J)`` is uniform, as in the paper. Isolated detections dropped
by the tracklet chaining are in no J.

The chain starts from :func:`initial_association`: tracklets of a class seen close to
each other join one object, except the tracklets that, alone with the odometry, the
target prefers as clutter (``initial_clutter``); then :func:`clear_start_objects` moves to
clutter each start object the target prefers there as a whole. A flat patch on the floor
seen in several tracklets, merged into one object at the start, fits its class only with
a height tens of prior stddevs off, yet taking it apart one tracklet at a time first
loses, so a chain started there stays; the start clearing also gives the solves a
trajectory not bent by posters fitted as objects. Then :func:`recall_start_clutter` tries
each tracklet left in clutter in its nearest object, and the clearing runs once more.
Only the start state changes: the target, and so the chain's exactness, do not.

Each solve is warm-started from the chain's current state (a proposal differs from it by
one move) and capped at ``proposal_max_iterations`` per phase of the outlier caps: a
hopeless proposal (a merge of objects metres apart) then costs a few iterations and is
rejected on the evidence at its last iterate, which is below its optimum. Values are
cached per state, so the chain sees one fixed target whatever path led to a state.

Most proposals are hopeless (a few percent are accepted), so the chain screens them first
(delayed acceptance, :mod:`objslam_mapper.inference.sampler`) with :meth:`AssociationTarget.screen`:
with the poses fixed at the current state's MAP the graph splits into one small problem
per object or distractor (:mod:`objslam_mapper.graph.conditional_evidence`), and the difference
of two associations one move apart is the conditional evidence of the few groups the
move changes, plus the exact clutter terms, and the no-overlap and missed-detection
terms of the changed groups at the fixed-pose objects. The screen leaves out how a move
changes what the kept groups hide of each other (where two things stand at one place one
hides the other, and taking the nearer away makes the other pay its misses). Counting that
as well made the screen exact at fixed poses, and the chain then found what the chain
without a screen (``screen_proposals: false``) finds too on ``twins``: a duplicate beside a
cyan object, which the target prefers to the merged object because the pair hides an
object behind them in more of the images it is missed in. That is a fault of the
detection term (README, "Speed"), not of the screen; until it is mended the screen keeps
its blind spot. Only a proposal that passes that screen costs a graph solve, and the second
stage corrects for the screen, so the chain's target is still exactly ``log P(J | Z)``
above (the screen is loosened by ``screen_margin_nats`` and ``screen_relative_margin``
and floored at ``screen_floor``, at ``screen_join_floor`` for moves that join two
objects' tracklets: a loop closure needs the poses to move, which a screen at fixed poses
cannot see). What stays approximate is what was already: each state's value is its
solve's, cached, and the screen's reference poses are those of a state's first solve
(cached for the last 1024 states; an evicted one is re-solved from the chain's current
state, which agrees to the solver's tolerance).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import OrderedDict
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from objslam_common.catalog import Catalog
from objslam_common.config import setting
from objslam_common.records import ImageSlices, OdometrySample

from objslam_mapper.config import GraphConfig
from objslam_mapper.graph.backends import solve_with_backend
from objslam_mapper.graph.conditional_evidence import object_evidence
from objslam_mapper.graph.initialization import initial_object
from objslam_mapper.graph.problem import GraphProblem, build_problem
from objslam_mapper.graph.solver import GraphSolution
from objslam_mapper.inference.algorithm1 import SampleObject, SampleSummary, build_from_samples
from objslam_mapper.inference.association import CLUTTER, Association
from objslam_mapper.inference.clutter import DISTRACTOR, ClutterConfig, ClutterModel, Component
from objslam_mapper.inference.detection import (
    DetectionConfig,
    Sight,
    Sightings,
    hit_matrix,
    miss_count_log_likelihood,
    sight,
    sightings,
    table_sight,
    view_top_elevation,
    visible,
)
from objslam_mapper.inference.exclusion import near_pairs, no_overlap_log_probability
from objslam_mapper.inference.sampler import MetropolisHastings, MoveConfig
from objslam_mapper.inference.tracklets import Tracklet, TrackletConfig, tracklets_of_problem
from objslam_mapper.map_file import BuiltMap

logger = logging.getLogger(__name__)

# The graph of an association without objects is the odometry chain alone: its MAP is the
# odometry (chi2 = 0), and as the map from poses to (first-pose residual, increments) has a
# unit Jacobian determinant, the Laplace evidence -cost + sum of normalizers + d/2 log 2 pi
# - 1/2 log|Lambda| is exactly 0. Computed here rather than solved: such a state needs no graph.
NO_OBJECT_LOG_EVIDENCE = 0.0

_REFERENCE_CACHE_SIZE = 1024
_OBJECT_EVIDENCE_CACHE_SIZE = 100_000

PhaseProgress = Callable[[str, int, int], None]  # phase ("tracklets", "sampling", "mapping"), done, total


@dataclass(frozen=True)
class SamplerConfig:
    """The association sampler and map building (the mapper's ``sampler.*`` parameters)."""

    samples: int = setting(6000, "MH steps in all, burn-in included (paper: 6000)", minimum=1)
    burn_in: int = setting(2500, "first steps left out of the map (paper: 2500)", minimum=0)
    seed: int = setting(1, "random seed of the chain (same seed, same inputs: same map)", minimum=0)
    moves: MoveConfig = setting(MoveConfig(), "proposal moves")
    tracklets: TrackletConfig = setting(TrackletConfig(), "chaining slices into tracklets")
    clutter: ClutterConfig = setting(ClutterConfig(), "false-alarm model")
    spurious_location_stddev_m: float = setting(
        0.30, "an object whose horizontal location stddev (largest axis) exceeds this is spurious (m)", minimum=0.0
    )
    existence_threshold: float = setting(
        0.5, "identities with P(ID|Z) above this make the map", minimum=0.0, maximum=1.0
    )
    report_min_fraction: float = setting(
        0.05, "other identities held by at least this fraction of samples are reported as rejected", minimum=0.0
    )
    identity_overlap: float = setting(
        0.8,
        "two sample objects are one identity when each holds at least this share of the other's measurements "
        "(1: the paper's exact identity)",
        minimum=0.501,
        maximum=1.0,
    )
    initial_merge_distance_m: float = setting(
        0.6, "start state: a tracklet joins the nearest same-class object within this distance (m)", minimum=0.0
    )
    exclusion: bool = setting(
        True, "objects are solid: an association pays the posterior probability that two of its objects overlap"
    )
    exclusion_floor_nats: float = setting(
        -60.0,
        "... each pair at most this much: with exp(floor) the prior does not hold (one object on another)",
        maximum=0.0,
    )
    detection: DetectionConfig = setting(DetectionConfig(), "detection probability and visibility of objects")
    initial_clutter: bool = setting(
        True,
        "start state: a tracklet the target prefers as clutter over a lone object starts in clutter, then start "
        "objects the target prefers as clutter go there, each clutter tracklet is tried once in its nearest object, "
        "and the objects are tried as clutter again (false: the plain nearest-neighbour start)",
    )
    proposal_max_iterations: int = setting(15, "most solver linearizations per proposed association", minimum=1)
    solution_cache_size: int = setting(256, "graph solutions kept for warm starts and map building", minimum=1)
    screen_proposals: bool = setting(
        True, "delayed acceptance: screen proposals on the moved objects alone (poses fixed) before a graph solve"
    )
    screen_margin_nats: float = setting(
        5.0, "the screen lets through proposals it judges worse by up to this much (nats)", minimum=0.0
    )
    screen_relative_margin: float = setting(
        0.1, "... or by up to this fraction of its log ratio, whichever is larger", minimum=0.0
    )
    screen_floor: float = setting(
        0.01,
        "a proposal the screen condemns still gets a graph solve with this probability",
        minimum=1e-6,
        maximum=1.0,
    )
    screen_join_floor: float = setting(
        0.1,
        "... this one when it joins tracklets of two objects (or of clutter and an object): loop closures "
        "need the poses to move, which the screen cannot see",
        minimum=1e-6,
        maximum=1.0,
    )

    def __post_init__(self) -> None:
        if self.burn_in >= self.samples:
            raise ValueError(f"burn_in ({self.burn_in}) must be smaller than samples ({self.samples})")


# A group of an association's factor graph: an object (its tracklets) or a distractor (one clutter tracklet).
GraphGroup = tuple[str, tuple[int, ...]]
_OBJECT = "object"


def _estimates(solution: GraphSolution, count: int | None = None) -> NDArray[np.float64]:
    """(G, 5) (x, y, z_base, diameter, height) of the solution's first ``count`` groups (default all)."""
    return np.array([np.concatenate([o.location_m, o.size_m]) for o in solution.objects[:count]]).reshape(-1, 5)


class AssociationTarget:
    """``log P(J|Z)`` of associations of ``tracklets`` (see the module docstring); callable."""

    def __init__(
        self,
        problem: GraphProblem,
        tracklets: Sequence[Tracklet],
        clutter: ClutterConfig,
        *,
        max_iterations: int | None = None,
        cache_size: int = 256,
        screen_iterations: int = 20,
        exclusion: bool = True,
        detection: DetectionConfig | None = None,
        exclusion_floor_nats: float = -60.0,
    ):
        # The target takes every upper edge as measured, those cut by the top of the view too;
        # the map's estimates (summary) take those as the lower bounds they are. Scored
        # one-sided, an upper edge no longer tells a cyan poster high on a wall from a cyan
        # object, nor one object from two beside each other: on the clutter and twins bags the
        # target then preferred those states (README, Results).
        censored_top = problem.measurement_censored_top
        problem = dataclasses.replace(problem, measurement_censored_top=np.zeros_like(censored_top))
        self.clutter = ClutterModel(problem, clutter)
        self.exclusion = exclusion
        self.exclusion_floor = exclusion_floor_nats
        self.detection = detection or DetectionConfig(enabled=False)
        self.view_top_rad = view_top_elevation(problem, self.detection)
        self.problem = self.clutter.problem  # with the distractors' prior rows
        self.estimation_problem = dataclasses.replace(self.problem, measurement_censored_top=censored_top)
        self.tracklets = list(tracklets)
        self.max_iterations = max_iterations
        self.cache_size = cache_size
        self.screen_iterations = screen_iterations
        self._members = [np.asarray(t.measurement_indices, dtype=np.int64) for t in self.tracklets]
        self._solutions: OrderedDict[Association, GraphSolution] = OrderedDict()
        self._anchor: GraphSolution | None = None
        self._components: dict[int, Component] = {}
        # Per state: the poses and groups its screens are conditioned on (its MAP when first solved).
        self._references: OrderedDict[Association, tuple[NDArray, NDArray, NDArray]] = OrderedDict()
        # Per state: how its graph groups appear, and the poses that was computed at.
        self._sights: OrderedDict[Association, tuple[NDArray, Sightings]] = OrderedDict()
        self._group_evidence: OrderedDict[tuple[Association, GraphGroup], tuple[float, NDArray]] = OrderedDict()
        self.solves = 0
        self.solve_seconds = 0.0
        self.screens = 0
        self.screen_seconds = 0.0  # conditional object solves only
        self.marginal_solves = 0
        self.marginal_seconds = 0.0
        self.object_solves = 0
        self.clutter_seconds = 0.0
        self.clutter_solves = 0  # one distractor solve per tracklet, ever: it does not depend on J

    # ---- the graph of an association -----------------------------------------------------
    def component(self, t: int) -> Component:
        """How tracklet t is explained when it is clutter (one distractor solve, remembered)."""
        if t not in self._components:
            start = time.perf_counter()
            self._components[t] = self.clutter.component(self._members[t])
            self.clutter_solves += 1
            self.clutter_seconds += time.perf_counter() - start
        return self._components[t]

    def graph_groups(self, state: Association) -> list[GraphGroup]:
        """The groups of ``state``'s factor graph: its objects in order, then its distractors."""
        groups: list[GraphGroup] = [(_OBJECT, g) for g in state.groups]
        groups += [(DISTRACTOR, (t,)) for t in state.clutter if self.component(t).kind == DISTRACTOR]
        return groups

    def _measurements(self, group: GraphGroup) -> NDArray[np.int64]:
        return np.sort(np.concatenate([self._members[t] for t in group[1]]))

    def _prior_row(self, group: GraphGroup, members: NDArray[np.int64]) -> int:
        if group[0] == DISTRACTOR:
            return self.clutter.distractor_row(int(members[0]))
        return int(self.problem.measurement_label[members[0]])

    def _on_table(self, groups: Sequence[GraphGroup], members: Sequence[NDArray[np.int64]]) -> NDArray[np.bool_]:
        """Which groups stand on a table: objects of a class whose base is above the floor
        (DESIGN.md); distractors are posters and patches, which stand on nothing."""
        return np.array(
            [
                g[0] == _OBJECT and self.problem.prior_mean[self._prior_row(g, m), 2] > 0.0
                for g, m in zip(groups, members, strict=True)
            ],
            dtype=bool,
        )

    def groups(self, state: Association) -> list[NDArray[np.int64]]:
        """Measurement indices of each object of ``state``, in its object order."""
        return [self._measurements((_OBJECT, g)) for g in state.groups]

    def _graph(self, state: Association) -> tuple[list[NDArray[np.int64]], list[int]]:
        """Measurements and prior rows of every group of ``state``'s graph."""
        groups = self.graph_groups(state)
        members = [self._measurements(g) for g in groups]
        rows = [self._prior_row(g, m) for g, m in zip(groups, members, strict=True)]
        return members, rows

    def tracklet_clutter_log_likelihood(self, t: int) -> float:
        """log L_clutter of tracklet t with the odometry alone (its component's)."""
        return self.component(t).alone_log_likelihood

    def prefers_clutter(self, t: int) -> bool:
        """Whether tracklet t alone, with the odometry, is likelier clutter than an object of its class.

        That is ``log P(J|Z)`` of the state with t its own object and every other tracklet
        clutter against the state with all of them clutter, both with the odometry alone
        (the other tracklets' terms cancel), so neither gets the trajectory the rest of the
        map would give.
        """
        alone = solve_with_backend(self.problem, [self._members[t]]).log_evidence
        return bool(self.tracklet_clutter_log_likelihood(t) > alone)

    def clutter_log_likelihood(self, state: Association) -> float:
        """The clutter terms of ``log P(J|Z)`` outside the graph (module docstring of clutter)."""
        return sum(self.component(t).log_weight for t in state.clutter)

    def solution(self, state: Association) -> GraphSolution:
        cached = self._solutions.get(state)
        if cached is not None:
            self._solutions.move_to_end(state)
            return cached
        start = time.perf_counter()
        max_iterations = None if self._anchor is None else self.max_iterations
        members, rows = self._graph(state)
        result = solve_with_backend(
            self.problem, members, warm_start=self._anchor, max_iterations=max_iterations, priors=rows
        )
        self.solve_seconds += time.perf_counter() - start
        self.solves += 1
        self._solutions[state] = result
        if len(self._solutions) > self.cache_size:
            self._solutions.popitem(last=False)
        return result

    def __call__(self, state: Association) -> float:
        if not self.graph_groups(state):
            return NO_OBJECT_LOG_EVIDENCE + self.clutter_log_likelihood(state)
        solution = self.solution(state)
        value = solution.log_evidence + self.clutter_log_likelihood(state)
        if self.exclusion and state.n_objects > 1 and np.isfinite(value):
            value += self.no_overlap_log_probability(state, solution)
        if self.detection.enabled and np.isfinite(value):
            value += self.detection_log_likelihood(state, solution)
        return value

    def detection_log_likelihood(self, state: Association, solution: GraphSolution) -> float:
        """The detection term of ``state``'s objects and distractors at its MAP (objslam_mapper.inference.detection)."""
        seen = self._sightings(state, solution.map_T_base, _estimates(solution))
        return miss_count_log_likelihood(int(np.count_nonzero(seen.missed)), self.detection)

    def no_overlap_log_probability(self, state: Association, solution: GraphSolution) -> float:
        """log P(no two objects of ``state`` overlap) at its MAP (objslam_mapper.inference.exclusion)."""
        members = self.groups(state)
        rows = [int(self.problem.measurement_label[m[0]]) for m in members]
        return no_overlap_log_probability(
            self.problem,
            solution.map_T_base,
            _estimates(solution, state.n_objects),
            members,
            rows,
            self.exclusion_floor,
        )

    # ---- the screen (first stage of delayed acceptance) --------------------------------
    def _reference(self, state: Association) -> tuple[NDArray, NDArray, NDArray]:
        """(poses (N, 3), graph group of each measurement (M,), groups (G, 5)) of ``state``'s MAP."""
        cached = self._references.get(state)
        if cached is not None:
            self._references.move_to_end(state)
            return cached
        if not self.graph_groups(state):
            owners = np.full(self.problem.measurement_count, -1, dtype=np.int64)
            reference = (np.asarray(self.problem.odometry_poses), owners, np.zeros((0, 5)))
        else:
            sol = self.solution(state)
            reference = (np.asarray(sol.map_T_base), sol.object_of_measurement, _estimates(sol))
        self._references[state] = reference
        if len(self._references) > _REFERENCE_CACHE_SIZE:
            self._references.popitem(last=False)
        return reference

    def _conditional(self, state: Association, group: GraphGroup) -> tuple[float, NDArray[np.float64]]:
        """(log e(group), its object) with the poses fixed at ``state``'s MAP (conditional_evidence)."""
        key = (state, group)
        cached = self._group_evidence.get(key)
        if cached is not None:
            return cached
        poses, owners, objects = self._reference(state)
        members = self._measurements(group)
        row = self._prior_row(group, members)
        owned = owners[members]
        owned = owned[owned >= 0]
        starts = [objects[int(np.argmax(np.bincount(owned)))]] if len(owned) else []
        starts.append(None)
        result = (-np.inf, np.zeros(5))
        for start in starts:
            if start is None:
                start = initial_object(self.problem, members, poses)
            self.object_solves += 1
            started = time.perf_counter()
            evidence = object_evidence(
                self.problem, poses, members, start, max_iterations=self.screen_iterations, prior=row
            )
            self.screen_seconds += time.perf_counter() - started
            result = (evidence.log_evidence, evidence.object_state)
            if np.isfinite(evidence.log_evidence):
                break
        self._group_evidence[key] = result
        if len(self._group_evidence) > _OBJECT_EVIDENCE_CACHE_SIZE:
            self._group_evidence.popitem(last=False)
        return result

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
            groups = [(_OBJECT, g) for g in assoc.groups]
            states = np.array([kept[g[1]] if g[1] in kept else self._conditional(state, g)[1] for g in groups])
            i, j = near_pairs(states)
            involved = np.array([groups[a][1] in changed or groups[b][1] in changed for a, b in zip(i, j, strict=True)])
            if not involved.any():
                return 0.0
            pairs = (i[involved], j[involved])
            needed = set(pairs[0].tolist()) | set(pairs[1].tolist())
            members = [self._measurements(g) if k in needed else None for k, g in enumerate(groups)]
            rows = [self._prior_row(g, m) if m is not None else -1 for g, m in zip(groups, members, strict=True)]
            return no_overlap_log_probability(
                self.problem, poses, states, members, rows, self.exclusion_floor, pairs=pairs
            )

        return term(new, fresh - old) - term(state, old - fresh)

    def _sightings(self, state: Association, map_T_base: NDArray, estimates: NDArray) -> Sightings:
        """How ``state``'s graph groups (at ``estimates``) appear from ``map_T_base``.

        The target term (at the state's MAP) and the screens of proposals from the state (at
        its reference, the same MAP unless the solution was evicted and solved again) share
        one computation: it is kept per state with the poses it was made at.
        """
        cached = self._sights.get(state)
        if cached is not None and cached[0] is map_T_base:
            self._sights.move_to_end(state)
            return cached[1]
        groups = self.graph_groups(state)
        members = [self._measurements(g) for g in groups]
        on_table = self._on_table(groups, members)
        seen = sightings(self.problem, map_T_base, estimates, members, self.detection, self.view_top_rad, on_table)
        self._sights[state] = (map_T_base, seen)
        if len(self._sights) > _REFERENCE_CACHE_SIZE:
            self._sights.popitem(last=False)
        return seen

    def _screen_detection(
        self, state: Association, old_groups: list[GraphGroup], new_groups: list[GraphGroup]
    ) -> float:
        """Change of the detection term from ``state`` (graph groups ``old_groups``) to the
        association of ``new_groups`` over the groups the move changes, at the screen's
        fixed poses and estimates (their effect on hiding the others is left to the target:
        see the module docstring)."""
        poses, _, estimates = self._reference(state)
        seen = self._sightings(state, poses, estimates)
        old_set, new_set = set(old_groups), set(new_groups)
        lost = [k for k, g in enumerate(old_groups) if g not in new_set]
        kept = [k for k, g in enumerate(old_groups) if g in new_set]
        gained = [g for g in new_groups if g not in old_set]
        n_miss = -int(np.count_nonzero(seen.missed[:, lost])) if lost else 0
        if gained:
            gained_estimates = np.array([self._conditional(state, g)[1] for g in gained])
            gained_members = [self._measurements(g) for g in gained]
            fresh = sight(self.problem, poses, gained_estimates, self.detection, self.view_top_rad)
            fresh_tables = table_sight(
                self.problem, poses, gained_estimates, self._on_table(gained, gained_members), self.detection
            )
            shown = visible(fresh, Sight.join([seen.occluders(kept), fresh, fresh_tables]), self.detection)
            hit = hit_matrix(self.problem, len(poses), gained_members)
            n_miss += int(np.count_nonzero(shown & ~hit))
        return miss_count_log_likelihood(n_miss, self.detection)

    def screen(self, state: Association, new: Association) -> float:
        """Approximate ``log P(new|Z) - log P(state|Z)``: poses fixed at ``state``'s MAP.

        The graph groups (objects and distractors) both associations share cancel, so only
        those the move changes are solved (5 variables each); the clutter terms outside
        the graph are the exact ones of the target, the no-overlap term is evaluated at the
        fixed-pose objects. A fixed function of the pair (cached), as delayed acceptance needs.
        """
        self.screens += 1
        old_list, new_list = self.graph_groups(state), self.graph_groups(new)
        old_groups, new_groups = set(old_list), set(new_list)
        gained = sum(self._conditional(state, g)[0] for g in new_groups - old_groups)
        lost = sum(self._conditional(state, g)[0] for g in old_groups - new_groups)
        value = gained - lost if np.isfinite(lost) else -np.inf
        value += self.clutter_log_likelihood(new) - self.clutter_log_likelihood(state)
        if self.exclusion and np.isfinite(value):
            value += self._screen_no_overlap(state, new)
        if self.detection.enabled and np.isfinite(value):
            value += self._screen_detection(state, old_list, new_list)
        return float(value)

    def move_to(self, state: Association) -> None:
        """The chain is now in ``state``: warm-start later solves from its solution."""
        self._anchor = self._solutions.get(state, self._anchor)

    def summary(self, state: Association) -> SampleSummary:
        """MAP and marginals of ``state``'s objects (Algorithm 1, step 2a); distractors are no map objects."""
        if not self.graph_groups(state):
            return SampleSummary(map_T_base=np.array(self.problem.odometry_poses), objects=())
        warm = self._solutions.get(state, self._anchor)
        started = time.perf_counter()
        members, rows = self._graph(state)
        result = solve_with_backend(
            self.estimation_problem, members, warm_start=warm, with_covariances=True, priors=rows
        )
        self.marginal_seconds += time.perf_counter() - started
        self.marginal_solves += 1
        objects = []
        for est in result.objects[: state.n_objects]:
            nan3, nan2 = np.full((3, 3), np.nan), np.full((2, 2), np.nan)
            objects.append(
                SampleObject(
                    identity=frozenset(int(m) for m in est.measurement_indices),
                    label=est.label,
                    location_m=np.asarray(est.location_m, dtype=float),
                    size_m=np.asarray(est.size_m, dtype=float),
                    location_cov=nan3 if est.location_cov is None else np.asarray(est.location_cov, dtype=float),
                    size_cov=nan2 if est.size_cov is None else np.asarray(est.size_cov, dtype=float),
                    error_cov=None if est.error_cov is None else np.asarray(est.error_cov, dtype=float),
                )
            )
        return SampleSummary(
            map_T_base=np.asarray(result.map_T_base, dtype=float),
            objects=tuple(objects),
            calibration=np.asarray(result.calibration, dtype=float),
            calibration_cov=np.asarray(result.calibration_cov, dtype=float),
        )


def _centroid(tracklets: Sequence[Tracklet], group: Sequence[int]) -> NDArray[np.float64]:
    """Rough xy of an object: its tracklets' positions weighted by their slice counts."""
    weights = np.array([len(tracklets[u]) for u in group], dtype=float)
    return weights @ np.array([tracklets[u].position_xy_m for u in group]) / weights.sum()


def _nearest_object(
    tracklet: Tracklet,
    labels: Sequence[str],
    centroids: Sequence[NDArray[np.float64]],
    frames: Sequence[set[int]],
    max_distance_m: float,
) -> int | None:
    """The object (by its label, centroid and images) of ``tracklet``'s class nearest to it
    within ``max_distance_m`` and not seen in the same images, or None."""
    xy = np.asarray(tracklet.position_xy_m)
    seen = set(tracklet.frame_indices)
    best, best_d = None, max_distance_m
    for j, (label, centroid, images) in enumerate(zip(labels, centroids, frames, strict=True)):
        if label != tracklet.label or images & seen:
            continue
        d = float(np.hypot(*(centroid - xy)))
        if d <= best_d:
            best, best_d = j, d
    return best


def initial_association(
    tracklets: Sequence[Tracklet], max_distance_m: float, clutter: Collection[int] = ()
) -> Association:
    """A start state: tracklets by first image, each joining the nearest object of its class
    whose centroid is within ``max_distance_m`` and that was not seen in the same images;
    the tracklets in ``clutter`` start as clutter."""
    members: list[list[int]] = []
    labels: list[str] = []
    centroids: list[NDArray[np.float64]] = []
    frames: list[set[int]] = []
    order = sorted(
        (t for t in range(len(tracklets)) if t not in clutter), key=lambda t: (tracklets[t].frame_indices[0], t)
    )
    for t in order:
        tr = tracklets[t]
        best = _nearest_object(tr, labels, centroids, frames, max_distance_m)
        if best is None:
            members.append([t])
            labels.append(tr.label)
            centroids.append(np.asarray(tr.position_xy_m))
            frames.append(set(tr.frame_indices))
        else:
            members[best].append(t)
            centroids[best] = _centroid(tracklets, members[best])
            frames[best] |= set(tr.frame_indices)
    return Association.from_groups(len(tracklets), members)


def _take_if_better(
    target: AssociationTarget, state: Association, value: float, candidate: Association, screen_margin_nats: float
) -> tuple[Association, float, bool]:
    """``candidate`` and its target value if the target prefers it to ``state`` (worth ``value``),
    else ``state``; a candidate the screen judges worse by more than the margin is not solved."""
    if target.screen(state, candidate) < -screen_margin_nats:
        return state, value, False
    candidate_value = target(candidate)
    if candidate_value > value:
        target.move_to(candidate)
        return candidate, candidate_value, True
    return state, value, False


def clear_start_objects(
    target: AssociationTarget, state: Association, screen_margin_nats: float = 20.0
) -> tuple[Association, list[int]]:
    """Move to clutter, one at a time, each start object whose tracklets the target prefers there.

    A distractor seen in several tracklets (a patch on the floor, passed twice) starts as
    one object when its tracklets lie close together. Each of them alone may fit its class
    well enough (a short look leaves the size to the prior), while together they pin a
    shape far off it; taking such an object apart one tracklet at a time first loses, so a
    chain started there stays. This greedy pass, largest objects last, only moves the
    start: the target and the chain's exactness do not change. A candidate the screen
    (poses fixed) judges worse by more than ``screen_margin_nats`` is not solved. Returns
    the new start and the tracklets moved.
    """
    moved: list[int] = []
    current = target(state)
    target.move_to(state)  # the candidates differ from it by one object: warm starts
    for group in sorted(state.groups, key=lambda g: (sum(len(target.tracklets[t]) for t in g), g)):
        candidate = Association.of([CLUTTER if t in group else a for t, a in enumerate(state.assignment)])
        state, current, taken = _take_if_better(target, state, current, candidate, screen_margin_nats)
        if taken:
            moved.extend(group)
    return state, sorted(moved)


def recall_start_clutter(
    target: AssociationTarget, state: Association, max_distance_m: float, screen_margin_nats: float = 20.0
) -> tuple[Association, list[int]]:
    """Move each clutter tracklet, largest first, into the nearest object of its class if the target prefers it.

    A short tracklet alone is often likelier clutter than a lone object (``initial_clutter``)
    though it is a piece of an object seen in other tracklets. The chain would bring each
    back with a move out of clutter, but only after many rejected proposals around it, and
    each proposal the screen passes costs a graph solve: the more images per metre, the
    more short tracklets (on ``office`` at 4x its frames 22 start in clutter, against 10 at
    1x). This greedy pass tries each once, into the object (same class, not seen in the
    same images) whose tracklets' weighted centroid is nearest and within
    ``max_distance_m``, screened first like :func:`clear_start_objects`, which should run
    again after it (a tracklet may join a ghost that is then clutter as a whole: on
    ``office`` seed 7 the chain otherwise kept a cyan ghost). Only the start moves; the
    chain stays exact. Returns the new start and the tracklets moved.
    """
    tracklets = target.tracklets
    moved: list[int] = []
    current = target(state)
    target.move_to(state)
    for t in sorted(state.clutter, key=lambda u: (-len(tracklets[u]), u)):
        groups = state.groups
        best = _nearest_object(
            tracklets[t],
            [tracklets[g[0]].label for g in groups],
            [_centroid(tracklets, g) for g in groups],
            [{f for u in g for f in tracklets[u].frame_indices} for g in groups],
            max_distance_m,
        )
        if best is None:
            continue
        candidate = Association.of([best if u == t else a for u, a in enumerate(state.assignment)])
        state, current, taken = _take_if_better(target, state, current, candidate, screen_margin_nats)
        if taken:
            moved.append(t)
    return state, sorted(moved)


def infer_map(problem: GraphProblem, config: SamplerConfig, progress: PhaseProgress | None = None) -> BuiltMap:
    """Tracklets, MH over associations and Algorithm 1 on a built factor-graph problem."""
    report = progress or (lambda _phase, _done, _total: None)
    started = time.perf_counter()
    report("tracklets", 0, 1)
    chained = tracklets_of_problem(problem, config.tracklets)
    report("tracklets", 1, 1)
    tracklet_seconds = time.perf_counter() - started
    diagnostics: dict[str, Any] = {
        "seed": config.seed,
        "poses": problem.pose_count,
        "graph_poses": problem.keyframes.problem.pose_count,  # objslam_mapper.graph.keyframes
        "measurements": problem.measurement_count,
        "rejected_images": problem.rejected_image_count,
        "rejected_slices": problem.rejected_slice_count,
        "tracklets": len(chained.tracklets),
        "isolated_dropped": len(chained.dropped_measurements),
    }
    target = AssociationTarget(
        problem,
        chained.tracklets,
        config.clutter,
        max_iterations=config.proposal_max_iterations,
        cache_size=config.solution_cache_size,
        exclusion=config.exclusion,
        detection=config.detection,
        exclusion_floor_nats=config.exclusion_floor_nats,
    )
    if not chained.tracklets:
        logger.warning("no tracklets (every detection isolated): the map holds no objects")
        summary = target.summary(Association(()))
        built = build_from_samples([(summary, 1)], problem.stamps_ns, diagnostics=diagnostics)
        report("mapping", 1, 1)
        return built

    sampler = MetropolisHastings(
        chained.labels,
        target,
        config.moves,
        positions_xy_m=[t.position_xy_m for t in chained.tracklets],
        tracklet_weights=[len(t) for t in chained.tracklets],
        allow_clutter=config.clutter.enabled,
        screen=target.screen if config.screen_proposals else None,
        screen_margin=config.screen_margin_nats,
        screen_relative_margin=config.screen_relative_margin,
        screen_floor=config.screen_floor,
        screen_join_floor=config.screen_join_floor,
    )
    start_in_clutter = config.initial_clutter and config.clutter.enabled
    start_clutter: set[int] = set()
    if start_in_clutter:
        start_clutter = {t for t in range(len(chained.tracklets)) if target.prefers_clutter(t)}
    start = initial_association(chained.tracklets, config.initial_merge_distance_m, start_clutter)
    diagnostics["start_objects"] = start.n_objects
    cleared: list[int] = []
    recalled: list[int] = []
    if start_in_clutter:
        start, cleared = clear_start_objects(target, start)
        start, recalled = recall_start_clutter(target, start, config.initial_merge_distance_m)
        if recalled:  # an object a recalled tracklet joined may now be clutter as a whole
            start, more = clear_start_objects(target, start)
            cleared += more
    chain = sampler.run(
        start,
        config.samples,
        config.burn_in,
        np.random.default_rng(config.seed),
        progress=lambda done, total: report("sampling", done, total),
        keep_trace=False,
        on_move=target.move_to,
    )
    sampling_seconds = time.perf_counter() - started - tracklet_seconds

    def summaries():
        for k, (state, count) in enumerate(chain.counts.items()):
            report("mapping", k, len(chain.counts))
            yield target.summary(state), count
        report("mapping", len(chain.counts), len(chain.counts))

    diagnostics.update(chain.diagnostics())
    diagnostics["start_clutter_tracklets"] = len(start_clutter)
    diagnostics["start_tracklets_cleared"] = len(cleared)
    diagnostics["start_tracklets_recalled"] = len(recalled)
    diagnostics["best_state_objects"] = chain.best_state.n_objects
    diagnostics["best_state_clutter_tracklets"] = len(chain.best_state.clutter)
    diagnostics["solves"] = target.solves
    diagnostics["screens"] = target.screens
    diagnostics["object_solves"] = target.object_solves
    diagnostics["clutter_solves"] = target.clutter_solves
    built = build_from_samples(
        summaries(),
        problem.stamps_ns,
        spurious_location_stddev_m=config.spurious_location_stddev_m,
        existence_threshold=config.existence_threshold,
        report_min_fraction=config.report_min_fraction,
        identity_overlap=config.identity_overlap,
        diagnostics=diagnostics,
    )
    total = time.perf_counter() - started
    mapping_seconds = total - tracklet_seconds - sampling_seconds
    built.diagnostics["marginal_solves"] = target.marginal_solves  # known once Algorithm 1 has run
    # Phases that add up to the total: the solves of the chain are timed where they happen
    # (a screen may need its reference state's solve, counted under solves).
    built.diagnostics["timings_s"] = {
        "tracklets": round(tracklet_seconds, 3),
        "sampling": round(sampling_seconds, 3),
        "solving_during_sampling": round(target.solve_seconds, 3),
        "screening": round(target.screen_seconds, 3),
        "clutter_solves": round(target.clutter_seconds, 3),
        "proposals_and_chain": round(
            sampling_seconds - target.solve_seconds - target.screen_seconds - target.clutter_seconds, 3
        ),
        "mapping": round(mapping_seconds, 3),
        "marginals": round(target.marginal_seconds, 3),
        "map_building": round(mapping_seconds - target.marginal_seconds, 3),
        "total": round(total, 3),
    }
    logger.info(
        "map: %d objects, %d rejected; %d tracklets, %d distinct associations visited, acceptance %.2f, %.1f s",
        len(built.objects),
        len(built.rejected),
        len(chained.tracklets),
        chain.distinct_visited,
        chain.overall_acceptance_rate,
        total,
    )
    return built


def build_map(
    odometry: Sequence[OdometrySample],
    images: Sequence[ImageSlices],
    catalog: Catalog,
    graph: GraphConfig | None = None,
    sampler: SamplerConfig | None = None,
    progress: PhaseProgress | None = None,
) -> BuiltMap:
    """The whole offline pipeline from odometry and slices to the object map."""
    graph = graph or GraphConfig()
    problem = build_problem(odometry, images, graph.camera_mount.to_mount(), catalog, graph)
    return infer_map(problem, sampler or SamplerConfig(), progress)
