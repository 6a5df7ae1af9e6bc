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

from collections.abc import Collection, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from objslam_mapper.config import SamplerConfig
from objslam_mapper.inference.association import CLUTTER, Association
from objslam_mapper.inference.screen import ProposalScreen
from objslam_mapper.inference.tracklets import Tracklet


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
        target.move_to(candidate)
        return candidate, candidate_value, True
    return state, value, False


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
    """
    target = screen.target
    moved: list[int] = []
    current = target(state)
    target.move_to(state)  # the candidates differ from it by one object: warm starts
    for group in sorted(state.groups, key=lambda g: (sum(len(target.tracklets[t]) for t in g), g)):
        candidate = Association.of([CLUTTER if t in group else a for t, a in enumerate(state.assignment)])
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
    target.move_to(state)
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
