"""Factor graph of a known association: problem building, MAP, marginals, Laplace evidence.

Data come from objslam_mapper.synthetic (the model itself plus known noise), so the truth
behind every measurement is known.
"""

from __future__ import annotations

import dataclasses
import math

import gtsam
import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import chi2

from objslam_common.config import load_config
from objslam_common.geometry import between, wrap_angle
from objslam_common.records import ImageSlices, OdometrySample, SliceMeasurement
from objslam_mapper.config import GraphConfig, MapperConfig, OdometryNoiseConfig, SolverConfig
from objslam_mapper.graph import solver as solver_module
from objslam_mapper.graph.gtsam_backend import build_gtsam_graph
from objslam_mapper.graph.initialization import initial_object
from objslam_mapper.graph.problem import GraphError, at_view_top, build_problem, with_extra_priors
from objslam_mapper.graph.solver import solve
from objslam_mapper.model.slice_model import LOWER_BOUND, predict_slices, slice_error
from objslam_mapper.synthetic import SyntheticObject, ellipse_trajectory, simulate_run
from tests.objslam_mapper.graph_scenes import CATALOG, CONFIG, MOUNT, SCENE, STEP_NS, draw_scene, object_nees

# Both ways of solving the linear systems: dense Schur complement (few objects), sparse LU.
SOLVERS = pytest.mark.parametrize("dense_object_limit", [40, 0], ids=["schur", "sparse"])


def with_limit(config, dense_object_limit):
    return dataclasses.replace(config, solver=dataclasses.replace(config.solver, dense_object_limit=dense_object_limit))


def make_run(seed, scene=SCENE, n_poses=60, config=CONFIG, solve_config=None, **kwargs):
    poses = ellipse_trajectory(n_poses, (3.0, 1.8))
    stamps = [k * STEP_NS for k in range(n_poses)]
    run = simulate_run(poses, stamps, scene, CATALOG, np.random.default_rng(seed), config=config, **kwargs)
    problem = build_problem(run.odometry, run.images, MOUNT, CATALOG, solve_config or config)
    return run, problem


# -- an independent evaluation of the model, for checking the solver's bookkeeping -------------


def state_vector(solution):
    objects = [np.r_[o.location_m, o.size_m] for o in solution.objects]
    return np.concatenate([np.ravel(solution.map_T_base), *objects, solution.calibration])


def whitened_residuals(problem, groups, theta):
    """All whitened residuals of the graph at theta = (poses, objects, calibration), written out plainly."""
    n, nc = problem.pose_count, problem.calibration_dim
    poses, objects = theta[: 3 * n].reshape(n, 3), theta[3 * n : len(theta) - nc].reshape(-1, 5)
    distance_scale, turn_scale, turn_bias = theta[len(theta) - nc :] if nc else (0.0, 0.0, 0.0)
    out = []
    for i in range(n - 1):
        true = between(poses[i], poses[i + 1])
        measured = np.r_[
            (1 + distance_scale) * true[:2],
            (1 + turn_scale) * true[2] + turn_bias * problem.increment_path_length_m[i],
        ]
        err = measured - problem.increments[i]
        err[2] = wrap_angle(err[2])
        out.append(err / problem.increment_stddev[i])
    if nc:
        out.append(theta[len(theta) - nc :] / problem.calibration_prior_stddev)
    err = poses[0] - problem.odometry_poses[0]
    err[2] = wrap_angle(err[2])
    out.append(err / problem.first_pose_stddev)
    for j, group in enumerate(groups):
        group = np.asarray(group)
        pred = predict_slices(poses[problem.measurement_pose[group]], objects[j, :3], objects[j, 3:], MOUNT)
        out.append((slice_error(pred.values, problem.measurements[group]) / problem.measurement_stddev[group]).ravel())
        label = problem.measurement_label[group[0]]
        out.append((objects[j] - problem.prior_mean[label]) / problem.prior_stddev[label])
    return np.concatenate(out)


def log_normalizers(problem, groups):
    """Sum of -1/2 log|2 pi Sigma| over every factor, from the noise standard deviations,
    plus each slice's inlier weight log(1 - outlier probability) (objslam_mapper.model.outliers)."""
    sigmas = [problem.increment_stddev.ravel(), problem.first_pose_stddev, problem.calibration_prior_stddev]
    for group in groups:
        group = np.asarray(group)
        sigmas.append(problem.measurement_stddev[group].ravel())
        sigmas.append(problem.prior_stddev[problem.measurement_label[group[0]]])
    sigmas = np.concatenate(sigmas)
    slices = sum(len(g) for g in groups)
    inlier_weight = slices * np.log1p(-CONFIG.slice_noise.outlier_probability)
    return float(np.sum(-0.5 * np.log(2 * np.pi * sigmas**2))) + inlier_weight


def dense_information(problem, groups, theta, step=1e-6):
    columns = []
    for k in range(len(theta)):
        plus, minus = theta.copy(), theta.copy()
        plus[k] += step
        minus[k] -= step
        columns.append(
            (whitened_residuals(problem, groups, plus) - whitened_residuals(problem, groups, minus)) / (2 * step)
        )
    jacobian = np.stack(columns, axis=1)
    return jacobian.T @ jacobian


# -- problem building ------------------------------------------------------------------------


def test_measurements_are_indexed_in_image_then_slice_order():
    odom = [OdometrySample(0, 0.0, 0.0, 0.0), OdometrySample(10, 1.0, 0.0, 0.0)]

    def sl(label, bearing):
        return SliceMeasurement(label, 0.9, bearing, 0.1, -0.2, 0.1)

    images = [
        ImageSlices(8, (sl("red", 0.3), sl("nope", 0.0), sl("green", 0.4))),
        ImageSlices(2, (sl("blue", 0.1),)),
        ImageSlices(20, (sl("red", 0.5),)),  # after the odometry ends
        ImageSlices(5, ()),
    ]
    problem = build_problem(odom, images, MOUNT, CATALOG, CONFIG)
    assert problem.stamps_ns.tolist() == [2, 5, 8]
    assert problem.pose_image.tolist() == [1, 3, 0]
    assert problem.rejected_image_count == 1
    assert problem.rejected_slice_count == 1
    assert [problem.label_of(m) for m in range(problem.measurement_count)] == ["blue", "red", "green"]
    assert problem.measurement_pose.tolist() == [0, 2, 2]
    assert problem.measurement_image.tolist() == [1, 0, 0]
    assert problem.measurement_slot.tolist() == [0, 0, 2]
    np.testing.assert_allclose(problem.odometry_poses[:, 0], [0.2, 0.5, 0.8])
    with pytest.raises(ValueError):
        problem.measurements[0, 0] = 1.0  # read-only


def test_no_image_inside_the_odometry_span_is_an_error():
    with pytest.raises(GraphError, match="odometry span"):
        build_problem([OdometrySample(0, 0.0, 0.0, 0.0)], [ImageSlices(5, ())], MOUNT, CATALOG, CONFIG)


def test_raised_classes_get_a_wide_lower_edge_noise():
    _, problem = make_run(0, n_poses=10)
    cyan = problem.measurement_label == problem.labels.index("cyan")
    assert np.all(problem.measurement_stddev[cyan, 2] == CONFIG.slice_noise.raised_elevation_bottom_stddev_rad)
    assert np.all(problem.measurement_stddev[~cyan, 2] == CONFIG.slice_noise.elevation_bottom_stddev_rad)


def test_priors_carry_the_spread_of_real_instances():
    # A floor object's base-height prior is slack for the MAP; the error covariance counts
    # the floor's own spread instead (0 by default: it stands on the floor).
    _, problem = make_run(0, n_poses=10)
    floor = np.array([CATALOG[label].on_floor for label in problem.labels])
    assert floor.any() and not floor.all()
    np.testing.assert_array_equal(problem.prior_spread[floor, 2], 0.0)
    assert np.all(problem.prior_stddev[floor, 2] > 0.0)
    keep = np.ones_like(problem.prior_spread, dtype=bool)
    keep[floor, 2] = False
    np.testing.assert_array_equal(problem.prior_spread[keep], problem.prior_stddev[keep])
    # A distractor's extra prior row is its own spread.
    extended, first = with_extra_priors(problem, np.zeros((1, 5)), np.full((1, 5), 0.7))
    np.testing.assert_array_equal(extended.prior_spread[first], 0.7)
    np.testing.assert_array_equal(extended.prior_spread[:first], problem.prior_spread)


def test_low_confidence_slices_get_inflated_noise():
    odom = [OdometrySample(0, 0.0, 0.0, 0.0), OdometrySample(10, 1.0, 0.0, 0.0)]
    sure, cut = (SliceMeasurement("red", c, 0.3, 0.1, -0.2, 0.1) for c in (0.9, 0.45))
    problem = build_problem(odom, [ImageSlices(5, (sure, cut))], MOUNT, CATALOG, CONFIG)
    scale = CONFIG.slice_noise.low_confidence_stddev_scale
    np.testing.assert_allclose(problem.measurement_stddev[1], scale * problem.measurement_stddev[0])


def test_upper_edges_where_cut_blobs_pile_up_are_found_at_the_top_of_the_view():
    top = 0.427
    rows = [
        # Four upper edges within 3 mrad at one bearing: the view's edge (on both sides of -pi).
        (-3.13, 0.1, 0.1, top),
        (-3.12, 0.1, 0.1, top - 0.003),
        (3.13, 0.1, 0.1, top - 0.001),
        (3.12, 0.1, 0.1, top - 0.002),
        (3.12, 0.1, 0.1, top - 0.05),  # lower: the object's own top
        # Elsewhere one tall object's top seen twice, and a view edge higher in the corners.
        (1.0, 0.1, 0.1, 0.40),
        (1.01, 0.1, 0.1, 0.40),
        (0.79, 0.1, 0.1, 0.60),
        (0.78, 0.1, 0.1, 0.598),
        (0.785, 0.1, 0.1, 0.599),
    ]
    flagged = at_view_top(np.array(rows), 0.007).tolist()
    assert flagged == [True] * 4 + [False] * 3 + [True] * 3
    assert at_view_top(np.array(rows), 0.0005).tolist() == [False] * 10  # too few that close
    assert at_view_top(np.zeros((0, 4)), 0.007).tolist() == []


def test_upper_edges_cut_by_the_view_are_lower_bounds():
    odom = [OdometrySample(0, 0.0, 0.0, 0.0), OdometrySample(10, 1.0, 0.0, 0.0)]
    cut = [SliceMeasurement("blue", 0.4, 0.3 + 0.001 * k, 0.1, -0.2, 0.427) for k in range(3)]
    sure = SliceMeasurement("blue", 0.9, 0.3, 0.1, -0.2, 0.427)  # at the top but whole: its own top
    below = SliceMeasurement("blue", 0.4, 0.3, 0.1, -0.2, 0.3)  # cut short, not by the view
    images = [ImageSlices(1 + k, (c,)) for k, c in enumerate(cut)] + [ImageSlices(5, (sure, below))]
    problem = build_problem(odom, images, MOUNT, CATALOG, CONFIG)
    assert (problem.measurement_bounds[:, 3] == LOWER_BOUND).tolist() == [True, True, True, False, False]
    assert not problem.measurement_bounds[:, :3].any()
    scale = CONFIG.slice_noise.low_confidence_stddev_scale
    np.testing.assert_allclose(problem.measurement_stddev[[0, 1, 2, 4]], scale * problem.measurement_stddev[[3] * 4])
    off = dataclasses.replace(CONFIG, slice_noise=dataclasses.replace(CONFIG.slice_noise, censor_view_top=False))
    assert not build_problem(odom, images, MOUNT, CATALOG, off).measurement_bounds.any()


@pytest.mark.parametrize(
    "groups, message",
    [
        ([[0, 1], [1]], "more than one object"),
        ([[]], "at least one"),
        ([[10**6]], "must lie in"),
    ],
)
def test_invalid_groups_are_refused(groups, message):
    _, problem = make_run(0, n_poses=10)
    with pytest.raises(GraphError, match=message):
        solve(problem, groups)


def test_a_group_mixing_classes_is_refused():
    run, problem = make_run(0, n_poses=10)
    groups = run.groups(problem)
    with pytest.raises(GraphError, match="mixes classes"):
        solve(problem, [groups[0] + groups[1]])


def test_graph_config_reads_its_sections_of_the_mapper_file(repo_root, tmp_path):
    assert load_config(MapperConfig, repo_root / "config" / "mapper.yaml", "mapper").graph == GraphConfig()
    custom = tmp_path / "mapper.yaml"
    custom.write_text("mapper:\n  ros__parameters:\n    sampler: {seed: 3}\n    slice_noise.bearing_stddev_rad: 0.02\n")
    assert load_config(MapperConfig, custom, "mapper").graph.slice_noise.bearing_stddev_rad == 0.02


# -- MAP -------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1])
def test_exact_slices_recover_the_truth_despite_perturbed_odometry(seed):
    # Odometry drifts by metres; with odometry trusted little the exact slices must win.
    drifting = dataclasses.replace(
        CONFIG, odometry=OdometryNoiseConfig(xy_stddev_per_sqrt_m=0.1, theta_stddev_per_sqrt_m=0.05)
    )
    loose = dataclasses.replace(
        CONFIG,
        odometry=OdometryNoiseConfig(
            xy_stddev_per_sqrt_m=2.0,
            xy_stddev_per_sqrt_rad=2.0,
            theta_stddev_per_sqrt_m=2.0,
            theta_stddev_per_sqrt_rad=2.0,
        ),
    )
    run, problem = make_run(seed, config=drifting, solve_config=loose, slice_noise_scale=0.0)
    odometry_error = np.hypot(*(problem.odometry_poses[:, :2] - run.true_map_T_base[:, :2]).T).max()
    assert odometry_error > 0.3
    solution = solve(problem, run.groups(problem))
    assert solution.converged
    np.testing.assert_allclose(solution.map_T_base[:, :2], run.true_map_T_base[:, :2], atol=0.015)
    np.testing.assert_allclose(wrap_angle(solution.map_T_base[:, 2] - run.true_map_T_base[:, 2]), 0.0, atol=0.003)
    for j, obj in zip(run.seen_objects(), solution.objects, strict=True):
        truth = run.objects[j]
        assert obj.label == truth.label
        np.testing.assert_allclose(obj.location_m, truth.location_m, atol=0.015)
        # The size prior (catalog nominal) pulls a little: true sizes are off nominal by up to 4 %.
        np.testing.assert_allclose(obj.size_m, truth.size_m, atol=0.01)


def test_a_solve_that_ends_without_a_positive_definite_information_has_no_evidence(monkeypatch):
    """Where damping gives up (the information is not positive definite at the last iterate),
    there is no optimum to take a Laplace evidence at: -inf, not an exception that ends the map
    (it did, fitting one distractor to slices of two things on a cluttered render)."""
    run, problem = make_run(0)

    def singular(*_args, **_kwargs):
        raise np.linalg.LinAlgError("not positive definite")

    monkeypatch.setattr(solver_module, "factorize", singular)
    solution = solve(problem, run.groups(problem))
    assert solution.log_evidence == -np.inf and not solution.converged


def test_object_positions_are_consistent_nees():
    nees = []
    for seed in range(6):
        rng = np.random.default_rng(100 + seed)
        scene = draw_scene(rng)
        poses = ellipse_trajectory(60, (3.0, 1.8))
        run = simulate_run(poses, [k * STEP_NS for k in range(60)], scene, CATALOG, rng, config=CONFIG)
        problem = build_problem(run.odometry, run.images, MOUNT, CATALOG, CONFIG)
        solution = solve(problem, run.groups(problem), with_covariances=True)
        assert solution.converged
        # Covariances are about the trajectory: errors are measured after fitting it, as objslam eval does.
        # The runs' noise is the configured, so the posterior is the error's covariance.
        nees += object_nees(solution, run, lambda o: o.location_cov)
    count = len(nees)
    low, high = chi2.ppf([0.025, 0.975], 3 * count) / count
    assert low < np.mean(nees) < high, (np.mean(nees), low, high)


def test_an_object_seen_once_is_well_posed():
    run, problem = make_run(2, n_poses=40)
    single = [run.groups(problem)[0][5]]
    solution = solve(problem, [single], with_covariances=True)
    assert solution.converged
    obj = solution.objects[0]
    assert np.all(np.isfinite(obj.location_cov)) and np.all(np.linalg.eigvalsh(obj.location_cov) > 0)
    # One sighting gives range from apparent size: far better than the 100 m prior, but metres-ish.
    assert np.sqrt(np.linalg.eigvalsh(obj.location_cov).max()) < 1.0
    assert np.isfinite(solution.log_evidence)
    truth = run.objects[run.seen_objects()[0]]
    assert np.hypot(*(obj.location_m[:2] - truth.location_m[:2])) < 0.3


@SOLVERS
def test_warm_start_converges_to_the_same_solution_faster(dense_object_limit):
    run, problem = make_run(3, solve_config=with_limit(CONFIG, dense_object_limit))
    groups = run.groups(problem)
    cold = solve(problem, groups)
    warm = solve(problem, groups, warm_start=cold)
    assert warm.iterations == 1 and warm.converged
    assert warm.log_evidence == pytest.approx(cold.log_evidence, abs=1e-3)
    # A split starts both parts from the parent; merging back starts from the larger part.
    first = np.asarray(groups[0])
    split = [first[::2], first[1::2], *groups[1:]]
    parts = solve(problem, split, warm_start=cold)
    merged = solve(problem, groups, warm_start=parts)
    assert merged.log_evidence == pytest.approx(cold.log_evidence, abs=1e-2)


def test_a_warm_start_with_a_pose_inside_an_object_still_solves():
    run, problem = make_run(3)
    groups = run.groups(problem)
    cold = solve(problem, groups)
    # Move the first object onto a pose that saw it: the model is undefined there.
    first = cold.objects[0]
    seen_from = cold.map_T_base[problem.measurement_pose[first.measurement_indices[0]]]
    moved = dataclasses.replace(first, location_m=np.r_[seen_from[:2], first.location_m[2]])
    bad = dataclasses.replace(cold, objects=(moved, *cold.objects[1:]))
    again = solve(problem, groups, warm_start=bad)
    assert again.converged
    assert again.log_evidence == pytest.approx(cold.log_evidence, abs=1e-2)


def test_initial_object_is_near_the_truth():
    run, problem = make_run(4)
    for j, group in zip(run.seen_objects(), run.groups(problem), strict=True):
        guess = initial_object(problem, group, run.true_map_T_base)
        assert np.hypot(*(guess[:2] - run.objects[j].location_m[:2])) < 0.1


# -- evidence --------------------------------------------------------------------------------


@SOLVERS
def test_laplace_evidence_matches_an_independent_dense_computation(dense_object_limit):
    run, problem = make_run(5, scene=SCENE[:2], n_poses=8)
    # One image sees the first object twice (a blob split in two), both assigned to it.
    images = list(run.images)
    images[3] = ImageSlices(images[3].stamp_ns, (*images[3].slices, images[3].slices[0]))
    problem = build_problem(run.odometry, images, MOUNT, CATALOG, with_limit(CONFIG, dense_object_limit))
    groups = [[m for m in range(problem.measurement_count) if problem.label_of(m) == obj.label] for obj in SCENE[:2]]
    twice = [g for g in groups if len(set(problem.measurement_pose[g])) < len(g)]
    assert len(twice) == 1
    solution = solve(problem, groups, with_covariances=True)
    theta = state_vector(solution)
    residual = whitened_residuals(problem, groups, theta)
    info = dense_information(problem, groups, theta)
    sign, log_det = np.linalg.slogdet(info)
    assert sign > 0
    expected = -0.5 * residual @ residual + log_normalizers(problem, groups) + 0.5 * len(theta) * np.log(2 * np.pi)
    expected -= 0.5 * log_det
    assert solution.chi2 == pytest.approx(residual @ residual, rel=1e-9)
    assert solution.log_det_information == pytest.approx(log_det, abs=1e-4)
    assert solution.log_evidence == pytest.approx(expected, abs=1e-4)
    # Covariances are those of each object's error less the rigid motion fitted to the
    # trajectory's (objslam_mapper.graph.gauge), from the inverse information: (E - M G) Lambda^-1 (E - M G)^T.
    cov = np.linalg.inv(info)
    n = 3 * problem.pose_count
    xy = solution.map_T_base[:, :2]
    centred = xy - xy.mean(axis=0)
    fit = np.zeros((3, len(theta)))  # translation x, y and rotation about the centroid, from the pose errors
    fit[0, 0:n:3] = fit[1, 1:n:3] = 1.0 / len(xy)
    fit[2, 0:n:3], fit[2, 1:n:3] = -centred[:, 1], centred[:, 0]
    fit[2] /= np.sum(centred**2)
    for j, obj in enumerate(solution.objects):
        lever = obj.location_m[:2] - xy.mean(axis=0)
        functional = -np.array([[1.0, 0.0, -lever[1]], [0.0, 1.0, lever[0]], [0.0, 0.0, 0.0]]) @ fit
        functional[:, n + 5 * j : n + 5 * j + 3] += np.eye(3)
        np.testing.assert_allclose(obj.location_cov, functional @ cov @ functional.T, rtol=1e-4, atol=1e-12)
        size = slice(n + 5 * j + 3, n + 5 * j + 5)
        np.testing.assert_allclose(obj.size_cov, cov[size, size], rtol=1e-4)
    # Anchored at the first pose instead, the marginals are larger: the drift on the way is a gauge choice.
    far = solution.objects[1]
    assert np.trace(far.location_cov[:2, :2]) < np.trace(cov[n + 5 : n + 7, n + 5 : n + 7])


def batch_log_joint(problem, groups, thetas):
    """log p(Z, theta) of many states (S, d) at once: the plain formulas of whitened_residuals."""
    n, nc, dim = problem.pose_count, problem.calibration_dim, thetas.shape[1]
    poses, objects = thetas[:, : 3 * n].reshape(-1, n, 3), thetas[:, 3 * n : dim - nc].reshape(len(thetas), -1, 5)
    calib = thetas[:, dim - nc :] if nc else np.zeros((len(thetas), 3))
    c, s = np.cos(poses[:, :-1, 2]), np.sin(poses[:, :-1, 2])
    d = poses[:, 1:, :2] - poses[:, :-1, :2]
    odo = np.stack(
        [c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1], wrap_angle(poses[:, 1:, 2] - poses[:, :-1, 2])],
        -1,
    )
    odo[..., :2] *= 1 + calib[:, None, :1]
    odo[..., 2] = (1 + calib[:, 1:2]) * odo[..., 2] + calib[:, 2:] * problem.increment_path_length_m
    odo = odo - problem.increments
    odo[..., 2] = wrap_angle(odo[..., 2])
    total = np.sum((odo / problem.increment_stddev) ** 2, axis=(1, 2))
    if nc:
        total += np.sum((calib / problem.calibration_prior_stddev) ** 2, axis=1)
    first = poses[:, 0] - problem.odometry_poses[0]
    first[:, 2] = wrap_angle(first[:, 2])
    total += np.sum((first / problem.first_pose_stddev) ** 2, axis=1)
    for j, group in enumerate(groups):
        group = np.asarray(group)
        at = poses[:, problem.measurement_pose[group]].reshape(-1, 3)
        obj = np.repeat(objects[:, j], len(group), axis=0)
        pred = predict_slices(at, obj[:, :3], obj[:, 3:], MOUNT, jacobians=False).values
        err = slice_error(pred, np.tile(problem.measurements[group], (len(thetas), 1)))
        err /= np.tile(problem.measurement_stddev[group], (len(thetas), 1))
        total += np.sum(err.reshape(len(thetas), -1) ** 2, axis=1)
        label = problem.measurement_label[group[0]]
        total += np.sum(((objects[:, j] - problem.prior_mean[label]) / problem.prior_stddev[label]) ** 2, axis=1)
    return log_normalizers(problem, groups) - 0.5 * total


@pytest.mark.parametrize("calibrated, n_samples", [(False, 40000), (True, 160000)], ids=["plain", "calibrated"])
def test_laplace_evidence_matches_importance_sampling(calibrated, n_samples):
    """The marginal likelihood itself, integrated numerically over poses, the object (and the calibration).

    The calibration enters the odometry bilinearly and, over 6 poses, is hardly more than
    its prior: the posterior is less Gaussian, so more samples are drawn.
    """
    config = (
        CONFIG
        if calibrated
        else dataclasses.replace(
            CONFIG,
            odometry=dataclasses.replace(
                CONFIG.odometry, calibration=dataclasses.replace(CONFIG.odometry.calibration, enabled=False)
            ),
        )
    )
    run, problem = make_run(6, scene=SCENE[1:2], n_poses=6, config=config)
    assert problem.calibration_dim == (3 if calibrated else 0)
    groups = run.groups(problem)
    solution = solve(problem, groups)
    theta = state_vector(solution)
    cov = np.linalg.inv(dense_information(problem, groups, theta))
    single = batch_log_joint(problem, groups, theta[None, :])[0]
    assert single == pytest.approx(log_normalizers(problem, groups) - 0.5 * solution.chi2, abs=1e-9)
    rng = np.random.default_rng(0)
    samples = rng.multivariate_normal(theta, cov, size=n_samples)
    centred = samples - theta
    log_q = -0.5 * np.einsum("si,ij,sj->s", centred, np.linalg.inv(cov), centred)
    log_q -= 0.5 * np.linalg.slogdet(2 * np.pi * cov)[1]
    log_weights = batch_log_joint(problem, groups, samples) - log_q
    estimate = logsumexp(log_weights) - np.log(len(samples))
    weights = np.exp(log_weights - log_weights.max())
    standard_error = np.std(weights) / np.mean(weights) / np.sqrt(len(samples))
    assert standard_error < 0.01
    # Calibrated, the Laplace approximation itself is off by about 0.02 nats here (200k samples).
    assert solution.log_evidence == pytest.approx(estimate, abs=0.05 if calibrated else 0.03)


def test_evidence_prefers_the_true_number_of_objects():
    run, problem = make_run(7)
    groups = [np.asarray(g) for g in run.groups(problem)]
    truth = solve(problem, groups)
    # One object cut in two (first and second half of its sightings) pays the Occam price.
    first = groups[0]
    cut = solve(problem, [first[: len(first) // 2], first[len(first) // 2 :], *groups[1:]], warm_start=truth)
    assert truth.log_evidence > cut.log_evidence + 5
    # Two real objects of one class glued into one cannot fit their slices.
    twin = (*SCENE, SyntheticObject("red", (-1.5, 1.9, 0.0), (0.3, 0.6)))
    run2, problem2 = make_run(7, scene=twin)
    groups2 = [np.asarray(g) for g in run2.groups(problem2)]
    reds = [k for k, j in enumerate(run2.seen_objects()) if run2.objects[j].label == "red"]
    separate = solve(problem2, groups2)
    glued_groups = [np.concatenate([groups2[k] for k in reds])] + [g for k, g in enumerate(groups2) if k not in reds]
    glued = solve(problem2, glued_groups, warm_start=separate)
    assert separate.log_evidence > glued.log_evidence + 100


# -- the same problem in GTSAM (objslam_mapper.graph.gtsam_backend; more in test_gtsam_backend.py) ---------


@SOLVERS
def test_same_map_and_information_as_gtsam(dense_object_limit):
    solver = SolverConfig(absolute_tolerance=1e-12, dense_object_limit=dense_object_limit)
    tight = dataclasses.replace(CONFIG, solver=solver)
    run, problem = make_run(8, scene=SCENE[:3], n_poses=15, config=tight)
    groups = run.groups(problem)
    ours = solve(problem, groups)
    # One CustomFactor per detection, solved by GTSAM's own optimizer from the same start,
    # in the same two phases: Gaussian slices, then the outlier model.
    gaussian, keys = build_gtsam_graph(problem, groups, per_detection=True, cap_scale=math.inf)
    graph, _ = build_gtsam_graph(problem, groups, per_detection=True)
    result = keys.to_values(
        problem.odometry_poses, [initial_object(problem, group, problem.odometry_poses) for group in groups]
    )
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    for phase in (gaussian, graph):
        result = gtsam.LevenbergMarquardtOptimizer(phase, result, params).optimize()
    theirs = np.array(
        [[result.atPose2(k).x(), result.atPose2(k).y(), result.atPose2(k).theta()] for k in keys.pose_keys]
    )
    np.testing.assert_allclose(ours.map_T_base, theirs, atol=1e-7)
    for j, obj in enumerate(ours.objects):
        np.testing.assert_allclose(np.r_[obj.location_m, obj.size_m], result.atVector(keys.object(j)), atol=1e-7)
    assert ours.chi2 == pytest.approx(2 * graph.error(result), rel=1e-9)
    log_det_r = graph.linearize(result).eliminateMultifrontal().logDeterminant()
    assert ours.log_det_information == pytest.approx(2 * log_det_r, abs=1e-5)
