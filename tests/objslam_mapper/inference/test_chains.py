"""Several chains from dispersed starts: seeds, starts, pooling, and the map they agree on."""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
import pytest

from objslam_mapper.config import DetectionConfig, SamplerConfig
from objslam_mapper.inference.algorithm1 import MapOptions, build_from_samples
from objslam_mapper.inference.association import CLUTTER
from objslam_mapper.inference.chains import ChainSpec, InProcess, chain_specs, run_chain_task
from objslam_mapper.inference.diagnostics import Work
from objslam_mapper.inference.infer import finish, infer_map, prepare
from objslam_mapper.inference.screen import ProposalScreen
from objslam_mapper.inference.start import dispersed_start, greedy_association, initial_association, start_state
from objslam_mapper.inference.target import AssociationTarget, TargetOptions
from objslam_mapper.inference.tracklets import tracklets_of_problem
from tests.objslam_mapper.association_scenes import problem_of, simulate

# Seed 3: its chains keep several states (the pooling tests need weights with work to do).
CHAINS = SamplerConfig(samples=300, burn_in=100, chains=3, seed=3, detection=DetectionConfig(max_range_m=3.5))


@pytest.fixture(scope="module")
def problem():
    return problem_of(simulate())


@pytest.fixture(scope="module")
def built(problem):
    return infer_map(problem, CHAINS)


def _without_timings(built):
    return dataclasses.replace(built, diagnostics={k: v for k, v in built.diagnostics.items() if k != "timings_s"})


def test_chain_specs_take_the_starts_in_turn_then_random_ones():
    config = dataclasses.replace(CHAINS, chains=6, seed=7)
    specs = chain_specs(config)
    assert [s.start for s in specs] == ["heuristic", "singletons", "greedy", "clutter", "random", "random"]
    assert [s.index for s in specs] == list(range(6)) and {s.seed for s in specs} == {7}


def test_each_chain_draws_its_own_stream_and_chain_0_the_seeds_own():
    draws = [ChainSpec(k, "random", 5).chain_rng().random(4) for k in range(3)]
    assert np.array_equal(draws[0], np.random.default_rng(5).random(4))  # one chain: the single-chain map
    assert not np.allclose(draws[1], draws[2]) and not np.allclose(draws[0], draws[1])
    assert np.array_equal(ChainSpec(2, "random", 5).chain_rng().random(4), draws[2])  # reproducible
    assert not np.allclose(ChainSpec(2, "random", 5).start_rng().random(4), draws[2])  # start apart from chain


def test_the_same_seed_gives_the_same_map_and_chains(problem, built):
    again = infer_map(problem, CHAINS)
    assert _without_timings(again) == _without_timings(built)
    other = infer_map(problem, dataclasses.replace(CHAINS, seed=2))
    traces = [[run["trace"]["log_target"] for run in b.diagnostics["chain_runs"]] for b in (built, other)]
    assert traces[0] != traces[1]


def test_one_chain_of_several_is_the_chain_of_a_one_chain_run(problem, built):
    alone = infer_map(problem, dataclasses.replace(CHAINS, chains=1))
    assert alone.diagnostics["chain_runs"][0] == built.diagnostics["chain_runs"][0]


def test_the_starts_are_dispersed(problem):
    chained = tracklets_of_problem(problem, CHAINS.tracklets)
    target = AssociationTarget(problem, chained.tracklets, TargetOptions.of(CHAINS))
    screen = ProposalScreen(target)
    rng = np.random.default_rng(0)
    starts = {kind: dispersed_start(kind, screen, CHAINS, rng).state for kind in CHAINS.starts}
    assert starts["heuristic"] == start_state(screen, CHAINS).state
    assert starts["singletons"].n_objects == len(chained.tracklets) and not starts["singletons"].clutter
    assert starts["greedy"] == greedy_association(problem, chained.tracklets)
    assert starts["clutter"].assignment == (CLUTTER,) * len(chained.tracklets)
    assert len(set(starts.values())) == len(starts)
    randoms = {dispersed_start("random", screen, CHAINS, rng).state for _ in range(5)}
    assert len(randoms) > 1
    with pytest.raises(ValueError, match="unknown chain start"):
        dispersed_start("best", screen, CHAINS, rng)


def _algorithm_1(problem, samples):
    return build_from_samples(samples, problem.stamps_ns, MapOptions.of(CHAINS))


def _plain(built):
    return [dataclasses.replace(o, existence_by_chain=()) for o in (*built.objects, *built.rejected)]


def test_pooled_by_counts_the_map_is_algorithm_1_over_the_samples_of_all_chains(problem):
    config = dataclasses.replace(CHAINS, pooling="counts")
    inference = prepare(problem, config)
    outcomes = InProcess().run(inference.tasks)
    assert [o.spec for o in outcomes] == chain_specs(config)
    pooled = _algorithm_1(problem, [sample for outcome in outcomes for sample in outcome.samples])
    mapped = finish(inference, outcomes)
    assert _plain(mapped) == [*pooled.objects, *pooled.rejected]
    assert mapped.trajectory == pooled.trajectory
    kept = CHAINS.samples - CHAINS.burn_in
    assert mapped.diagnostics["kept_samples"] == mapped.diagnostics["map_samples"] == CHAINS.chains * kept
    assert mapped.diagnostics["pooling"] == "counts"
    # Each identity's pooled probability is the mean of its per-chain ones (equal kept draws per chain).
    for obj in (*mapped.objects, *mapped.rejected):
        assert len(obj.existence_by_chain) == CHAINS.chains
        assert obj.existence_probability == pytest.approx(np.mean(obj.existence_by_chain), abs=1e-9)


def test_pooled_by_target_each_distinct_kept_state_weighs_its_posterior_probability(problem):
    # Every state kept, starts included: after 100 steps the three chains hold one state.
    config = dataclasses.replace(CHAINS, burn_in=0)
    built = infer_map(problem, config)
    inference = prepare(problem, config)
    outcomes = InProcess().run(inference.tasks)
    # Computed apart: the target of every distinct kept state, read off each chain's trace. A
    # state several chains kept was solved by each (warm-started apart, equal to the solver's
    # tolerance): each chain's solution of it carries an equal share of its weight.
    value, kept = {}, []
    for outcome in outcomes:
        for state, log_p in zip(outcome.result.trace, outcome.result.log_targets, strict=True):
            value[(outcome.spec.index, state)] = log_p
        pairs = zip(outcome.result.counts, outcome.summaries, strict=True)
        kept += [(outcome.spec.index, state, s) for state, s in pairs]
    holders = Counter(state for _, state, _ in kept)
    top = max(value[(chain, state)] for chain, state, _ in kept)
    pooled = _algorithm_1(
        problem, [(s, float(np.exp(value[(chain, state)] - top)) / holders[state]) for chain, state, s in kept]
    )
    mine, theirs = _plain(built), [*pooled.objects, *pooled.rejected]

    def keys(objects):
        return [(o.id, o.label, o.measurement_count) for o in objects]

    assert keys(mine) == keys(theirs)
    for a, b in zip(mine, theirs, strict=True):
        assert a.existence_probability == pytest.approx(b.existence_probability, abs=1e-12)
        assert a.position_m == pytest.approx(b.position_m, abs=1e-9)
    assert np.allclose([p.x_m for p in built.trajectory], [p.x_m for p in pooled.trajectory], atol=1e-9)
    assert built.diagnostics["pooling"] == "target" and CHAINS.pooling == "target"
    assert len(holders) > 1  # the chains kept more than one state: the weights had work to do


def test_the_map_file_records_each_chain(built):
    runs = built.diagnostics["chain_runs"]
    assert [r["start"] for r in runs] == ["heuristic", "singletons", "greedy"]
    for run in runs:
        for key in (
            "acceptance_rates",
            "distinct_associations_visited",
            "best_log_target",
            "kept_objects_mean",
            "unconverged_solves",
            "settled_solves",
            "unconverged_settles",
        ):
            assert key in run
        assert len(run["trace"]["log_target"]) == len(run["trace"]["objects"]) <= 300
        assert run["trace"]["every_steps"] * len(run["trace"]["objects"]) <= CHAINS.samples
    assert built.diagnostics["best_log_target"] == max(r["best_log_target"] for r in runs)
    convergence = built.diagnostics["convergence"]
    assert convergence["chains"] == 3 and convergence["draws_per_chain"] == CHAINS.samples - CHAINS.burn_in
    assert isinstance(convergence["converged"], bool)
    names = set(convergence["quantities"])
    assert {"log_target", "objects"} <= names
    assert {f"identity_{o.id}" for o in (*built.objects, *built.rejected)} <= names


@pytest.mark.parametrize(("max_iterations", "unconverged"), [(2, 1), (None, 0)])
def test_the_target_counts_the_solves_that_stopped_before_converging(problem, max_iterations, unconverged):
    short = problem
    if max_iterations is not None:
        short = dataclasses.replace(problem, solver=dataclasses.replace(problem.solver, max_iterations=max_iterations))
    chained = tracklets_of_problem(short, CHAINS.tracklets)
    work = Work()
    target = AssociationTarget(short, chained.tracklets, TargetOptions.of(CHAINS), work)
    solution = target.solution(initial_association(chained.tracklets, 0.6))
    assert (work.solves, work.unconverged_solves) == (1, unconverged)
    assert solution.converged is (unconverged == 0)


def test_a_chain_task_is_a_pure_function_of_its_task(problem):
    inference = prepare(problem, CHAINS)
    first, second = (run_chain_task(inference.tasks[1]) for _ in range(2))
    assert first.result.counts == second.result.counts and first.start == second.start
    assert first.result.log_targets == second.result.log_targets


def test_states_of_nil_weight_are_summarized_without_error_covariances_and_the_map_is_unchanged(problem, monkeypatch):
    import objslam_mapper.inference.chains as chains_module

    config = dataclasses.replace(CHAINS, burn_in=0)  # the starts kept: states far below the best
    task = prepare(problem, config).tasks[1]
    light, nil_nats = run_chain_task(task), chains_module.NEGLIGIBLE_NATS
    monkeypatch.setattr(chains_module, "NEGLIGIBLE_NATS", np.inf)
    full = run_chain_task(task)
    assert light.result.counts == full.result.counts
    values = light.kept_log_targets()
    negligible = [v < max(values) - nil_nats for v in values]
    assert any(negligible) and not all(negligible)
    for nil, summary, reference in zip(negligible, light.summaries, full.summaries, strict=True):
        assert all((o.error_cov is None) == nil for o in summary.objects)
        assert all(o.error_cov is not None for o in reference.objects)
        for a, b in zip(summary.objects, reference.objects, strict=True):
            np.testing.assert_array_equal(a.location_cov, b.location_cov)
    stamps = problem.stamps_ns
    mine = build_from_samples(chains_module.pooled_samples([light], "target"), stamps)
    theirs = build_from_samples(chains_module.pooled_samples([full], "target"), stamps)
    assert [(o.id, o.label, o.measurement_count) for o in mine.objects] == [
        (o.id, o.label, o.measurement_count) for o in theirs.objects
    ]
    for a, b in zip((*mine.objects, *mine.rejected), (*theirs.objects, *theirs.rejected), strict=True):
        assert a.existence_probability == b.existence_probability
        np.testing.assert_allclose(a.position_covariance, b.position_covariance, rtol=1e-12, atol=0.0)


def test_pooled_by_counts_every_kept_state_has_its_error_covariances(problem):
    config = dataclasses.replace(CHAINS, burn_in=0, pooling="counts")
    outcome = run_chain_task(prepare(problem, config).tasks[1])
    assert all(o.error_cov is not None for s in outcome.summaries for o in s.objects)


def test_a_proposal_a_chain_might_take_on_an_unconverged_value_is_solved_on_first(problem):
    # Warm solves capped at one linearization stop unconverged: the value there is not the
    # state's (its detection term can lie far above the optimum's, docs/method.md).
    chained = tracklets_of_problem(problem, CHAINS.tracklets)
    here = initial_association(chained.tracklets, 0.6)
    assignment = list(here.assignment)
    assignment[max(here.groups, key=len)[0]] = CLUTTER
    proposal = type(here).of(assignment)
    converged = AssociationTarget(problem, chained.tracklets, TargetOptions.of(CHAINS))(proposal)

    def chain_at_here(settle_within_nats: float) -> tuple[AssociationTarget, Work]:
        work = Work()
        options = TargetOptions.of(CHAINS)._replace(max_iterations=1, settle_within_nats=settle_within_nats)
        target = AssociationTarget(problem, chained.tracklets, options, work)
        target.move_to(here, target(here))
        return target, work

    capped_target, work = chain_at_here(0.0)
    capped = capped_target(proposal)
    assert not capped_target.solution(proposal).converged and work.settled_solves == 0
    assert capped != pytest.approx(converged, abs=0.1)

    settled_target, work = chain_at_here(1e6)
    assert settled_target(proposal) == pytest.approx(converged, abs=0.01)  # within the solver's tolerance
    assert settled_target.solution(proposal).converged and work.settled_solves == 1
    assert work.unconverged_settles == 0

    # Only where the chain might take it: a proposal valued further below is judged as it stopped.
    margin = capped_target(here) - capped - 1.0
    assert margin > 0.0  # the scene's proposal lies below the chain's state
    below_target, work = chain_at_here(margin)
    assert below_target(proposal) == pytest.approx(capped) and work.settled_solves == 0
