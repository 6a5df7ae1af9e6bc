"""A target normalized by enumeration: what the sampler's visit frequencies are tested against."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from objslam_mapper.inference.association import Association
from objslam_mapper.inference.chain import LogTarget
from objslam_mapper.inference.moves import logsumexp


@dataclass(frozen=True)
class ExactDistribution:
    """A target normalized by enumeration (for tests and tiny problems)."""

    states: tuple[Association, ...]
    probabilities: NDArray[np.float64] = field(repr=False)

    @classmethod
    def of(cls, states: Sequence[Association], log_target: LogTarget) -> ExactDistribution:
        logs = np.array([log_target(s) for s in states])
        return cls(tuple(states), np.exp(logs - logsumexp(logs)))

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
