"""Fast sampling: empty graphs, the conditional object evidence and delayed acceptance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objslam_common.catalog import load_catalog
from objslam_mapper.config import GraphConfig
from objslam_mapper.graph.problem import build_problem
from objslam_mapper.graph.solver import solve
from objslam_mapper.inference.target import NO_OBJECT_LOG_EVIDENCE
from objslam_mapper.synthetic import office_run

CATALOG = load_catalog()
CONFIG = GraphConfig()


@pytest.fixture(scope="module")
def office():
    run = office_run(0, n_poses=60)
    problem = build_problem(run.odometry, run.images, CONFIG.camera_mount.to_mount(), CATALOG, CONFIG)
    return run, problem


@pytest.mark.parametrize("dense_object_limit", [40, 0], ids=["schur", "sparse"])
def test_a_graph_without_objects_is_the_odometry_with_zero_evidence(office, dense_object_limit):
    import dataclasses

    _, problem = office
    problem = dataclasses.replace(
        problem, solver=dataclasses.replace(problem.solver, dense_object_limit=dense_object_limit)
    )
    solution = solve(problem, [])
    assert solution.converged and solution.objects == ()
    np.testing.assert_allclose(solution.map_T_base, problem.odometry_poses, atol=1e-9)
    assert solution.log_evidence == pytest.approx(NO_OBJECT_LOG_EVIDENCE, abs=1e-6)


# ---- delayed acceptance is exact whatever the screen ----------------------------------------


def _state_noise(state, other, scale):
    """A fixed, state-dependent (hence asymmetric) error: deterministic in the ordered pair."""
    seed = hash((state.assignment, other.assignment)) % (2**32)
    return scale * np.random.default_rng(seed).normal()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("screen_error", "margins"),
    [
        (0.0, (0.0, 0.0, 0.0, None, 0.0)),
        (2.0, (0.0, 0.0, 0.0, None, 0.0)),
        (2.0, (1.0, 0.3, 0.2, None, 0.0)),
        (4.0, (0, 0, 0.02, 0.3, 0.0)),
        (4.0, (0, 0, 0.02, 0.3, 1.5)),
    ],
    ids=[
        "exact-screen",
        "poor-screen",
        "poor-screen-with-margins-and-floor",
        "bad-screen-with-a-join-floor",
        "bad-screen-far-joins-always-solved",
    ],
)
def test_delayed_acceptance_visits_states_with_their_exact_probabilities(screen_error, margins):
    from objslam_mapper.config import ScreenConfig
    from objslam_mapper.inference.association import CLUTTER, Association, enumerate_associations
    from objslam_mapper.inference.chain import MetropolisHastings
    from objslam_mapper.inference.exact import ExactDistribution
    from tests.objslam_mapper.inference.test_sampler import random_problem, things_by_class

    labels = ["r", "r", "g", "g"]
    states, scores, positions, weights = random_problem(labels, seed=0, clutter=True)
    exact = ExactDistribution.of(states, scores.__getitem__)
    calls = []

    def screen(state, new):
        calls.append(1)
        return scores[new] - scores[state] + _state_noise(state, new, screen_error)

    sampler = MetropolisHastings(
        labels,
        scores.__getitem__,
        positions_xy_m=positions,
        tracklet_weights=weights,
        screen=screen,
        guide=screen,  # informed moves, whose reverse is known only once J' is solved
        clutter_things=things_by_class(labels),  # and informed group moves
        screen_config=ScreenConfig(
            margin_nats=margins[0],
            relative_margin=margins[1],
            floor=margins[2],
            join_floor=margins[2] if margins[3] is None else margins[3],
            far_join_m=margins[4],
        ),
    )
    result = sampler.run(Association.of([CLUTTER] * 4), 50_000, 1000, np.random.default_rng(100), keep_trace=False)
    assert exact.total_variation(result.counts) < 0.05
    # The chain reached nearly every state (a bad screen slows it down); those it missed are rare ones.
    unvisited = [p for s, p in zip(exact.states, exact.probabilities, strict=True) if s not in result.counts]
    assert len(unvisited) <= 1 and sum(unvisited) < 0.01
    assert len(exact.states) == len(enumerate_associations(labels, True))
    screened = sum(s.screened_out for s in result.moves.values())
    assert calls and screened > 0


def test_moves_that_join_or_part_tracklets_far_apart_are_always_solved():
    from objslam_mapper.config import ScreenConfig
    from objslam_mapper.inference.association import CLUTTER, Association
    from objslam_mapper.inference.chain import MetropolisHastings

    # Two red tracklets 0.5 m apart and a third 10 m away.
    sampler = MetropolisHastings(
        ["r", "r", "r"],
        lambda state: 0.0,
        positions_xy_m=[[0.0, 0.0], [0.5, 0.0], [10.0, 0.0]],
        screen=lambda state, new: -100.0,
        screen_config=ScreenConfig(floor=0.01, join_floor=0.1, far_join_m=3.0),
    )
    all_one, far_one_apart = Association.of([0, 0, 0]), Association.of([0, 0, 1])
    assert sampler._log_floor(all_one, far_one_apart) == 0.0  # parting the far one
    assert sampler._log_floor(far_one_apart, all_one) == 0.0  # joining it
    assert sampler._log_floor(Association.of([0, 0, CLUTTER]), all_one) == 0.0  # from clutter, far
    near_apart = Association.of([0, 1, 2])
    assert sampler._log_floor(near_apart, far_one_apart) == pytest.approx(math.log(0.1))  # a near join
    assert sampler._log_floor(near_apart, Association.of([0, 1, CLUTTER])) == pytest.approx(math.log(0.01))


@pytest.mark.slow
def test_a_screen_that_ignores_the_reverse_stage_is_caught():
    """Power check: accepting on the screen alone (no second-stage correction) is visibly wrong."""
    from objslam_mapper.config import ScreenConfig
    from objslam_mapper.inference.association import CLUTTER, Association
    from objslam_mapper.inference.chain import MetropolisHastings
    from objslam_mapper.inference.exact import ExactDistribution
    from tests.objslam_mapper.inference.test_sampler import random_problem

    labels = ["r", "r", "g", "g"]
    states, scores, positions, weights = random_problem(labels, seed=0, clutter=True)
    exact = ExactDistribution.of(states, scores.__getitem__)

    class ScreenOnly(MetropolisHastings):
        def _log_acceptance(self, state, log_p, proposal, rng):
            log_first = self.screen(state, proposal.view.state) + proposal.log_q_reverse - proposal.log_q_forward
            return log_first, False

    sampler = ScreenOnly(
        labels,
        scores.__getitem__,
        positions_xy_m=positions,
        tracklet_weights=weights,
        screen=lambda s, n: scores[n] - scores[s] + _state_noise(s, n, 2.0),
        screen_config=ScreenConfig(margin_nats=0.0, relative_margin=0.0, floor=0.0, join_floor=0.0),
    )
    result = sampler.run(Association.of([CLUTTER] * 4), 50_000, 1000, np.random.default_rng(100), keep_trace=False)
    assert exact.total_variation(result.counts) > 0.08


# ---- the conditional object evidence against an independent computation ------------------------


def _whitened_residuals(problem, poses, group, state, row):
    from objslam_common.geometry import wrap_angle
    from objslam_mapper.model.slice_model import censor, predict_reduced

    pred = predict_reduced(poses[problem.measurement_pose[group]], state[:3], state[3:], problem.mount, jacobians=False)
    res = pred.values - problem.measurements[group].T
    res[0] = wrap_angle(res[0])
    res = res / problem.measurement_stddev[group].T
    res *= censor(res, problem.measurement_bounds[group])
    prior = (state - problem.prior_mean[row]) / problem.prior_stddev[row]
    floor = min(state[2], 0.0) / problem.prior_floor_stddev[row]  # 0 without a floor factor (inf)
    return np.concatenate([res.ravel(), prior, [floor]])


@pytest.mark.parametrize("censored", ["measured", "upper-edges-cut", "every-edge-cut", "pulled-below-the-floor"])
def test_conditional_object_evidence_matches_finite_differences_and_the_full_map(office, censored):
    import dataclasses

    from objslam_mapper.graph.conditional_evidence import object_evidence
    from objslam_mapper.graph.initialization import initial_object
    from objslam_mapper.graph.problem import LOG_2PI, with_extra_priors
    from objslam_mapper.model.slice_model import bounds_of_cuts

    run, problem = office
    groups = [g for g in run.groups(problem) if len(g) >= 5]
    cut = np.zeros(problem.measurement_count, dtype=bool)
    cut[::3] = True
    measured = np.array(problem.measurements)
    sign = np.where(np.arange(problem.measurement_count)[cut] % 2 == 0, -1.0, 1.0)
    if censored == "upper-edges-cut":
        # Every third slice's upper edge cut by the view, half of them 0.03 rad below the
        # object's (free as lower bounds), half above (they cost).
        measured[cut, 3] += 0.03 * sign
        bounds = bounds_of_cuts(np.zeros(cut.shape, int), cut)
    elif censored == "every-edge-cut":
        # Every third slice cut on some of its four edges (all combinations), every component
        # moved 0.02 rad one way or the other: some bounds cost, some are cleared.
        cuts = np.where(cut, np.arange(problem.measurement_count) % 16, 0)
        measured[cut] += 0.02 * sign[:, None] * np.array([1.0, -1.0, -1.0, 1.0])
        bounds = bounds_of_cuts(cuts, np.zeros(cut.shape, bool))
    if censored in ("upper-edges-cut", "every-edge-cut"):
        problem = dataclasses.replace(problem, measurements=measured, measurement_bounds=bounds)
        assert cut[np.asarray(groups[0])].any()
    rows = [int(problem.measurement_label[g[0]]) for g in groups]
    if censored == "pulled-below-the-floor":
        # The first object under a prior that wants its base 0.3 m under the floor, against
        # a floor factor (objslam_mapper.model.floor): active at the MAP.
        mean, stddev = np.array(problem.prior_mean[rows[0]]), np.array(problem.prior_stddev[rows[0]])
        mean[2], stddev[2] = -0.5, 0.02
        problem, rows[0] = with_extra_priors(problem, mean, stddev, floor_stddev_m=0.2)
    # Solved to the optimum (not just within the default cost tolerance): the comparison is at 1e-5 m.
    tight = dataclasses.replace(problem, solver=dataclasses.replace(problem.solver, absolute_tolerance=1e-10))
    full = solve(tight, groups, priors=rows)
    poses = np.asarray(full.map_T_base)
    group = np.asarray(groups[0], dtype=np.int64)
    start = initial_object(problem, group, poses)
    result = object_evidence(
        problem, poses, group, start, absolute_tolerance=1e-12, relative_tolerance=0.0, prior=rows[0]
    )
    assert result.converged
    assert (result.object_state[2] < -0.01) == (censored == "pulled-below-the-floor")
    # With the poses at the full MAP, the object's conditional MAP is the full MAP's object.
    expected = np.concatenate([full.objects[0].location_m, full.objects[0].size_m])
    np.testing.assert_allclose(result.object_state, expected, atol=1e-5)
    # Laplace evidence recomputed from residuals and a finite-difference Jacobian.
    r = _whitened_residuals(problem, poses, group, result.object_state, rows[0])
    step = 1e-6
    jac = np.column_stack(
        [
            (
                _whitened_residuals(problem, poses, group, result.object_state + step * e, rows[0])
                - _whitened_residuals(problem, poses, group, result.object_state - step * e, rows[0])
            )
            / (2 * step)
            for e in np.eye(5)
        ]
    )
    normalizer = np.sum(problem.measurement_log_normalizer[group]) + problem.prior_log_normalizer[rows[0]]
    independent = -0.5 * r @ r + normalizer + 2.5 * LOG_2PI - 0.5 * np.linalg.slogdet(jac.T @ jac)[1]
    assert result.log_evidence == pytest.approx(independent, abs=1e-4)
