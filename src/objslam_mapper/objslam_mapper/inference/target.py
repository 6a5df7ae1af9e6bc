r"""The chain's target ``log P(J | Z)``: the value of an association of tracklets.

The target of the chain (paper eq. 25, extended with clutter and solid objects) is, up to
a constant,

    log P(J | Z) = log P(Z | J) + sum over clutter things tau of log w(tau)
                   + log P(no two objects of J overlap | J, Z) + log P(J),

where ``log P(Z | J)`` is the Laplace evidence of J's factor graph
(:func:`objslam_mapper.graph.solver.solve`, every Gaussian normalizer included): its objects
(one per group of tracklets, with its class priors) and its distractors (each clutter
thing that a static thing of unknown shape explains, with broad priors;
:mod:`objslam_mapper.inference.clutter`). A clutter *thing* is one clutter tracklet, or
several that one distractor explains better together than apart
(:meth:`AssociationTarget.clutter_things`). ``log w(tau)`` is the rest of a clutter thing's
likelihood: the distractor component's weight, or, for a tracklet of independent false
alarms (outside the graph), that weight times its uniform density. Each slice's factor
is the max-mixture of :mod:`objslam_mapper.model.outliers` (a merged or cut blob costs a capped
amount). The no-overlap term is :mod:`objslam_mapper.inference.exclusion` (real objects do not
share floor space; without it a blob merged with a neighbour becomes a duplicate beside
the real object), and ``P(J)`` is uniform, as in the paper. Isolated detections dropped
by the tracklet chaining are in no J.

Each solve is warm-started from the chain's current state (a proposal differs from it by
one move) and capped at ``proposal_max_iterations`` per phase of the outlier caps: a
hopeless proposal (a merge of objects metres apart) then costs a few iterations and is
rejected on the value at its last iterate. That value is not always below the optimum's:
the graph's evidence nearly is (up to its log-determinant), but the detection term is
evaluated there too and is not what the solve optimises (on ``clutter`` seed 14 a state
stopped unconverged 93 nats above its converged value, and the chains kept it;
docs/method.md), so a proposal the chain might take on such a value is solved on first
(``settle_within_nats``). Values are
cached per state, so the chain sees one fixed target whatever path led to a state. Another
chain may reach the same state from elsewhere, and its solve find another local optimum of
trajectory and objects (on ``clutter`` seed 13 one state was worth 51632 nats in one chain
and 51318 solved from the odometry; docs/method.md).

The screen of proposals (:mod:`objslam_mapper.inference.screen`) and the start state
(:mod:`objslam_mapper.inference.start`) are built on it.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from cachetools import LRUCache
from numpy.typing import NDArray

from objslam_mapper.config import ClutterConfig, DetectionConfig, SamplerConfig
from objslam_mapper.graph.backends import solve_with_backend
from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.graph.solver import GraphSolution
from objslam_mapper.inference.algorithm1 import SampleObject, SampleSummary
from objslam_mapper.inference.association import Association
from objslam_mapper.inference.caches import lru, lru_bytes, remember
from objslam_mapper.inference.clutter import DISTRACTOR, ClutterModel, Component, DistractorFit
from objslam_mapper.inference.detection import Sightings, camera_view, lies_over, sightings
from objslam_mapper.inference.diagnostics import Work
from objslam_mapper.inference.exclusion import no_overlap_log_probability
from objslam_mapper.inference.tracklets import Tracklet
from objslam_mapper.model.slice_model import BEARING, ELEVATION_TOP, MEASURED, WIDTH

# The graph of an association without objects is the odometry chain alone: its MAP is the
# odometry (chi2 = 0), and as the map from poses to (first-pose residual, increments) has a
# unit Jacobian determinant, the Laplace evidence -cost + sum of normalizers + d/2 log 2 pi
# - 1/2 log|Lambda| is exactly 0. Computed here rather than solved: such a state needs no graph.
NO_OBJECT_LOG_EVIDENCE = 0.0

CLUTTER_THINGS_CACHE_SIZE = 1024

# Clutter tracklets of one class are tested for being one thing (``AssociationTarget.joins``)
# when their rough positions (Tracklet.position_xy_m, from odometry and range-from-size) are
# this close. Only a screen: whether they join is decided by the fit. Fragments of one patch
# seen a pass apart are within a metre on the bundled scenarios; the wider radius leaves room
# for odometry drift at a few milliseconds per pair tested.
JOIN_RADIUS_M = 1.5

# A group of an association's factor graph: an object (its tracklets) or a distractor (a clutter thing's tracklets).
GraphGroup = tuple[str, tuple[int, ...]]
OBJECT = "object"


class TargetOptions(NamedTuple):
    """Which terms the target has and how hard it solves (:meth:`of` takes them from the sampler's settings)."""

    clutter: ClutterConfig = ClutterConfig()
    exclusion: bool = True  # objects are solid
    exclusion_floor_nats: float = -60.0
    detection: DetectionConfig = DetectionConfig(enabled=False)  # missed detections
    max_iterations: int | None = None  # per solve warm-started from the chain's state (None: solver.max_iterations)
    # An unconverged proposal valued within this many nats below the chain's state (or above
    # it) is solved on with the solver's own budget before the chain sees its value; 0: never.
    settle_within_nats: float = 0.0
    cache_size: int = 256  # graph solutions kept
    sightings_cache_bytes: int = 256 * 2**20  # per-state sightings kept, in bytes (inference.caches)

    @classmethod
    def of(cls, config: SamplerConfig) -> TargetOptions:
        return cls(
            clutter=config.clutter,
            exclusion=config.exclusion,
            exclusion_floor_nats=config.exclusion_floor_nats,
            detection=config.detection,
            max_iterations=config.proposal_max_iterations,
            settle_within_nats=config.settle_within_nats,
            cache_size=config.solution_cache_size,
            sightings_cache_bytes=config.sightings_cache_mb * 2**20,
        )


def estimates(solution: GraphSolution, count: int | None = None) -> NDArray[np.float64]:
    """(G, 5) (x, y, z_base, diameter, height) of the solution's first ``count`` groups (default all)."""
    return np.array([np.concatenate([o.location_m, o.size_m]) for o in solution.objects[:count]]).reshape(-1, 5)


class AssociationTarget:
    """``log P(J|Z)`` of associations of ``tracklets`` (see the module docstring); callable.

    The costly calls are counted in ``work`` (:class:`~objslam_mapper.inference.diagnostics.Work`).
    """

    def __init__(
        self,
        problem: GraphProblem,
        tracklets: Sequence[Tracklet],
        options: TargetOptions | None = None,
        work: Work | None = None,
    ):
        # The target takes every upper edge as measured, those cut by the top of the view too;
        # the map's estimates (summary) take those as the lower bounds they are. Scored
        # one-sided, an upper edge no longer tells a cyan poster high on a wall from a cyan
        # object, nor one object from two beside each other: on the clutter and twins bags the
        # target then preferred those states (docs/method.md). Edges cut at the sides and the
        # bottom stay bounds in the target too: taken as measured, the bearing and width of a
        # slice half out of a forward camera's view disagree with the object's, and its
        # tracklet became an object of its own.
        bounds = problem.measurement_bounds
        target_bounds = np.array(bounds)
        target_bounds[:, ELEVATION_TOP] = MEASURED
        problem = dataclasses.replace(problem, measurement_bounds=target_bounds)
        options = options or TargetOptions()
        self.options = options
        self.work = work or Work()
        self.clutter = ClutterModel(problem, options.clutter)
        self.detection = options.detection
        self.view = camera_view(problem, self.detection)
        self.problem = self.clutter.problem  # with the distractors' prior rows
        self.estimation_problem = dataclasses.replace(self.problem, measurement_bounds=bounds)
        solver = self.estimation_problem.solver
        self._marginals_only = dataclasses.replace(
            self.estimation_problem,
            solver=dataclasses.replace(
                solver, error_covariance=dataclasses.replace(solver.error_covariance, enabled=False)
            ),
        )
        self.tracklets = list(tracklets)
        self._members = [np.asarray(t.measurement_indices, dtype=np.int64) for t in self.tracklets]
        self._solutions: LRUCache[Association, GraphSolution] = lru(options.cache_size)
        self._anchor: GraphSolution | None = None
        self._anchor_value: float | None = None  # the chain's state's value (settle_within_nats)
        self._thing_components: dict[tuple[int, ...], Component] = {}
        self._join_graph: list[set[int]] | None = None
        self._join_gains: dict[tuple[int, int], float] = {}  # per joined pair a < b: :meth:`_join_gain`
        self._things: LRUCache[Association, list[tuple[int, ...]]] = lru(CLUTTER_THINGS_CACHE_SIZE)
        # Per state: how its graph groups appear, and the poses that was computed at.
        self._sights: LRUCache[Association, tuple[NDArray, Sightings]] = lru_bytes(options.sightings_cache_bytes)

    def component(self, t: int) -> Component:
        """How tracklet t is explained when it is clutter on its own (one distractor solve, remembered)."""
        return self.thing_component((t,))

    def thing_component(self, thing: tuple[int, ...]) -> Component:
        """How clutter tracklets that are one thing (:meth:`clutter_things`) are explained: a
        tracklet alone by the likelier clutter component; several by one distractor (remembered)."""
        if thing not in self._thing_components:
            start = time.perf_counter()
            explain = self.clutter.component if len(thing) == 1 else self.clutter.distractor
            self._thing_components[thing] = explain(
                self.measurements((DISTRACTOR, thing)), lambda fit: self._distractor_misses(thing, fit)
            )
            self.work.clutter_solves += 1
            self.work.clutter_seconds += time.perf_counter() - start
        return self._thing_components[thing]

    def joins(self) -> list[set[int]]:
        """Per tracklet, the tracklets it is one thing with when both are clutter: those of its
        class within JOIN_RADIUS_M whose slices together, as one distractor with the odometry
        alone (its misses included), are likelier than each explained on its own.

        Without it every clutter tracklet was a thing of its own, and a patch seen in three
        tracklets was three distractors, each paying the Occam factor of its broad priors, the
        misses in the images only the others saw, and, for a short fragment, ~5 nats per slice
        as independent false alarms: together dearer than one object of its class, however
        unlike the class it is (on ``clutter`` seed 1 four patches were mapped at P = 1.00,
        one as a 6 mm tall "green" object). The relation is a fixed function of the tracklets,
        so the target stays a fixed function of the association (docs/method.md)."""
        if self._join_graph is None:
            n = len(self.tracklets)
            graph: list[set[int]] = [set() for _ in range(n)]
            if self.options.clutter.distractor_weight > 0.0:
                xy = np.array([t.position_xy_m for t in self.tracklets], dtype=float).reshape(-1, 2)
                labels = np.array([t.label for t in self.tracklets])
                near = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1)) < JOIN_RADIUS_M
                for a, b in zip(*np.nonzero(np.triu(near & (labels[:, None] == labels[None, :]), k=1)), strict=True):
                    gain = self._join_gain(int(a), int(b))
                    if gain > 0.0:
                        graph[a].add(int(b))
                        graph[b].add(int(a))
                        self._join_gains[(int(a), int(b))] = gain
            self._join_graph = graph
        return self._join_graph

    def _value(self, thing: tuple[int, ...]) -> float:
        return self.thing_component(thing).alone_log_likelihood

    def _join_gain(self, a: int, b: int) -> float:
        """How much likelier tracklets a < b are as one thing than each on its own."""
        return self._value((a, b)) - self._value((a,)) - self._value((b,))

    def clutter_things(self, state: Association) -> list[tuple[int, ...]]:
        """The things ``state``'s clutter tracklets are, in order of their first tracklet.

        Joined tracklets (:meth:`joins`) are gathered greedily, the pair that gains most by
        being one thing first, and two sets become one only if one distractor explains them
        better than the two do apart: joins are judged in pairs with the odometry alone, and a
        chain of them can link tracklets of different things (two objects 0.8 m apart, passed
        twice with drifting odometry), which one distractor explains hundreds of nats worse.
        A fixed function of the clutter set (ties broken by tracklet order)."""
        cached = self._things.get(state)
        if cached is not None:
            return cached
        graph = self.joins()
        clutter = set(state.clutter)
        pairs = [(a, b) for a in state.clutter for b in sorted(graph[a] & clutter) if a < b]
        gains = self._join_gains  # looked up, not recomputed: this runs for every state the screen judges
        pairs.sort(key=lambda p: (-gains[p], p))
        part_of: dict[int, tuple[int, ...]] = {t: (t,) for t in state.clutter}
        for a, b in pairs:
            first, second = part_of[a], part_of[b]
            if first == second:
                continue
            joined = tuple(sorted(first + second))
            if self._value(joined) > self._value(first) + self._value(second):
                for t in joined:
                    part_of[t] = joined
        return remember(self._things, state, sorted(set(part_of.values())))

    def graph_groups(self, state: Association) -> list[GraphGroup]:
        """The groups of ``state``'s factor graph: its objects in order, then its distractors."""
        groups: list[GraphGroup] = [(OBJECT, g) for g in state.groups]
        groups += [(DISTRACTOR, th) for th in self.clutter_things(state) if self.thing_component(th).kind == DISTRACTOR]
        return groups

    def measurements(self, group: GraphGroup) -> NDArray[np.int64]:
        return np.sort(np.concatenate([self._members[t] for t in group[1]]))

    def prior_row(self, group: GraphGroup, members: NDArray[np.int64]) -> int:
        if group[0] == DISTRACTOR:
            return self.clutter.distractor_row(int(members[0]))
        return int(self.problem.measurement_label[members[0]])

    def on_table(self, groups: Sequence[GraphGroup], members: Sequence[NDArray[np.int64]]) -> NDArray[np.bool_]:
        """Which groups stand on a table: objects of a class whose base is above the floor
        (docs/design.md); distractors are posters and patches, which stand on nothing."""
        return np.array(
            [
                g[0] == OBJECT and self.problem.prior_mean[self.prior_row(g, m), 2] > 0.0
                for g, m in zip(groups, members, strict=True)
            ],
            dtype=bool,
        )

    def objects_at_map(self, state: Association) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray, NDArray]:
        """``state``'s poses (N, 3) and objects at its MAP (distractors left out): (K, 5) (x, y,
        z_base, diameter, height), (K,) class rows, (K,) whether each stands on a table."""
        groups = self.graph_groups(state)
        if not groups:
            empty = np.zeros(0)
            return np.array(self.problem.odometry_poses), np.zeros((0, 5)), empty.astype(np.int64), empty.astype(bool)
        solution = self.solution(state)
        keep = [k for k, g in enumerate(groups) if g[0] == OBJECT]
        members = [self.measurements(groups[k]) for k in keep]
        labels = np.array([int(self.problem.measurement_label[m[0]]) for m in members], dtype=np.int64)
        on_table = self.on_table([groups[k] for k in keep], members)
        return solution.map_T_base, estimates(solution)[keep].reshape(-1, 5), labels, on_table

    def kin(self, groups: Sequence[GraphGroup]) -> NDArray[np.int64]:
        """Which of ``groups`` share their hits and misses in the detection term
        (objslam_mapper.inference.detection.share): a distractor unlike any object of its
        class (:attr:`.clutter.Component.unlike_class`) gets its class's distractor prior row,
        the rest -1. A thing shaped like its class is left to pay its own misses: its tracklets
        can join as one object, and sharing would let a real object escape into fragments that
        pay the misses of one thing with the freedom of several. Unlike is judged once per
        tracklet, with the odometry alone, not at the state's estimates: those move with the
        map, and a map stretched to half again its size (one object joining tracklets metres
        apart) made every distractor on the floor look unlike its class and share its hits,
        8000 nats of misses fewer on ``office`` (docs/method.md)."""
        kin = np.full(len(groups), -1, dtype=np.int64)
        for k, g in enumerate(groups):
            if g[0] == DISTRACTOR and self.thing_component(g[1]).unlike_class:
                kin[k] = self.clutter.distractor_row(int(self._members[g[1][0]][0]))
        return kin

    def groups(self, state: Association) -> list[NDArray[np.int64]]:
        """Measurement indices of each object of ``state``, in its object order."""
        return [self.measurements((OBJECT, g)) for g in state.groups]

    def _graph(self, state: Association) -> tuple[list[NDArray[np.int64]], list[int]]:
        """Measurements and prior rows of every group of ``state``'s graph."""
        groups = self.graph_groups(state)
        members = [self.measurements(g) for g in groups]
        rows = [self.prior_row(g, m) for g, m in zip(groups, members, strict=True)]
        return members, rows

    def _alone_detection(self, group: GraphGroup, solution: GraphSolution, kin: int) -> float:
        """The detection term of one graph group solved alone as ``solution``: its misses with
        nothing in front of it but its own table, if it stands on one. An image where a
        tracklet of its class has a slice over its predicted bearing interval is no miss: its
        other fragments' slices (clutter module docstring)."""
        if not self.detection.enabled:
            return 0.0
        members = self.measurements(group)
        seen = sightings(
            self.problem,
            solution.map_T_base,
            estimates(solution),
            [members],
            self.detection,
            self.view,
            on_table=self.on_table([group], [members]),
            kin=np.array([kin]),
        )
        label = self.problem.measurement_label[members[0]]
        kind = np.concatenate([m for m in self._members if self.problem.measurement_label[m[0]] == label])
        pose = self.problem.measurement_pose[kind]
        measured = np.asarray(self.problem.measurements)[kind]
        over = lies_over(
            measured[:, BEARING], measured[:, WIDTH], seen.sight.bearing[pose, 0], seen.sight.width[pose, 0]
        )
        hit = seen.hit.copy()
        hit[pose[over], 0] = True
        return dataclasses.replace(seen, hit=hit).terms(self.detection).log_likelihood(self.detection)

    def _distractor_misses(self, thing: tuple[int, ...], fit: DistractorFit) -> float:
        """What the distractor of tracklets ``thing`` pays alone (clutter module docstring)."""
        return self._alone_detection((DISTRACTOR, thing), fit.solution, fit.prior_row if fit.unlike_class else -1)

    def tracklet_clutter_log_likelihood(self, t: int) -> float:
        """log L_clutter of tracklet t with the odometry alone (its component's, misses included)."""
        return self.component(t).alone_log_likelihood

    def prefers_clutter(self, t: int) -> bool:
        """Whether tracklet t alone, with the odometry, is likelier clutter than an object of its class.

        That is ``log P(J|Z)`` of the state with t its own object and every other tracklet
        clutter against the state with all of them clutter, both with the odometry alone
        (the other tracklets' terms cancel), so neither gets the trajectory the rest of the
        map would give; each pays the misses it would alone.
        """
        solution = solve_with_backend(self.problem, [self._members[t]])
        alone = solution.log_evidence + self._alone_detection((OBJECT, (t,)), solution, -1)
        return bool(self.tracklet_clutter_log_likelihood(t) > alone)

    def clutter_log_likelihood(self, state: Association) -> float:
        """The clutter terms of ``log P(J|Z)`` outside the graph (module docstring of clutter)."""
        return sum(self.thing_component(th).log_weight for th in self.clutter_things(state))

    def solution(self, state: Association) -> GraphSolution:
        cached = self._solutions.get(state)
        if cached is not None:
            return cached
        max_iterations = None if self._anchor is None else self.options.max_iterations
        result = self._solve(state, self._anchor, max_iterations)
        self.work.solves += 1
        self.work.unconverged_solves += not result.converged
        return result

    def _solve(self, state: Association, warm_start: GraphSolution | None, max_iterations: int | None) -> GraphSolution:
        """``state``'s graph solved (timed) and kept as its solution."""
        start = time.perf_counter()
        members, rows = self._graph(state)
        result = solve_with_backend(
            self.problem, members, warm_start=warm_start, max_iterations=max_iterations, priors=rows
        )
        self.work.solve_seconds += time.perf_counter() - start
        return remember(self._solutions, state, result)

    def __call__(self, state: Association) -> float:
        if not self.graph_groups(state):
            return NO_OBJECT_LOG_EVIDENCE + self.clutter_log_likelihood(state)
        solution = self.solution(state)
        value = self._state_value(state, solution)
        # An unconverged solve's value can lie far above the optimum's (the detection term is
        # evaluated at the last iterate, not optimised; module docstring): a proposal the
        # chain might take on such a value is solved on first.
        settle = self.options.settle_within_nats
        if settle > 0.0 and not solution.converged and self._anchor_value is not None:
            if np.isfinite(value) and value > self._anchor_value - settle:
                solution = self._settle(state, solution)
                value = self._state_value(state, solution)
        return value

    def _settle(self, state: Association, solution: GraphSolution) -> GraphSolution:
        """``state`` solved on from ``solution`` with the solver's own iteration budget."""
        result = self._solve(state, solution, None)
        self.work.settled_solves += 1
        self.work.unconverged_settles += not result.converged
        return result

    def _state_value(self, state: Association, solution: GraphSolution) -> float:
        value = solution.log_evidence + self.clutter_log_likelihood(state)
        if self.options.exclusion and state.n_objects > 1 and np.isfinite(value):
            value += self.no_overlap_log_probability(state, solution)
        if self.detection.enabled and np.isfinite(value):
            value += self.detection_log_likelihood(state, solution)
        return value

    def detection_log_likelihood(self, state: Association, solution: GraphSolution) -> float:
        """The detection term of ``state``'s objects and distractors at its MAP (objslam_mapper.inference.detection)."""
        seen = self.sightings(state, solution.map_T_base, estimates(solution))
        return seen.terms(self.detection).log_likelihood(self.detection)

    def no_overlap_log_probability(self, state: Association, solution: GraphSolution) -> float:
        """log P(no two objects of ``state`` overlap) at its MAP (objslam_mapper.inference.exclusion)."""
        members = self.groups(state)
        rows = [int(self.problem.measurement_label[m[0]]) for m in members]
        return no_overlap_log_probability(
            self.problem,
            solution.map_T_base,
            estimates(solution, state.n_objects),
            members,
            rows,
            self.options.exclusion_floor_nats,
        )

    def sightings(self, state: Association, map_T_base: NDArray, estimates: NDArray) -> Sightings:
        """How ``state``'s graph groups (at ``estimates``) appear from ``map_T_base``.

        The target term (at the state's MAP) and the screens of proposals from the state (at
        its reference, the same MAP unless the solution was evicted and solved again) share
        one computation: it is kept per state with the poses it was made at.
        """
        cached = self._sights.get(state)
        if cached is not None and cached[0] is map_T_base:
            return cached[1]
        groups = self.graph_groups(state)
        members = [self.measurements(g) for g in groups]
        on_table = self.on_table(groups, members)
        seen = sightings(
            self.problem,
            map_T_base,
            estimates,
            members,
            self.detection,
            self.view,
            on_table=on_table,
            kin=self.kin(groups),
        )
        return remember(self._sights, state, (map_T_base, seen))[1]

    def move_to(self, state: Association, value: float) -> None:
        """The chain is now in ``state``, worth ``value`` (this target's value of it, as the
        caller judged it): warm-start later solves from its solution and settle proposals
        against that value. Evaluating the state again here would solve on a settled state
        whose solve still stopped unconverged, and hold a value the chain does not."""
        self._anchor = self._solutions.get(state, self._anchor)
        self._anchor_value = value

    def summary(self, state: Association, *, error_covariances: bool = True) -> SampleSummary:
        """MAP and marginals of ``state``'s objects (Algorithm 1, step 2a); distractors are no map objects.

        ``error_covariances=False`` leaves out the covariances of the objects' errors
        (``solver.error_covariance``; the objects then report their marginals), the costly
        part on a long run: for a state whose weight in the map is nil.
        """
        if not self.graph_groups(state):
            return SampleSummary(map_T_base=np.array(self.problem.odometry_poses), objects=())
        warm = self._solutions.get(state, self._anchor)
        started = time.perf_counter()
        members, rows = self._graph(state)
        result = solve_with_backend(
            self.estimation_problem if error_covariances else self._marginals_only,
            members,
            warm_start=warm,
            with_covariances=True,
            priors=rows,
        )
        self.work.marginal_seconds += time.perf_counter() - started
        self.work.marginal_solves += 1
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
