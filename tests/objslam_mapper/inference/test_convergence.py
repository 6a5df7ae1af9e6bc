"""The chains' agreement: R-hat and bulk ESS against the paper's formulas, and the verdict.

The reference below is written from Vehtari, Gelman, Simpson, Carpenter and Bürkner (2021),
"Rank-normalization, folding, and localization: an improved R-hat", sections 3-4 and
appendix A, independently of ArviZ (which :mod:`objslam_mapper.inference.convergence` calls).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ndtri
from scipy.stats import rankdata

from objslam_mapper.inference.convergence import chain_convergence, draws_for_rhat, rhat_and_ess
from objslam_mapper.inference.diagnostics import Work


def _split(draws: np.ndarray) -> np.ndarray:
    half = draws.shape[1] // 2
    return np.vstack([draws[:, :half], draws[:, -half:]])


def _rank_normalized(draws: np.ndarray) -> np.ndarray:
    ranks = rankdata(draws, method="average").reshape(draws.shape)
    return ndtri((ranks - 0.375) / (draws.size + 0.25))


def _basic_rhat(chains: np.ndarray) -> float:
    n = chains.shape[1]
    within = chains.var(axis=1, ddof=1).mean()
    between = n * chains.mean(axis=1).var(ddof=1)
    return float(np.sqrt(((n - 1) / n * within + between / n) / within))


def _ess(chains: np.ndarray) -> float:
    """Geyer's initial monotone sequence over chains, as Stan computes it (paper eqs. 10-11,
    appendix A): paired autocorrelations summed while positive, made monotone, and the first
    positive even-lag term past the cut added once."""
    m, n = chains.shape
    centred = chains - chains.mean(axis=1, keepdims=True)
    autocov = np.array([[np.dot(c[: n - t], c[t:]) / n for t in range(n)] for c in centred])
    within = autocov[:, 0].mean() * n / (n - 1)
    var_plus = within * (n - 1) / n + chains.mean(axis=1).var(ddof=1)
    rho = 1.0 - (within - autocov.mean(axis=0)) / var_plus
    kept = np.zeros(n)
    kept[0], kept[1] = 1.0, rho[1]
    even, odd, t = 1.0, rho[1], 1
    while t < n - 3 and even + odd > 0:
        even, odd = rho[t + 1], rho[t + 2]
        if even + odd >= 0:
            kept[t + 1], kept[t + 2] = even, odd
        t += 2
    last = t - 2
    if even > 0:
        kept[last + 1] = even
    for t in range(1, last - 1, 2):
        if kept[t + 1] + kept[t + 2] > kept[t - 1] + kept[t]:
            kept[t + 1] = kept[t + 2] = (kept[t - 1] + kept[t]) / 2
    tau = -1.0 + 2.0 * kept[: last + 1].sum() + kept[last + 1]
    return float(m * n / max(tau, 1.0 / np.log10(m * n)))


def reference_rhat(draws: np.ndarray) -> float:
    split = _split(draws)
    folded = np.abs(split - np.median(split))
    return max(_basic_rhat(_rank_normalized(split)), _basic_rhat(_rank_normalized(folded)))


def reference_bulk_ess(draws: np.ndarray) -> float:
    return _ess(_rank_normalized(_split(draws)))


def ar1_chains(rng, chains: int, draws: int, phi: float, offsets) -> np.ndarray:
    noise = rng.normal(size=(chains, draws))
    out = np.empty_like(noise)
    out[:, 0] = noise[:, 0]
    for t in range(1, draws):
        out[:, t] = phi * out[:, t - 1] + np.sqrt(1 - phi**2) * noise[:, t]
    return out + np.asarray(offsets, dtype=float)[:, None]


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    chains=st.integers(2, 5),
    draws=st.integers(40, 400),
    phi=st.floats(0.0, 0.95),
    shift=st.floats(0.0, 2.0),
)
def test_rhat_and_bulk_ess_match_the_papers_formulas(seed, chains, draws, phi, shift):
    rng = np.random.default_rng(seed)
    offsets = np.zeros(chains)
    offsets[0] = shift  # one chain apart from the others: R-hat must see it
    draws_array = ar1_chains(rng, chains, draws, phi, offsets)
    got = rhat_and_ess(draws_array)
    assert got.rhat == pytest.approx(reference_rhat(draws_array), rel=1e-9)
    assert got.ess_bulk == pytest.approx(reference_bulk_ess(draws_array), rel=1e-9)


def test_chains_from_one_distribution_agree_and_chains_apart_do_not():
    rng = np.random.default_rng(0)
    same = rhat_and_ess(ar1_chains(rng, 4, 1000, 0.5, [0, 0, 0, 0]))
    assert same.rhat < 1.01 and 1000 < same.ess_bulk < 4000  # AR(1), phi 0.5: about a third of the draws
    apart = rhat_and_ess(ar1_chains(rng, 4, 1000, 0.5, [0, 0, 0, 1]))
    assert apart.rhat > 1.05 and apart.ess_bulk < 100  # one chain a stddev off: far past 1.01


def test_indicators_that_never_change_count_as_agreeing_or_as_apart():
    assert rhat_and_ess(np.ones((3, 50))).rhat == 1.0  # the same everywhere: the chains agree exactly
    stuck = np.vstack([np.ones(50), np.ones(50), np.zeros(50)])  # each chain constant, one apart
    assert rhat_and_ess(stuck).rhat == float("inf")


class _Result:
    def __init__(self, trace, log_targets):
        self.trace = tuple(trace)
        self.log_targets = tuple(log_targets)
        self.counts = {state: self.trace.count(state) for state in dict.fromkeys(self.trace)}


class _Outcome:
    def __init__(self, trace, log_targets, work=None):
        self.result = _Result(trace, log_targets)
        self.work = work or Work()


class _State:
    def __init__(self, name, n_objects):
        self.name, self.n_objects = name, n_objects

    def __hash__(self):
        return hash(self.name)

    def __eq__(self, other):
        return self.name == other.name


A, B = _State("a", 2), _State("b", 3)


def _yields(outcomes, of_state):
    return [of_state[state.name] for outcome in outcomes for state in outcome.result.counts]


def test_chains_that_mix_between_two_states_converge():
    rng = np.random.default_rng(1)
    outcomes = []
    for _ in range(3):
        trace = [A if x else B for x in rng.random(400) < 0.7]
        # Each chain solved the states from its own warm start: a few 1e-9 nats apart.
        outcomes.append(_Outcome(trace, [(10.0 if s is A else 9.0) + 1e-9 * rng.random() for s in trace]))
    got = chain_convergence(outcomes, _yields(outcomes, {"a": frozenset({0}), "b": frozenset({0, 1})}), [0, 1], 1.01)
    assert got.converged, got.disagreements
    assert got.existence_by_chain[0] == (1.0, 1.0, 1.0)
    assert all(abs(p - 0.3) < 0.1 for p in got.existence_by_chain[1])
    assert set(got.quantities) == {"log_target", "objects", "identity_0", "identity_1"}


def test_a_chain_stuck_in_another_state_is_named():
    outcomes = [_Outcome([A] * 200, [10.0] * 200), _Outcome([A] * 200, [10.0] * 200), _Outcome([B] * 200, [9.0] * 200)]
    got = chain_convergence(outcomes, _yields(outcomes, {"a": frozenset({0}), "b": frozenset({0, 1})}), [0, 1], 1.01)
    assert got.converged is False and got.rhat_max == float("inf")
    assert got.existence_by_chain[1] == (0.0, 0.0, 1.0) and got.spread(1) == 1.0
    assert any("identity 1 is in the map of some chains and not of others" in d for d in got.disagreements)
    assert got.to_dict()["rhat_max"] == "inf"


def test_one_chain_has_no_verdict():
    outcomes = [_Outcome([A, B] * 50, [10.0, 9.0] * 50)]
    got = chain_convergence(outcomes, _yields(outcomes, {"a": frozenset({0}), "b": frozenset()}), [0], 1.01)
    assert got.converged is None and got.rhat_max is None and got.existence_by_chain[0] == (0.5,)


def test_chains_that_switch_rarely_say_how_many_draws_they_need():
    """Every chain visits both states, but in long runs: short of draws, not stuck."""
    runs = ([A] * 90 + [B] * 60 + [A] * 50, [B] * 70 + [A] * 130, [A] * 120 + [B] * 80)
    outcomes = [_Outcome(trace, [10.0 if s is A else 9.0 for s in trace]) for trace in runs]
    got = chain_convergence(outcomes, _yields(outcomes, {"a": frozenset({0}), "b": frozenset({0})}), [0], 1.01)
    assert got.converged is False and 0.0 < got.ess_min < 300.0
    # ESS grows with the draws: 200 draws per chain gave ess_min over 3 chains, 100 per chain wanted.
    assert got.draws_needed == pytest.approx(200 * 300 / got.ess_min, rel=0.05)
    assert got.draws_needed > 200
    assert any(f"about {got.draws_needed} kept draws per chain" in d for d in got.disagreements)
    assert got.to_dict()["draws_needed"] == got.draws_needed


def _sticky(rng, draws: int, switch: float) -> list:
    """A chain between A and B that switches with probability ``switch`` per step."""
    in_a, trace = rng.random() < 0.5, []
    for _ in range(draws):
        in_a ^= bool(rng.random() < switch)
        trace.append(A if in_a else B)
    return trace


def test_chains_with_enough_ess_but_r_hat_above_the_threshold_say_how_many_draws_they_need():
    """Four chains of one distribution with a bulk ESS just over 100 per chain: R-hat 1.017,
    no identity split, no chain apart; short of draws for R-hat, not stuck."""
    rng = np.random.default_rng(1)
    outcomes = [_Outcome(t, [10.0 if s is A else 9.0 for s in t]) for t in (_sticky(rng, 2000, 0.05) for _ in range(4))]
    got = chain_convergence(outcomes, _yields(outcomes, {"a": frozenset({0}), "b": frozenset({0})}), [0], 1.01)
    assert got.converged is False and got.ess_min >= 400 and got.rhat_max > 1.01
    assert got.draws_needed == draws_for_rhat(2000, got.rhat_max, 1.01) > 2000
    assert any(f"about {got.draws_needed} kept draws per chain would bring it to 1.01" in d for d in got.disagreements)


def test_r_hat_excess_falls_as_one_over_the_ess():
    """What the estimate above rests on: for chains of one distribution, (R-hat^2 - 1) x bulk
    ESS does not change with the chains' length."""
    rng = np.random.default_rng(2)
    products = []
    for draws in (1000, 4000):
        runs = [rhat_and_ess(ar1_chains(rng, 4, draws, 0.95, [0, 0, 0, 0])) for _ in range(60)]
        products.append(np.mean([q.rhat**2 - 1 for q in runs]) * np.mean([q.ess_bulk for q in runs]))
    assert 0.7 < products[1] / products[0] < 1.4


def test_a_chain_whose_states_no_other_chain_kept_is_stuck_not_short_of_draws():
    """Same identities, so no identity splits the chains and R-hat is finite; but the third
    chain moves between two states of its own (as on twins seed 15: 17 nats below)."""
    c, d = _State("c", 2), _State("d", 3)
    runs = ([A] * 90 + [B] * 60 + [A] * 50, [B] * 70 + [A] * 130, [c] * 100 + [d] * 50 + [c] * 50)
    outcomes = [_Outcome(t, [{"a": 10.0, "b": 9.0, "c": 0.0, "d": 0.5}[s.name] for s in t]) for t in runs]
    same = {"a": frozenset({0}), "b": frozenset({0}), "c": frozenset({0}), "d": frozenset({0})}
    got = chain_convergence(outcomes, _yields(outcomes, same), [0], 1.01)
    assert got.converged is False and np.isfinite(got.rhat_max)
    assert got.draws_needed is None
    assert "chain 2 kept only states no other chain kept" in got.disagreements
    assert not any("switch between them rarely" in d for d in got.disagreements)


def test_no_count_of_draws_is_promised_to_chains_that_hold_apart_states():
    stuck = [_Outcome([A] * 200, [10.0] * 200), _Outcome([A] * 200, [10.0] * 200), _Outcome([B] * 200, [9.0] * 200)]
    got = chain_convergence(stuck, _yields(stuck, {"a": frozenset({0}), "b": frozenset({0, 1})}), [0, 1], 1.01)
    assert got.converged is False and got.draws_needed is None
    rng = np.random.default_rng(1)
    mixed = [
        _Outcome(t, [10.0 if s is A else 9.0 for s in t])
        for t in ([A if x else B for x in rng.random(400) < 0.7] for _ in range(3))
    ]
    got = chain_convergence(mixed, _yields(mixed, {"a": frozenset({0}), "b": frozenset({0, 1})}), [0, 1], 1.01)
    assert got.converged and got.draws_needed is None


@pytest.mark.parametrize(("unconverged", "named"), [(60, True), (50, True), (49, False), (0, False)])
def test_a_chain_apart_whose_solves_mostly_stopped_short_is_said_to_be(unconverged, named):
    """Its values are where its solves stopped (as on a pinhole render of clutter: a chain
    held a state worth 4127 nats in the chain and 1700 solved again); from half of them on."""
    stopped = Work(solves=100, unconverged_solves=unconverged)
    outcomes = [
        _Outcome([A] * 200, [10.0] * 200, Work(solves=100, unconverged_solves=90)),  # not apart: not named
        _Outcome([A] * 200, [10.0] * 200),
        _Outcome([B] * 200, [9.0] * 200, stopped),
    ]
    got = chain_convergence(outcomes, _yields(outcomes, {"a": frozenset({0}), "b": frozenset({0, 1})}), [0, 1], 1.01)
    lines = [d for d in got.disagreements if "graph solves stopped before converging" in d]
    expected = (
        f"chain 2: {unconverged} of its 100 graph solves stopped before converging, so its states' values are "
        "where those solves stopped, which depends on where each one started"
    )
    assert lines == ([expected] if named else [])
