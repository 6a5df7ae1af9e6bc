"""The data association state J: tracklets partitioned into objects, plus a clutter set.

A state is stored as a canonical label vector: entry ``t`` is the object number of
tracklet ``t``, or ``CLUTTER`` (-1) when the tracklet is explained by the false-alarm
model. Object numbers are assigned in order of each object's first tracklet, so two
states that group the tracklets the same way are equal and hash the same, whatever order
their objects were built in; that is what lets the sampler cache the target per state.

An object only holds tracklets of one class (paper section 3: classes are taken from the
detector, so a red and a green detection are never the same object).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from functools import cached_property

from objslam_mapper.errors import MapperError

CLUTTER = -1


class AssociationError(MapperError, ValueError):
    """An association that is not a valid state for the given tracklets."""


def canonical(assignment: Sequence[int]) -> tuple[int, ...]:
    """Renumber objects in order of first appearance; ``CLUTTER`` stays."""
    renumber: dict[int, int] = {}
    out = []
    for a in assignment:
        if a == CLUTTER:
            out.append(CLUTTER)
            continue
        if a < 0:
            raise AssociationError(f"object numbers must be >= 0 (or {CLUTTER} for clutter), got {a}")
        out.append(renumber.setdefault(a, len(renumber)))
    return tuple(out)


@dataclass(frozen=True)
class Association:
    """One association state J over ``len(assignment)`` tracklets (canonical, hashable)."""

    assignment: tuple[int, ...]

    def __post_init__(self) -> None:
        if canonical(self.assignment) != tuple(self.assignment):
            raise AssociationError(f"assignment is not canonical: {self.assignment} (use Association.of)")

    @classmethod
    def of(cls, assignment: Iterable[int]) -> Association:
        """The state of any labelling (object numbers need not be canonical)."""
        state = object.__new__(cls)
        # Canonical by construction: skip __post_init__'s check (the sampler's hot path).
        object.__setattr__(state, "assignment", canonical(list(assignment)))
        return state

    @classmethod
    def from_groups(cls, n_tracklets: int, groups: Iterable[Iterable[int]]) -> Association:
        """Objects given as groups of tracklet indices; tracklets in no group are clutter."""
        assignment = [CLUTTER] * n_tracklets
        for j, group in enumerate(groups):
            members = list(group)
            if not members:
                raise AssociationError("an object must hold at least one tracklet")
            for t in members:
                if not 0 <= t < n_tracklets:
                    raise AssociationError(f"tracklet index {t} out of range 0..{n_tracklets - 1}")
                if assignment[t] != CLUTTER:
                    raise AssociationError(f"tracklet {t} is in two objects")
                assignment[t] = j
        return cls.of(assignment)

    @property
    def n_tracklets(self) -> int:
        return len(self.assignment)

    @cached_property
    def groups(self) -> tuple[tuple[int, ...], ...]:
        """Tracklet indices of each object, objects in canonical order."""
        members: list[list[int]] = [[] for _ in range(self.n_objects)]
        for t, a in enumerate(self.assignment):
            if a != CLUTTER:
                members[a].append(t)
        return tuple(tuple(m) for m in members)

    @cached_property
    def clutter(self) -> tuple[int, ...]:
        return tuple(t for t, a in enumerate(self.assignment) if a == CLUTTER)

    @cached_property
    def n_objects(self) -> int:
        return max(self.assignment, default=CLUTTER) + 1

    def validate(self, labels: Sequence[str]) -> None:
        """Raise AssociationError unless every object holds tracklets of a single class."""
        if len(labels) != self.n_tracklets:
            raise AssociationError(f"{len(labels)} labels for {self.n_tracklets} tracklets")
        for group in self.groups:
            classes = {labels[t] for t in group}
            if len(classes) > 1:
                raise AssociationError(f"object with tracklets {group} mixes classes {sorted(classes)}")

    def measurement_groups(self, tracklet_measurements: Sequence[Sequence[int]]) -> list[list[int]]:
        """Measurement indices per object (the ``groups`` the factor graph solves for)."""
        return [sorted(m for t in group for m in tracklet_measurements[t]) for group in self.groups]


def _set_partitions(items: Sequence[int]) -> Iterator[list[list[int]]]:
    """Every partition of ``items`` into non-empty blocks (Bell(n) of them)."""
    if not items:
        yield []
        return
    first, rest = items[0], items[1:]
    for partition in _set_partitions(rest):
        yield [[first], *partition]
        for k in range(len(partition)):
            yield [*partition[:k], [first, *partition[k]], *partition[k + 1 :]]


def _class_options(members: Sequence[int], allow_clutter: bool) -> Iterator[tuple[list[list[int]], list[int]]]:
    """(objects, clutter) choices for the tracklets of one class."""
    n = len(members)
    for mask in range(1 << n) if allow_clutter else (0,):
        clutter = [members[i] for i in range(n) if mask >> i & 1]
        kept = [members[i] for i in range(n) if not mask >> i & 1]
        for partition in _set_partitions(kept):
            yield partition, clutter


def enumerate_associations(labels: Sequence[str], allow_clutter: bool = True) -> list[Association]:
    """Every valid state for tracklets of the given classes (small problems only).

    The count is the product over classes of Bell(k + 1) with clutter, Bell(k) without,
    for a class of k tracklets.
    """
    by_class: dict[str, list[int]] = {}
    for t, label in enumerate(labels):
        by_class.setdefault(label, []).append(t)
    per_class = [list(_class_options(members, allow_clutter)) for members in by_class.values()]
    states = []
    for combo in itertools.product(*per_class):
        groups = [g for partition, _clutter in combo for g in partition]
        states.append(Association.from_groups(len(labels), groups))
    return states
