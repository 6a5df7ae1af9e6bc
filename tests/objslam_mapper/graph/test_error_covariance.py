"""Covariance of the estimate's error (objslam_mapper.graph.error_covariance): the algebra against
Monte Carlo on linear problems, the solver's rows against its information, and the pipeline's
consistency where the posterior is pessimistic."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from objslam_mapper.config import ErrorCovarianceConfig, GraphConfig
from objslam_mapper.graph import solver as solver_module
from objslam_mapper.graph.covariance import noise_groups, object_error_covariance_about_trajectory
from objslam_mapper.graph.error_covariance import (
    ErrorCovarianceError,
    NoiseGroup,
    bias_shares,
    error_covariance,
    row_leverages,
    white_weights,
)
from objslam_mapper.graph.factorize import information_matrix
from objslam_mapper.graph.keyframes import keyframes_of
from objslam_mapper.graph.layout import layout_of
from objslam_mapper.graph.linearize import AssociationSystem, cap_schedule
from objslam_mapper.graph.problem import OBJECT_DIM, POSE_DIM, build_problem
from objslam_mapper.graph.solver import solve
from objslam_mapper.synthetic import ellipse_trajectory, simulate_run
from tests.objslam_mapper.graph_scenes import CATALOG, CONFIG, MOUNT, STEP_NS, draw_scene, object_nees


def with_error_covariance(config: GraphConfig, **fields) -> GraphConfig:
    error = dataclasses.replace(config.solver.error_covariance, **fields)
    return dataclasses.replace(config, solver=dataclasses.replace(config.solver, error_covariance=error))


def run_and_problem(seed, n_poses=40, config=CONFIG, **noise):
    rng = np.random.default_rng(seed)
    poses = ellipse_trajectory(n_poses, (3.0, 1.8))
    stamps = [k * STEP_NS for k in range(n_poses)]
    scene = draw_scene(rng, config.solver.error_covariance.floor_z_base_spread_m)
    run = simulate_run(poses, stamps, scene, CATALOG, rng, config=config, **noise)
    return run, build_problem(run.odometry, run.images, MOUNT, CATALOG, config)


# -- linear problems: the algebra -------------------------------------------------------------


def linear_problem(rng, sizes, n_shared, n_objects):
    """Whitened Jacobians of groups of measurements, each of one 'object', over a state of
    ``n_shared`` variables every measurement sees (the poses) and two per object (its own)."""
    n_state = n_shared + 2 * n_objects
    jacobians, owners = [], []
    for m in sizes:
        owner = rng.integers(0, n_objects, size=m)
        jac = np.zeros((m, n_state))
        jac[:, :n_shared] = rng.standard_normal((m, n_shared))
        for column in (0, 1):
            jac[np.arange(m), n_shared + 2 * owner + column] = rng.standard_normal(m)
        jacobians.append(jac)
        owners.append(owner)
    return jacobians, owners


def groups_of(jacobians, residuals, owners=None, shares=None):
    out = []
    for k, (jac, res) in enumerate(zip(jacobians, residuals, strict=True)):
        owner = None if owners is None or owners[k] is None else owners[k]
        share = 0.0 if shares is None else shares[k]
        out.append(NoiseGroup(f"g{k}", scipy.sparse.csr_matrix(jac), res, owner, share))
    return out


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), rows=st.integers(1, 40), width=st.integers(1, 6))
def test_row_leverages_are_the_diagonal_of_the_hat_matrix(seed, rows, width):
    rng = np.random.default_rng(seed)
    n = 8
    columns = np.array([rng.choice(n, width, replace=False) for _ in range(rows)])
    jacobian = scipy.sparse.csr_matrix(
        (rng.standard_normal(rows * width), columns.ravel(), np.arange(0, rows * width + 1, width)), shape=(rows, n)
    )
    spread = rng.standard_normal((n, n))
    inverse = spread @ spread.T + np.eye(n)
    dense = jacobian.toarray()
    np.testing.assert_allclose(row_leverages(jacobian, inverse), np.diag(dense @ inverse @ dense.T), rtol=1e-10)
    # As LAPACK's potri leaves it: the upper triangle, anything below.
    upper = np.triu(inverse) + np.tril(rng.standard_normal((n, n)), -1)
    np.testing.assert_array_equal(row_leverages(jacobian, upper), row_leverages(jacobian, inverse))


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000), scale=st.floats(0.1, 3.0))
def test_white_weights_are_unbiased_for_each_rows_variance(seed, scale):
    # Least squares with true noise scale^2 I: E[r_i^2 / (1 - h_ii)] = scale^2 for every row (HC2).
    rng = np.random.default_rng(seed)
    (jac,), _ = linear_problem(rng, [30], 6, 1)
    inverse = np.linalg.inv(jac.T @ jac)
    weights = []
    for _ in range(1000):
        noise = scale * rng.standard_normal(30)
        residual = noise - jac @ (inverse @ (jac.T @ noise))
        weights.append(white_weights(groups_of([jac], [residual])[0], inverse))
    # Per row a mean of 1000 chi-square(1) terms: sd sqrt(2 / 1000) = 0.045, so within 4.5 sd.
    np.testing.assert_allclose(np.mean(weights, axis=0), scale**2, rtol=0.2)
    assert np.mean(weights) == pytest.approx(scale**2, rel=0.05)


def test_noisier_rows_weigh_more_and_a_bias_per_object_is_no_white_noise():
    # Eight objects of 100 rows, the last four 3x noisier (white 0.3 or 0.9), each with a bias of 0.5.
    rng = np.random.default_rng(8)
    (jac,), (owner,) = linear_problem(rng, [800], 3, 8)
    white = np.where(owner >= 4, 0.9, 0.3)
    inverse = np.linalg.inv(jac.T @ jac + 1e-6 * np.eye(jac.shape[1]))
    about_means, plain = [], []
    for _ in range(200):
        noise = white * rng.standard_normal(800) + 0.5 * rng.standard_normal(8)[owner]
        residual = noise - jac @ (inverse @ (jac.T @ noise))
        about_means.append(white_weights(NoiseGroup("g", scipy.sparse.csr_matrix(jac), residual, owner, 0.5), inverse))
        plain.append(white_weights(NoiseGroup("g", scipy.sparse.csr_matrix(jac), residual), inverse))
    by_object = np.bincount(owner, weights=np.mean(about_means, axis=0)) / np.bincount(owner)
    # Within 30 %: what the shared variables take up of the biases leaks into every object's residuals.
    np.testing.assert_allclose(by_object, np.where(np.arange(8) >= 4, 0.81, 0.09), rtol=0.3)
    assert np.mean(plain) > 1.5 * np.mean(about_means)  # the biases' part the state does not take up


def test_sandwich_matches_monte_carlo_with_white_noise_and_object_biases():
    """The estimator's error covariance against its scatter over simulated noise.

    Two groups whose white noise is 0.3x and 0.5x their configured level; the first's rows
    belong to six objects, each with a bias common to its rows of 0.5 configured stddevs.
    A weak prior (mean at the truth). The estimate is the MAP under the configured (unit)
    weights; rows are two objects' own variables and a mix of all.
    """
    rng = np.random.default_rng(11)
    n_objects, share = 6, 0.5
    jacobians, owners = linear_problem(rng, [1200, 300], 3, n_objects)
    n_state = jacobians[0].shape[1]
    information = 0.1 * np.eye(n_state) + sum(j.T @ j for j in jacobians)
    inverse = np.linalg.inv(information)
    rows = np.vstack([np.eye(n_state)[[3, 4, 7, 8]], rng.standard_normal(n_state)])  # objects 0 and 2, a mix
    errors, residuals = [], None
    for _ in range(4000):
        bias = share * rng.standard_normal(n_objects)
        noise = [0.3 * rng.standard_normal(1200) + bias[owners[0]], 0.5 * rng.standard_normal(300)]
        estimate = inverse @ sum(j.T @ z for j, z in zip(jacobians, noise, strict=True))
        errors.append(rows @ estimate)
        residuals = [z - j @ estimate for j, z in zip(jacobians, noise, strict=True)]
    scatter = np.cov(np.array(errors).T)
    result = error_covariance(information, groups_of(jacobians, residuals, [owners[0], None], (share, 0.0)), rows)
    assert result.levels["g0"] == pytest.approx(0.09, rel=0.2)  # mean white weight: the white noise
    assert result.levels["g1"] == pytest.approx(0.25, rel=0.2)
    np.testing.assert_allclose(result.posterior, rows @ inverse @ rows.T, rtol=1e-10)
    # Monte Carlo: 4000 draws give the covariance to about 3 %; the levels come from one draw.
    tolerance = {"rtol": 0.25, "atol": 0.05 * np.abs(scatter).max()}
    np.testing.assert_allclose(result.covariance, scatter, **tolerance)
    # Without the biases, or under the configured noise, it would be far off: the test can tell.
    unbiased = error_covariance(information, groups_of(jacobians, residuals), rows)
    assert not np.allclose(unbiased.covariance, scatter, **tolerance)
    assert not np.allclose(result.posterior, scatter, **tolerance)


def test_a_prior_counts_the_spread_of_the_truth_about_its_mean():
    """Three variables with strong priors: one whose truth is the prior's mean (a floor
    object's base height), one drawn with half the prior's stddev, one with all of it.
    The sandwich with ``prior_scale`` (0, 0.5, 1) against the Monte Carlo scatter."""
    rng = np.random.default_rng(5)
    m = 1200
    (jac,), _ = linear_problem(rng, [m], 3, 3)
    n_state = jac.shape[1]
    prior_sd = np.full(n_state, 10.0)  # weak elsewhere
    strong = [3, 5, 7]
    prior_sd[strong] = 0.05  # about as informative as the measurements of those variables
    scale = np.ones(n_state)
    scale[strong] = (0.0, 0.5, 1.0)
    information = jac.T @ jac + np.diag(prior_sd**-2.0)
    inverse = np.linalg.inv(information)
    rows = np.vstack([np.eye(n_state)[strong], rng.standard_normal(n_state)])
    errors, residual = [], None
    for _ in range(4000):
        truth = scale * prior_sd * rng.standard_normal(n_state)  # about the prior's mean, 0
        noise = 0.5 * rng.standard_normal(m)  # half the configured noise
        # MAP of z = J x + noise under the prior N(0, prior_sd^2): error x_hat - x.
        estimate = inverse @ (jac.T @ (jac @ truth + noise))
        errors.append(rows @ (estimate - truth))
        residual = jac @ truth + noise - jac @ estimate
    scatter = np.cov(np.array(errors).T)
    tolerance = {"rtol": 0.15, "atol": 0.03 * np.abs(scatter).max()}
    counted = error_covariance(information, groups_of([jac], [residual]), rows, scale)
    np.testing.assert_allclose(counted.covariance, scatter, **tolerance)
    as_sparse = error_covariance(scipy.sparse.csc_matrix(information), groups_of([jac], [residual]), rows, scale)
    np.testing.assert_allclose(as_sparse.covariance, counted.covariance, rtol=1e-12)
    as_stated = error_covariance(information, groups_of([jac], [residual]), rows)
    ones = error_covariance(information, groups_of([jac], [residual]), rows, np.ones(n_state))
    np.testing.assert_allclose(as_stated.covariance, ones.covariance)
    assert not np.allclose(as_stated.covariance, scatter, **tolerance)
    assert as_stated.covariance[0, 0] > 2.0 * scatter[0, 0]  # the prior counted as stated overstates it


def test_an_object_whose_residuals_show_a_large_bias_gets_it():
    # Eight objects of 100 rows, white noise 0.3; biases of 0.1 except object 5's, 2.0.
    rng = np.random.default_rng(21)
    (jac,), (owner,) = linear_problem(rng, [800], 3, 8)
    inverse = np.linalg.inv(jac.T @ jac + 1e-6 * np.eye(jac.shape[1]))
    noise = 0.3 * rng.standard_normal(800) + np.where(np.arange(8) == 5, 2.0, 0.1)[owner]
    residual = noise - jac @ (inverse @ (jac.T @ noise))
    group = NoiseGroup("g", scipy.sparse.csr_matrix(jac), residual, owner, 0.1)
    shares = bias_shares(group, inverse, white_weights(group, inverse))
    upper = np.triu(inverse) + np.tril(np.full_like(inverse, np.nan), -1)  # potri's: the upper triangle read
    np.testing.assert_allclose(bias_shares(group, upper, white_weights(group, upper)), shares, rtol=1e-12)
    assert shares[5] == pytest.approx(2.0, rel=0.3)  # the part the state took up is put back
    assert np.all(shares >= 0.1)
    assert np.sum(np.delete(shares, 5) == 0.1) >= 6  # the others keep the configured share (but for chance)


def test_objects_at_the_configured_bias_keep_it_but_for_chance():
    # 300 objects of 20 rows whose biases are what the configured share says: the mean of
    # their residuals divided by the small part the state leaves of it is a noisy estimate,
    # which would give many of them a share several times the configured one; only means
    # beyond two standard deviations of what the configured bias and the noise explain count.
    rng = np.random.default_rng(5)
    (jac,), (owner,) = linear_problem(rng, [6000], 3, 300)
    inverse = np.linalg.inv(jac.T @ jac + 1e-6 * np.eye(jac.shape[1]))
    noise = 0.3 * rng.standard_normal(6000) + 0.1 * rng.standard_normal(300)[owner]
    residual = noise - jac @ (inverse @ (jac.T @ noise))
    group = NoiseGroup("g", scipy.sparse.csr_matrix(jac), residual, owner, 0.1)
    shares = bias_shares(group, inverse, white_weights(group, inverse))
    assert 0.01 < np.mean(shares > 0.1) < 0.1  # about P(chi-square(1) > 4) = 4.6 %
    assert np.all(shares >= 0.1)


def test_an_indefinite_information_is_one_clear_error():
    with pytest.raises(ErrorCovarianceError, match="not positive definite"):
        error_covariance(-np.eye(3), [], np.eye(3))


# -- the solver's rows ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def solved():
    run, problem = run_and_problem(4)
    groups = run.groups(problem)
    solution = solve(problem, groups, with_covariances=True)
    layout = layout_of(problem, groups)
    system = AssociationSystem(problem, layout, problem.solver.dense_object_limit)
    poses = np.asarray(solution.map_T_base)
    objects = np.array([np.r_[o.location_m, o.size_m] for o in solution.objects])
    state = (poses, objects, np.asarray(solution.calibration))
    system.cap_scale = cap_schedule(problem, layout, poses, objects, True)[-1]
    return problem, solution, system, state


def test_noise_groups_and_the_priors_make_up_the_information(solved):
    problem, _, system, state = solved
    lin = system.linearize(*state)
    groups = noise_groups(system, *state, ErrorCovarianceConfig().bias_shares())
    assert [g.name for g in groups] == [
        "bearing",
        "angular_width",
        "elevation_bottom",
        "elevation_top",
        "odometry_translation",
        "odometry_turn",
    ]
    information = information_matrix(system, lin)
    rest = information - sum((g.jacobian.T @ g.jacobian).toarray() for g in groups)
    # What is left is the priors': objects' class priors, the first pose's, the calibration's (all diagonal).
    np.testing.assert_allclose(rest - np.diag(np.diag(rest)), 0.0, atol=1e-6 * np.abs(information).max())
    n_poses = problem.pose_count
    expected = np.zeros(system.dimension)
    expected[:POSE_DIM] = problem.first_pose_stddev**-2
    expected[POSE_DIM * n_poses : POSE_DIM * n_poses + OBJECT_DIM * system.n_objects] = (
        system.prior_inv_sigma.ravel() ** 2
    )
    expected[POSE_DIM * n_poses + OBJECT_DIM * system.n_objects :] = problem.calibration_prior_stddev**-2
    np.testing.assert_allclose(np.diag(rest), expected, rtol=1e-6, atol=1e-6)
    # The residuals are the cost's: half their squared norm plus the priors' is the cost.
    prior_cost = lin.cost - 0.5 * sum(float(g.residual @ g.residual) for g in groups)
    poses, objects, calib = state
    first = (poses[0] - problem.odometry_poses[0]) / problem.first_pose_stddev
    priors = (objects - system.prior_mean) * system.prior_inv_sigma
    calibration = calib / problem.calibration_prior_stddev
    assert prior_cost == pytest.approx(0.5 * (first @ first + np.sum(priors**2) + calibration @ calibration), abs=1e-6)


def test_slice_rows_know_their_object_and_share(solved):
    _, _, system, state = solved
    shares = (0.1, 0.2, 0.3, 0.4)
    for share, group in zip(shares, noise_groups(system, *state, shares)[:4], strict=False):
        assert group.bias_share == share
        np.testing.assert_array_equal(group.owner, system.layout.object_of)  # no slice capped in this run
    assert all(g.owner is None for g in noise_groups(system, *state, shares)[4:])


def test_noise_groups_keep_the_slices_they_are_told(solved):
    # The rows of one state's kept slices at another state (scripts/error_budget.py: the MAP's at the truth).
    _, _, system, state = solved
    shares = CONFIG.solver.error_covariance.bias_shares()
    kept = system.inlier_slices(*state[:2])
    assert kept.all()  # no slice capped in this run
    kept[[0, 5]] = False
    default, told = noise_groups(system, *state, shares), noise_groups(system, *state, shares, kept)
    for full, fewer in zip(default[:4], told[:4], strict=True):
        np.testing.assert_array_equal(fewer.residual, full.residual[kept])
        np.testing.assert_array_equal(fewer.owner, full.owner[kept])
        np.testing.assert_allclose(fewer.jacobian.toarray(), full.jacobian.toarray()[kept])
    assert all(len(a.residual) == len(b.residual) for a, b in zip(default[4:], told[4:], strict=True))


def test_the_posterior_rows_are_the_solvers_covariances_about_the_trajectory(solved):
    problem, solution, system, state = solved
    lin = system.linearize(*state)
    weights = keyframes_of(problem).images_per_keyframe
    result = object_error_covariance_about_trajectory(system, lin, state, weights, (0.0,) * 4)
    reported = object_error_covariance_about_trajectory(
        system, lin, state, weights, CONFIG.solver.error_covariance.bias_shares()
    )
    for j, obj in enumerate(solution.objects):
        np.testing.assert_allclose(result.posterior[j, :3, :3], obj.location_cov, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(result.posterior[j, 3:, 3:], obj.size_cov, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(obj.error_cov, reported.covariance[j], rtol=1e-9)


def test_floor_objects_count_the_floors_spread_not_their_prior(solved):
    problem, _, system, state = solved
    lin = system.linearize(*state)
    weights = keyframes_of(problem).images_per_keyframe
    shares = CONFIG.solver.error_covariance.bias_shares()
    on_floor = np.array([CATALOG[problem.labels[p]].on_floor for p in system.layout.priors])
    assert on_floor.any() and not on_floor.all()
    standing = object_error_covariance_about_trajectory(system, lin, state, weights, shares).covariance
    # The same map with the floor prior counted as stated: only its part differs.
    system.prior_spread = system.prior_spread.copy()
    system.prior_spread[on_floor, 2] = 1.0 / system.prior_inv_sigma[on_floor, 2]
    stated = object_error_covariance_about_trajectory(system, lin, state, weights, shares).covariance
    added = stated[:, 2, 2] - standing[:, 2, 2]
    assert np.all(added[on_floor] > 0.1 * stated[on_floor, 2, 2])
    # Raised objects share no prior with the floor ones; what they gain is through the poses.
    assert np.all(np.abs(added[~on_floor]) < 0.05 * stated[~on_floor, 2, 2])


def test_the_switch_turns_error_covariances_off():
    run, problem = run_and_problem(4, n_poses=20, config=with_error_covariance(CONFIG, enabled=False))
    solution = solve(problem, run.groups(problem), with_covariances=True)
    assert all(o.error_cov is None and o.location_cov is not None for o in solution.objects)
    assert all(o.error_cov is None for o in solve(problem, run.groups(problem)).objects)


def test_a_singular_information_falls_back_to_the_marginals(monkeypatch, caplog):
    run, problem = run_and_problem(4, n_poses=20)

    def singular(*_args, **_kwargs):
        raise ErrorCovarianceError("information matrix is not positive definite: leading minor 7")

    monkeypatch.setattr(solver_module, "object_error_covariance_about_trajectory", singular)
    solution = solve(problem, run.groups(problem), with_covariances=True)
    assert all(o.error_cov is None and o.location_cov is not None for o in solution.objects)
    assert "marginals stand in" in caplog.text


# -- the pipeline -------------------------------------------------------------------------------


def aligned_nees(config, cov_of, seeds, noise_scale):
    """Mean NEES (x, y, z_base) over the objects of simulated runs, errors after the trajectory fit."""
    nees = []
    for seed in seeds:
        run, problem = run_and_problem(
            200 + seed, n_poses=60, config=config, slice_noise_scale=noise_scale, odometry_noise_scale=noise_scale
        )
        solution = solve(problem, run.groups(problem), with_covariances=True)
        assert solution.converged
        nees += object_nees(solution, run, cov_of)
    return float(np.mean(nees)), len(nees)


def test_error_covariances_are_consistent_where_the_posterior_is_pessimistic():
    # Noise 4x below the configured: the posterior overstates the error, the error covariance
    # (levels from the residuals; no bias in these runs, so no shares) does not.
    config = with_error_covariance(CONFIG, **{f: 0.0 for f in _SHARE_FIELDS})
    mean_error, count = aligned_nees(config, lambda o: o.error_cov[:3, :3], range(6), 0.25)
    mean_posterior, _ = aligned_nees(config, lambda o: o.location_cov, range(6), 0.25)
    low, high = chi2.ppf([0.025, 0.975], 3 * count) / count
    assert low < mean_error < high, (mean_error, low, high)
    assert mean_posterior < low, (mean_posterior, low)


_SHARE_FIELDS = (
    "bearing_bias_share",
    "angular_width_bias_share",
    "elevation_bottom_bias_share",
    "elevation_top_bias_share",
)
