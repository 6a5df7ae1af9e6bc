"""The chain's start state: a heuristic association the target then improves greedily.

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

:func:`start_state` runs these steps as the sampler's settings say.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from objslam_mapper.config import SamplerConfig
from objslam_mapper.graph.backends import solve_with_backend
from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.graph.solver import GraphSolution
from objslam_mapper.inference.association import CLUTTER, Association
from objslam_mapper.inference.clutter import DISTRACTOR
from objslam_mapper.inference.diagnostics import PhaseProgress
from objslam_mapper.inference.screen import ProposalScreen
from objslam_mapper.inference.target import AssociationTarget
from objslam_mapper.inference.tracklets import Tracklet

logger = logging.getLogger(__name__)


def centroid(tracklets: Sequence[Tracklet], group: Sequence[int]) -> NDArray[np.float64]:
    """Rough xy of an object: its tracklets' positions weighted by their slice counts."""
    weights = np.array([len(tracklets[u]) for u in group], dtype=float)
    return weights @ np.array([tracklets[u].position_xy_m for u in group]) / weights.sum()


def nearest_object(
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
        best = nearest_object(tr, labels, centroids, frames, max_distance_m)
        if best is None:
            members.append([t])
            labels.append(tr.label)
            centroids.append(np.asarray(tr.position_xy_m))
            frames.append(set(tr.frame_indices))
        else:
            members[best].append(t)
            centroids[best] = centroid(tracklets, members[best])
            frames[best] |= set(tr.frame_indices)
    return Association.from_groups(len(tracklets), members)


def _take_if_better(
    screen: ProposalScreen, state: Association, value: float, candidate: Association, screen_margin_nats: float
) -> tuple[Association, float, bool]:
    """``candidate`` and its target value if the target prefers it to ``state`` (worth ``value``),
    else ``state``; a candidate the screen judges worse by more than the margin is not solved."""
    target = screen.target
    if screen(state, candidate) < -screen_margin_nats:
        return state, value, False
    candidate_value = target(candidate)
    if candidate_value > value:
        target.move_to(candidate, candidate_value)
        return candidate, candidate_value, True
    return state, value, False


def _only_like_their_class(target: AssociationTarget, state: Association, tracklets: Collection[int]) -> bool:
    """Whether every clutter thing of ``state`` holding one of ``tracklets`` is a distractor
    shaped like its class (:attr:`.clutter.Component.unlike_class` false)."""
    wanted = set(tracklets)
    things = [th for th in target.clutter_things(state) if wanted.intersection(th)]
    return all(
        component.kind == DISTRACTOR and not component.unlike_class
        for component in (target.thing_component(th) for th in things)
    )


def clear_start_objects(
    screen: ProposalScreen, state: Association, screen_margin_nats: float = 20.0
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

    An object whose tracklets would be clutter only as distractors shaped like its class
    stays: that is the chain's question, not the start's. A distractor's size is free, so
    with a drifting odometry such a thing often fits better than the object whose size its
    class pins; each one cleared then frees the odometry's scale a little more, and on a
    ``loop`` bag the pass cleared all 26 start objects, into a state (every real object a
    distractor, the distance scale 6 % off) 40 nats below the right map and 190 below any
    state one object closer to it, which the chain never left.
    """
    target = screen.target
    moved: list[int] = []
    current = target(state)
    target.move_to(state, current)  # the candidates differ from it by one object: warm starts
    for group in sorted(state.groups, key=lambda g: (sum(len(target.tracklets[t]) for t in g), g)):
        candidate = Association.of([CLUTTER if t in group else a for t, a in enumerate(state.assignment)])
        if _only_like_their_class(target, candidate, group):
            continue
        state, current, taken = _take_if_better(screen, state, current, candidate, screen_margin_nats)
        if taken:
            moved.extend(group)
    return state, sorted(moved)


def recall_start_clutter(
    screen: ProposalScreen, state: Association, max_distance_m: float, screen_margin_nats: float = 20.0
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
    target = screen.target
    tracklets = target.tracklets
    moved: list[int] = []
    current = target(state)
    target.move_to(state, current)
    for t in sorted(state.clutter, key=lambda u: (-len(tracklets[u]), u)):
        groups = state.groups
        best = nearest_object(
            tracklets[t],
            [tracklets[g[0]].label for g in groups],
            [centroid(tracklets, g) for g in groups],
            [{f for u in g for f in tracklets[u].frame_indices} for g in groups],
            max_distance_m,
        )
        if best is None:
            continue
        candidate = Association.of([best if u == t else a for u, a in enumerate(state.assignment)])
        state, current, taken = _take_if_better(screen, state, current, candidate, screen_margin_nats)
        if taken:
            moved.append(t)
    return state, sorted(moved)


@dataclass(frozen=True)
class GreedyOptions:
    gate_probability: float = 0.99  # chi-square gate of the Mahalanobis distance (2 dof)
    # A tracklet whose object the solve places no better than this (the larger xy standard
    # deviation) says nothing about which object it is: it stays an object of its own, left
    # out of the later solves (greedy_association).
    max_location_stddev_m: float = 1.0

    @property
    def gate_chi2(self) -> float:
        # Chi-square with 2 dof has the closed-form quantile -2 ln(1 - p).
        return -2.0 * math.log1p(-self.gate_probability)


def measurement_groups(tracklets: Sequence[Tracklet], groups: Sequence[Sequence[int]]) -> list[NDArray[np.int64]]:
    """Each group's measurement indices (its tracklets' slices), sorted."""
    return [np.sort(np.concatenate([tracklets[t].measurement_indices for t in g])).astype(np.int64) for g in groups]


def no_association(tracklets: Sequence[Tracklet]) -> Association:
    """Every tracklet its own object; nothing is clutter."""
    return Association.of(range(len(tracklets)))


def _mahalanobis2_xy(a_m: NDArray, a_cov: NDArray | None, b_m: NDArray, b_cov: NDArray | None) -> float:
    if a_cov is None or b_cov is None:
        return math.inf
    cov = np.asarray(a_cov)[:2, :2] + np.asarray(b_cov)[:2, :2]
    diff = np.asarray(a_m)[:2] - np.asarray(b_m)[:2]
    if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(diff))):
        return math.inf
    try:
        return float(diff @ np.linalg.solve(cov, diff))
    except np.linalg.LinAlgError:
        return math.inf


def _located_within(cov: NDArray | None, stddev_m: float) -> bool:
    """Whether the xy covariance's larger standard deviation is at most ``stddev_m``."""
    if cov is None:
        return False
    xy = np.asarray(cov)[:2, :2]
    return bool(np.all(np.isfinite(xy)) and np.linalg.eigvalsh(xy).max() <= stddev_m**2)


def greedy_association(
    problem: GraphProblem,
    tracklets: Sequence[Tracklet],
    options: GreedyOptions | None = None,
    progress: PhaseProgress | None = None,
) -> Association:
    """Greedy nearest-neighbour association with Mahalanobis gating (module docstring).

    A tracklet the solve cannot place (no optimum, or its object's xy standard deviation
    above ``max_location_stddev_m``) joins nothing and is left out of the later solves, an
    object of its own in the result. Gated on, such a tracklet joined any object of its
    class, its covariance being metres to 10^18 m wide, and kept in the solves it pulled them
    astray: on a pinhole render of `clutter`, from the 17th of 75 tracklets on every solve
    placed its objects 10^14 m away, and the start joined what the chain could not undo.
    """
    options = options or GreedyOptions()
    gate = options.gate_chi2
    # The decisions read the posterior marginals only: the error covariances would cost a dense
    # inverse per tracklet (minutes on a 900-pose bag) and change nothing here.
    solver = problem.solver
    problem = dataclasses.replace(
        problem,
        solver=dataclasses.replace(
            solver, error_covariance=dataclasses.replace(solver.error_covariance, enabled=False)
        ),
    )
    report = progress or (lambda _phase, _done, _total: None)
    order = sorted(range(len(tracklets)), key=lambda t: (tracklets[t].frame_indices[0], t))
    groups: list[list[int]] = []
    frames: list[set[int]] = []
    unplaced: list[list[int]] = []
    warm: GraphSolution | None = None
    for done, t in enumerate(order):
        report("association", done, len(order))
        tracklet = tracklets[t]
        seen = set(tracklet.frame_indices)
        candidates = [
            j for j, g in enumerate(groups) if tracklets[g[0]].label == tracklet.label and not frames[j] & seen
        ]
        if not candidates:
            groups.append([t])
            frames.append(set(seen))
            continue
        solution = solve_with_backend(
            problem,
            measurement_groups(tracklets, [*groups, [t]]),
            warm_start=warm,
            with_covariances=True,
        )
        new = solution.objects[-1] if np.isfinite(solution.log_evidence) else None
        if new is None or not _located_within(new.location_cov, options.max_location_stddev_m):
            logger.debug("greedy: the solve does not place tracklet %d; it stays an object of its own", t)
            unplaced.append([t])
            continue
        # A solve that stopped short of convergence still gates: the chain's target takes such
        # values too. On `clutter` seed 13 the solve with tracklet 17 stalled (its
        # evidence 1500 nats above a cold solve's); skipping it kept that tracklet's object
        # in every later solve, each stalled too, and every later tracklet stayed an object
        # of its own (58 objects of 117 tracklets with this rule; nearly 117 without).
        if not solution.converged:
            logger.debug("greedy: the solve with tracklet %d did not converge; gating on it", t)
        warm = solution
        best, best_d2 = None, gate
        for j in candidates:
            obj = solution.objects[j]
            if not _located_within(obj.location_cov, options.max_location_stddev_m):
                continue  # an object placed nowhere in particular would take anything
            d2 = _mahalanobis2_xy(new.location_m, new.location_cov, obj.location_m, obj.location_cov)
            if d2 <= best_d2:
                best, best_d2 = j, d2
        if best is None:
            groups.append([t])
            frames.append(set(seen))
        else:
            groups[best].append(t)
            frames[best] |= seen
    report("association", len(order), len(order))
    return Association.from_groups(len(tracklets), [*groups, *unplaced])


class StartState(NamedTuple):
    """The start of the chain and how it was reached."""

    state: Association
    first_objects: int  # objects of the nearest-neighbour start
    clutter_tracklets: int  # tracklets the target preferred as clutter alone
    cleared: list[int]  # tracklets of start objects moved to clutter
    recalled: list[int]  # clutter tracklets moved into their nearest object


def start_state(screen: ProposalScreen, config: SamplerConfig) -> StartState:
    """The chain's start (module docstring); with ``initial_clutter`` off (or no clutter model), the
    plain nearest-neighbour start."""
    target = screen.target
    tracklets = target.tracklets
    improve = config.initial_clutter and config.clutter.enabled
    in_clutter = {t for t in range(len(tracklets)) if target.prefers_clutter(t)} if improve else set()
    state = initial_association(tracklets, config.initial_merge_distance_m, in_clutter)
    first_objects = state.n_objects
    cleared: list[int] = []
    recalled: list[int] = []
    if improve:
        state, cleared = clear_start_objects(screen, state)
        state, recalled = recall_start_clutter(screen, state, config.initial_merge_distance_m)
        if recalled:  # an object a recalled tracklet joined may now be clutter as a whole
            state, more = clear_start_objects(screen, state)
            cleared += more
    return StartState(state, first_objects, len(in_clutter), cleared, recalled)


def random_association(tracklets: Sequence[Tracklet], rng: np.random.Generator, allow_clutter: bool) -> Association:
    """A random association: tracklets in random order, each to clutter (one in five, when
    allowed), into a random object of its class not seen in its images (half of the rest), or
    a new object."""
    members: list[list[int]] = []
    labels: list[str] = []
    frames: list[set[int]] = []
    assignment = [CLUTTER] * len(tracklets)
    for t in rng.permutation(len(tracklets)):
        tracklet = tracklets[int(t)]
        seen = set(tracklet.frame_indices)
        draw = rng.random()
        if allow_clutter and draw < 0.2:
            continue
        free = [
            j
            for j, (label, images) in enumerate(zip(labels, frames, strict=True))
            if label == tracklet.label and not images & seen
        ]
        if free and draw < 0.6:
            j = free[int(rng.integers(len(free)))]
        else:
            j = len(members)
            members.append([])
            labels.append(tracklet.label)
            frames.append(set())
        members[j].append(int(t))
        frames[j] |= seen
        assignment[int(t)] = j
    return Association.of(assignment)


def dispersed_start(kind: str, screen: ProposalScreen, config: SamplerConfig, rng: np.random.Generator) -> StartState:
    """The start of a chain of the given kind (``sampler.starts``): far apart on purpose, so that
    chains which agree in the end say more than one chain from a good guess."""
    target = screen.target
    tracklets = target.tracklets
    clutter = config.clutter.enabled
    if kind == "heuristic":
        return start_state(screen, config)
    if kind == "singletons":
        state = no_association(tracklets)
    elif kind == "greedy":
        state = greedy_association(target.problem, tracklets)
    elif kind == "clutter":
        state = Association.of([CLUTTER] * len(tracklets)) if clutter else no_association(tracklets)
    elif kind == "random":
        state = random_association(tracklets, rng, clutter)
    else:
        raise ValueError(f"unknown chain start {kind!r}")
    return StartState(state, state.n_objects, len(state.clutter), [], [])
