"""Do the chains agree? Rank-normalized split R-hat and bulk ESS (Vehtari et al. 2021) by ArviZ.

Three kinds of quantities are traced over every chain's kept draws: the log target, the
number of objects of the state, and, for every identity the map reports (objects and
rejected ones), whether the draw yields it (0 or 1). For each the chains' R-hat and bulk
effective sample size are computed; and each reported identity's existence probability is
computed per chain. The chains agree (``converged``) when every R-hat is at most
``sampler.rhat_max`` (1.01 by default) and every reported identity is on the same side of
1/2 in every chain, i.e. each chain alone would have put the same identities in the map.

Chains that visit the same states, but switch between them too rarely, are short of draws,
not stuck: ``draws_needed`` then says how many kept draws per chain would give every
quantity a bulk ESS of 100 per chain (Vehtari et al. 2021 trust R-hat from there), the ESS
growing in proportion to the draws at the mixing seen. Where the ESS is there already but
R-hat is still above the threshold (on ``small``, 1.01 with a bulk ESS of 402 over four
chains), it says how many would bring R-hat down, its excess R-hat^2 - 1 falling as 1/ESS:
for four AR(1) chains of one distribution (R-hat^2 - 1) x bulk ESS stays near 8.5 from 500
to 8000 draws, so at a bulk ESS of 400 the noise alone puts R-hat at about 1.01.

Where a chain holds a state no other chain visits (an identity on the other side of 1/2, an
R-hat that is infinite, or a chain none of whose kept states another chain kept) more draws
of the same chains need not meet, and it is None. The last is checked on the states
themselves: on ``twins`` seed 15 one chain kept two states 17 nats below every state of the
others, with the same identities, and the estimate had called it short of 270000 draws.
Such a chain is also said to have stopped most of its graph solves short where it did
(``UNCONVERGED_SHARE``): its values are then where those solves stopped, and it can be
stuck on a value, not on a state.

A quantity that is the same constant in every draw of every chain has no R-hat in ArviZ
(0/0); the chains agree on it exactly, so it counts as 1. One that is constant within each
chain but not across them (each chain stuck in its own state) has infinite R-hat, and an
effective sample size of one draw per chain. One chain has no R-hat at all: ``converged``
is then None.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from objslam_mapper.inference.association import Association
from objslam_mapper.inference.chains import ChainOutcome

LOG_TARGET = "log_target"
OBJECTS = "objects"
ESS_PER_CHAIN = 100  # bulk ESS per chain before R-hat is trusted (Vehtari et al. 2021, section 4)
# A chain apart from the others most of whose graph solves stopped short is named as such:
# its states' values are not their optima, so it can hold a state whose value was a lucky
# solve and refuse every move from it (docs/method.md, "Solves that do not converge").
UNCONVERGED_SHARE = 0.5


def identity_name(map_id: int) -> str:
    return f"identity_{map_id}"


@dataclass(frozen=True)
class QuantityDiagnostics:
    rhat: float  # 1.0 where every draw of every chain is the same; inf where the chains cannot be compared
    ess_bulk: float


@dataclass(frozen=True)
class Convergence:
    """Agreement of the chains of one map (module docstring)."""

    chains: int
    draws: int  # kept draws per chain
    quantities: dict[str, QuantityDiagnostics] = field(default_factory=dict)
    existence_by_chain: dict[int, tuple[float, ...]] = field(default_factory=dict)  # map id -> P per chain
    rhat_max: float | None = None
    ess_min: float | None = None
    converged: bool | None = None  # None: one chain
    disagreements: tuple[str, ...] = ()  # why not, one line each
    draws_needed: int | None = None  # kept draws per chain for ESS_PER_CHAIN (module docstring)

    def spread(self, map_id: int) -> float:
        """Largest minus smallest per-chain existence probability of an identity."""
        values = self.existence_by_chain.get(map_id, ())
        return float(max(values) - min(values)) if values else 0.0

    def to_dict(self) -> dict[str, object]:
        return {
            "chains": self.chains,
            "draws_per_chain": self.draws,
            "converged": self.converged,
            "rhat_max": _plain(self.rhat_max),
            "ess_bulk_min": _plain(self.ess_min),
            "disagreements": list(self.disagreements),
            "draws_needed": self.draws_needed,
            "quantities": {
                name: {"rhat": _plain(q.rhat), "ess_bulk": _plain(q.ess_bulk)} for name, q in self.quantities.items()
            },
            "existence_by_chain": {
                int(k): [round(p, 4) for p in v] for k, v in sorted(self.existence_by_chain.items())
            },
        }


def _plain(value: float | None) -> float | str | None:
    if value is None:
        return None
    if math.isinf(value):
        return "inf"
    return round(float(value), 4)


def rhat_and_ess(draws: NDArray[np.float64]) -> QuantityDiagnostics:
    """Rank-normalized split R-hat and bulk ESS of (chains, draws) by ArviZ (module docstring)."""
    draws = np.asarray(draws, dtype=float)
    if np.all(draws == draws.flat[0]):
        return QuantityDiagnostics(1.0, float(draws.size))
    if np.all(draws == draws[:, :1]):  # each chain stuck in its own value: no within-chain variance
        return QuantityDiagnostics(math.inf, float(draws.shape[0]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ArviZ announces its refactor, and warns on 0/0 between chains
        import arviz

        rhat = float(arviz.rhat(draws, method="rank"))
        ess = float(arviz.ess(draws, method="bulk"))
    if not math.isfinite(rhat):
        rhat = math.inf  # constant within chains but not between them
    return QuantityDiagnostics(rhat, ess if math.isfinite(ess) else 0.0)


def chain_traces(
    outcomes: Sequence[ChainOutcome], yields: Sequence[frozenset[int]], map_ids: Sequence[int]
) -> dict[str, NDArray[np.float64]]:
    """(chains, draws) arrays of the log target, the objects and each identity's indicator.

    ``yields`` are the ids each sample yields, in the pooled order of the chains' samples
    (chain by chain, each chain's distinct kept states in order).
    """
    traces: dict[str, list[list[float]]] = {LOG_TARGET: [], OBJECTS: []}
    traces.update({identity_name(i): [] for i in map_ids})
    log_target = _one_value_per_state(outcomes)
    offset = 0
    for outcome in outcomes:
        index: dict[Association, int] = {state: offset + k for k, state in enumerate(outcome.result.counts)}
        offset += len(index)
        trace = outcome.result.trace
        traces[LOG_TARGET].append([log_target[state] for state in trace])
        traces[OBJECTS].append([float(state.n_objects) for state in trace])
        yielded = [yields[index[state]] for state in trace]
        for i in map_ids:
            traces[identity_name(i)].append([float(i in y) for y in yielded])
    return {name: np.array(rows, dtype=float) for name, rows in traces.items()}


def _one_value_per_state(outcomes: Sequence[ChainOutcome]) -> dict[Association, float]:
    """The log target of each state the chains kept: the mean of what the chains computed.

    The target is a function of the association, but each chain solves a state from its own
    warm start, to the solver's tolerance: two chains in the same state report values a few
    1e-8 nats apart, which R-hat would take for chains that never meet.
    """
    values: dict[Association, list[float]] = {}
    for outcome in outcomes:
        for state, value in zip(outcome.result.trace, outcome.result.log_targets, strict=True):
            values.setdefault(state, []).append(value)
    return {state: float(np.mean(v)) for state, v in values.items()}


def chain_convergence(
    outcomes: Sequence[ChainOutcome], yields: Sequence[frozenset[int]], map_ids: Sequence[int], rhat_max: float
) -> Convergence:
    """The agreement of the chains (module docstring) on the identities ``map_ids`` of the map."""
    traces = chain_traces(outcomes, yields, map_ids)
    chains, draws = traces[LOG_TARGET].shape
    by_chain = {i: tuple(float(p) for p in traces[identity_name(i)].mean(axis=1)) for i in map_ids}
    if chains < 2:
        return Convergence(chains, draws, existence_by_chain=by_chain)
    quantities = {name: rhat_and_ess(values) for name, values in traces.items()}
    disagreements = [
        f"R-hat of {name} is {q.rhat:.3f} (at most {rhat_max})" for name, q in quantities.items() if q.rhat > rhat_max
    ]
    split = False
    for i, values in by_chain.items():
        if len({p > 0.5 for p in values}) > 1:
            split = True
            shown = ", ".join(f"{p:.2f}" for p in values)
            disagreements.append(f"identity {i} is in the map of some chains and not of others (P by chain: {shown})")
    rhat_worst = max(q.rhat for q in quantities.values())
    ess_min = min(q.ess_bulk for q in quantities.values())
    needed = None
    apart = _chains_apart(outcomes) if disagreements else []
    for k in apart:
        disagreements.append(f"chain {k} kept only states no other chain kept")
        work = outcomes[k].work
        if work.solves and work.unconverged_solves >= UNCONVERGED_SHARE * work.solves:
            disagreements.append(
                f"chain {k}: {work.unconverged_solves} of its {work.solves} graph solves stopped before converging, "
                "so its states' values are where those solves stopped, which depends on where each one started"
            )
    if disagreements and not split and not apart and math.isfinite(rhat_worst) and ess_min > 0.0:
        if ess_min < ESS_PER_CHAIN * chains:
            needed = draws_needed(draws, chains, ess_min)
            disagreements.append(
                f"the chains visit the same states but switch between them rarely: about {needed} kept draws per "
                f"chain would give a bulk ESS of {ESS_PER_CHAIN} per chain (now {ess_min / chains:.0f})"
            )
        elif rhat_worst > rhat_max:
            needed = draws_for_rhat(draws, rhat_worst, rhat_max)
            disagreements.append(
                f"the chains agree with a bulk ESS of {ess_min / chains:.0f} per chain, but R-hat is still "
                f"{rhat_worst:.4f}: about {needed} kept draws per chain would bring it to {rhat_max}"
            )
    return Convergence(
        chains,
        draws,
        quantities,
        by_chain,
        rhat_max=rhat_worst,
        ess_min=ess_min,
        converged=not disagreements,
        disagreements=tuple(disagreements),
        draws_needed=needed,
    )


def _chains_apart(outcomes: Sequence[ChainOutcome]) -> list[int]:
    """The chains none of whose kept states another chain kept."""
    kept = [set(outcome.result.counts) for outcome in outcomes]
    return [k for k, mine in enumerate(kept) if not any(mine & theirs for j, theirs in enumerate(kept) if j != k)]


def draws_needed(draws: int, chains: int, ess_min: float) -> int:
    """Kept draws per chain for a bulk ESS of ``ESS_PER_CHAIN`` per chain, the ESS growing in
    proportion to the draws; rounded up to two significant digits."""
    return _two_digits_up(draws * ESS_PER_CHAIN * chains / ess_min)


def draws_for_rhat(draws: int, rhat: float, rhat_max: float) -> int:
    """Kept draws per chain for an R-hat of ``rhat_max`` where the chains already agree and
    mix: there R-hat^2 - 1 is the between-chain share of the variance, which falls as 1/ESS,
    so as 1/draws; rounded up to two significant digits."""
    return _two_digits_up(draws * (rhat**2 - 1.0) / (rhat_max**2 - 1.0))


def _two_digits_up(raw: float) -> int:
    step = 10 ** max(0, math.floor(math.log10(raw)) - 1)
    return int(math.ceil(raw / step) * step)
