"""The GTSAM backend solves the same model as the fast solver, to the same numbers.

Every granularity of the graph (one factor per detection, per group and window of poses,
per whole group) and both drives (GTSAM's optimizer, our loop over GTSAM linearizations)
must give the fast solver's MAP, chi-square, log-determinant, Laplace evidence and object
marginals; the custom factors' analytic Jacobians are checked against finite differences.
"""

from __future__ import annotations

import dataclasses
import math

import gtsam
import numpy as np
import pytest

from objslam_common.catalog import load_catalog
from objslam_common.config import from_mapping, load_config
from objslam_common.errors import ConfigError
from objslam_common.records import ImageSlices
from objslam_mapper.config import GraphConfig, KeyframeConfig, MapperConfig, SolverConfig
from objslam_mapper.graph import gtsam_backend
from objslam_mapper.graph.backends import solve_with_backend
from objslam_mapper.graph.gtsam_backend import (
    GtsamBackendError,
    _damped,
    _Linearizer,
    build_gtsam_graph,
    solve_gtsam,
)
from objslam_mapper.graph.keyframes import keyframes_of
from objslam_mapper.graph.layout import layout_of
from objslam_mapper.graph.problem import build_problem, with_extra_priors
from objslam_mapper.graph.solver import solve
from objslam_mapper.model.slice_model import bounds_of_cuts, predict_slices
from objslam_mapper.synthetic import SyntheticObject, ellipse_trajectory, simulate_run

CATALOG = load_catalog()
SCENE = (
    SyntheticObject("red", (2.2, 0.3, 0.0), (0.31, 0.58)),
    SyntheticObject("green", (-0.5, 1.0, 0.0), (0.41, 0.39)),
    SyntheticObject("cyan", (0.4, -0.9, 0.75), (0.15, 0.26)),
)
# Tight tolerances: both backends then stop at the optimum, not somewhere near it.
TIGHT = dataclasses.replace(GraphConfig(), solver=SolverConfig(absolute_tolerance=1e-12))
N_POSES = 15


def make_problem(seed, config=TIGHT, duplicate_slice=True):
    """A small run; image 3 sees the red object twice (a blob split in two), both slices assigned to it."""
    poses = ellipse_trajectory(N_POSES, (3.0, 1.8))
    stamps = [k * 250_000_000 for k in range(N_POSES)]
    run = simulate_run(poses, stamps, SCENE, CATALOG, np.random.default_rng(seed), config=config)
    images = list(run.images)
    slice_object = list(run.slice_object)
    if duplicate_slice:
        images[3] = ImageSlices(images[3].stamp_ns, (*images[3].slices, images[3].slices[0]))
        slice_object[3] = (*slice_object[3], slice_object[3][0])
    run = dataclasses.replace(run, images=tuple(images), slice_object=tuple(slice_object))
    problem = build_problem(run.odometry, run.images, config.camera_mount.to_mount(), CATALOG, config)
    return problem, [np.asarray(g) for g in run.groups(problem)]


@pytest.fixture(scope="module")
def reference():
    problem, groups = make_problem(8)
    return problem, groups, solve(problem, groups, with_covariances=True)


def state(solution):
    objects = np.array([np.r_[o.location_m, o.size_m] for o in solution.objects])
    return solution.map_T_base, objects, solution.calibration


def assert_same_solution(theirs, ours, atol_state=1e-6):
    assert theirs.converged
    np.testing.assert_allclose(theirs.map_T_base, ours.map_T_base, atol=atol_state)
    np.testing.assert_allclose(state(theirs)[1], state(ours)[1], atol=atol_state)
    np.testing.assert_allclose(theirs.calibration, ours.calibration, atol=atol_state)
    np.testing.assert_array_equal(theirs.object_of_measurement, ours.object_of_measurement)
    assert theirs.chi2 == pytest.approx(ours.chi2, abs=1e-4)
    assert theirs.log_det_information == pytest.approx(ours.log_det_information, abs=1e-4)
    assert theirs.log_evidence == pytest.approx(ours.log_evidence, abs=1e-4)


@pytest.mark.parametrize("drive", ["python", "optimizer"])
@pytest.mark.parametrize(
    "per_detection, window_poses",
    [(True, None), (False, 4), (False, None)],
    ids=["per-detection", "per-group-window", "per-group"],
)
def test_same_map_evidence_and_marginals_as_the_fast_solver(reference, drive, per_detection, window_poses):
    problem, groups, ours = reference
    theirs = solve_gtsam(
        problem, groups, with_covariances=True, per_detection=per_detection, drive=drive, window_poses=window_poses
    )
    assert_same_solution(theirs, ours)
    np.testing.assert_allclose(theirs.calibration_cov, ours.calibration_cov, rtol=1e-4)
    for a, b in zip(theirs.objects, ours.objects, strict=True):
        assert a.label == b.label
        np.testing.assert_array_equal(a.measurement_indices, b.measurement_indices)
        np.testing.assert_allclose(a.location_cov, b.location_cov, rtol=1e-4)
        np.testing.assert_allclose(a.size_cov, b.size_cov, rtol=1e-4)
        # The error covariance is computed by shared code at each backend's MAP.
        assert a.error_cov is not None
        np.testing.assert_allclose(a.error_cov, b.error_cov, rtol=1e-3, atol=1e-12)


@pytest.mark.parametrize("per_detection", [True, False], ids=["per-detection", "per-group"])
def test_a_keyframe_graph_solves_to_the_same_numbers(per_detection):
    """Images between keyframes (objslam_mapper.graph.keyframes): both backends solve the same graph."""
    sparse = KeyframeConfig(min_travel_m=2.5, min_turn_rad=10.0)  # about 1 m per image: every third
    config = dataclasses.replace(TIGHT, solver=dataclasses.replace(TIGHT.solver, keyframes=sparse))
    problem, groups = make_problem(8, config=config)
    assert keyframes_of(problem).problem.pose_count < problem.pose_count / 2
    ours = solve(problem, groups, with_covariances=True)
    theirs = solve_gtsam(problem, groups, with_covariances=True, per_detection=per_detection, window_poses=None)
    assert_same_solution(theirs, ours)
    for a, b in zip(theirs.objects, ours.objects, strict=True):
        np.testing.assert_allclose(a.location_cov, b.location_cov, rtol=1e-4)


def test_warm_start_and_a_split_match_the_fast_solver(reference):
    problem, groups, ours = reference
    warm = solve_gtsam(problem, groups, warm_start=ours)
    assert warm.iterations == 1
    assert_same_solution(warm, ours)
    # A split starts both parts from the parent, as in the fast solver.
    split = [groups[0][::2], groups[0][1::2], *groups[1:]]
    assert_same_solution(solve_gtsam(problem, split, warm_start=ours), solve(problem, split, warm_start=ours))


def test_a_bad_start_needs_damping_and_still_reaches_the_optimum(reference, monkeypatch):
    problem, groups, ours = reference
    rng = np.random.default_rng(0)
    objects = tuple(
        dataclasses.replace(o, location_m=o.location_m + np.r_[rng.normal(0.0, 1.0, 2), 0.0]) for o in ours.objects
    )
    poses = ours.map_T_base + rng.normal(0.0, [1.0, 1.0, 0.5], ours.map_T_base.shape)
    bad = dataclasses.replace(ours, objects=objects, map_T_base=poses)
    dampings = []

    def spy(linear, damping, diagonals):
        dampings.append(damping)
        return _damped(linear, damping, diagonals)

    monkeypatch.setattr(gtsam_backend, "_damped", spy)
    counts = {"linearizations": 0, "diagonals": 0}
    linearize, diagonals = _Linearizer.__call__, gtsam_backend._diagonals

    def counted_linearize(self, values):
        counts["linearizations"] += 1
        return linearize(self, values)

    def counted_diagonals(lin, dims):
        counts["diagonals"] += 1
        return diagonals(lin, dims)

    monkeypatch.setattr(_Linearizer, "__call__", counted_linearize)
    monkeypatch.setattr(gtsam_backend, "_diagonals", counted_diagonals)
    theirs = solve_gtsam(problem, groups, warm_start=bad, drive="python")
    assert dampings
    assert_same_solution(theirs, ours)
    # The lost test and the damping share one diagonal per linearization.
    assert 0 < counts["diagonals"] <= counts["linearizations"]


def test_no_objects_and_an_object_seen_once(reference):
    problem, groups, _ = reference
    # Odometry alone is a chain of Gaussians over the poses: it integrates to exactly 1.
    empty = solve_gtsam(problem, [], with_covariances=True)
    assert empty.converged and empty.objects == ()
    assert empty.log_evidence == pytest.approx(0.0, abs=1e-8)
    once = [groups[0][:1]]
    ours = solve(problem, once, with_covariances=True)
    theirs = solve_gtsam(problem, once, with_covariances=True)
    assert_same_solution(theirs, ours)
    np.testing.assert_allclose(theirs.objects[0].location_cov, ours.objects[0].location_cov, rtol=1e-4)


def test_default_tolerances_stop_near_the_same_optimum():
    problem, groups = make_problem(3, config=GraphConfig(), duplicate_slice=False)
    ours = solve(problem, groups)
    theirs = solve_gtsam(problem, groups)
    assert theirs.converged
    np.testing.assert_allclose(theirs.map_T_base, ours.map_T_base, atol=1e-3)
    assert theirs.log_evidence == pytest.approx(ours.log_evidence, abs=1e-2)


# -- the factors -------------------------------------------------------------------------------


def numerical_jacobian(factor, values, step=1e-6):
    """Central differences of the whitened error over each key's tangent space (Pose2 chart, vectors)."""
    blocks = []
    for key in factor.keys():
        dim = 5 if gtsam.Symbol(key).chr() == ord("o") else 3  # x: Pose2, c: calibration
        block = np.empty((factor.dim(), dim))
        for k in range(dim):
            delta = gtsam.VectorValues()
            delta.insert(key, step * np.eye(dim)[k])
            plus = factor.whitenedError(values.retract(delta))
            delta = gtsam.VectorValues()
            delta.insert(key, -step * np.eye(dim)[k])
            minus = factor.whitenedError(values.retract(delta))
            block[:, k] = (plus - minus) / (2 * step)
        blocks.append(block)
    return np.hstack(blocks)


@pytest.mark.parametrize("per_detection, window_poses", [(True, None), (False, 4), (False, None)])
def test_factor_jacobians_match_finite_differences(reference, per_detection, window_poses):
    problem, groups, ours = reference
    rng = np.random.default_rng(1)
    # The Gaussian factors: at this state many slices lie beyond their outlier cap, whose
    # Jacobian is zero by design (test_outlier_slices_cost_their_cap_and_carry_no_information).
    graph, keys = build_gtsam_graph(
        problem, groups, per_detection=per_detection, window_poses=window_poses, cap_scale=math.inf
    )
    # A random state near the MAP (the model is defined there), headings across +-pi included.
    poses, objects, calibration = state(ours)
    assert len(calibration) == 3  # the default model estimates the odometry calibration
    poses = poses + rng.normal(0.0, [0.05, 0.05, 0.1], poses.shape)
    poses[0, 2] = np.pi - 1e-3
    objects = objects + rng.normal(0.0, 0.02, objects.shape)
    values = keys.to_values(poses, objects, calibration + rng.normal(0.0, 0.05, 3))
    checked = 0
    for index in range(graph.size()):
        factor = graph.at(index)
        if not isinstance(factor, gtsam.CustomFactor):
            continue
        analytic, b = gtsam.JacobianFactor(factor.linearize(values)).jacobian()
        np.testing.assert_allclose(-b, factor.whitenedError(values), rtol=1e-12)
        np.testing.assert_allclose(analytic, numerical_jacobian(factor, values), rtol=1e-5, atol=1e-4)
        checked += 1
    if per_detection:
        assert checked == 1 + (N_POSES - 1) + sum(len(g) for g in groups)
    else:
        assert checked >= 2 + len(groups)


def test_a_thing_pulled_below_the_floor_solves_to_the_same_numbers(reference):
    """A prior row with a floor factor (objslam_mapper.model.floor) whose prior wants the
    base 0.5 m under the floor: the factor is active at the MAP of both backends."""
    problem, groups, _ = reference
    rows = [int(problem.measurement_label[g[0]]) for g in groups]
    mean, stddev = np.array(problem.prior_mean[rows[0]]), np.array(problem.prior_stddev[rows[0]])
    mean[2], stddev[2] = -0.5, 0.02
    problem, rows[0] = with_extra_priors(problem, mean, stddev, floor_stddev_m=0.2)
    ours = solve(problem, groups, with_covariances=True, priors=rows)
    assert ours.objects[0].location_m[2] < -0.01
    for drive in ("python", "optimizer"):
        assert_same_solution(solve_gtsam(problem, groups, with_covariances=True, drive=drive, priors=rows), ours)
    graph, keys = build_gtsam_graph(problem, groups, priors=rows)
    poses, objects, calibration = state(ours)
    floors = [graph.at(i) for i in range(graph.size()) if isinstance(graph.at(i), gtsam.CustomFactor)]
    floors = [f for f in floors if f.dim() == 1]
    assert len(floors) == 1
    for z_base in (-0.2, 0.3):  # below the floor, and above it (no residual, no Jacobian)
        objects[0, 2] = z_base
        values = keys.to_values(poses, objects, calibration)
        np.testing.assert_allclose(floors[0].whitenedError(values), [min(z_base, 0.0) / 0.2])
        analytic, _ = gtsam.JacobianFactor(floors[0].linearize(values)).jacobian()
        np.testing.assert_allclose(analytic, numerical_jacobian(floors[0], values), atol=1e-8)


def test_outlier_slices_cost_their_cap_and_carry_no_information(reference):
    problem, groups, ours = reference
    gaussian, keys = build_gtsam_graph(problem, groups, per_detection=True, cap_scale=math.inf)
    robust, _ = build_gtsam_graph(problem, groups, per_detection=True)
    poses, objects, calibration = state(ours)
    values = keys.to_values(poses, objects + np.array([0.3, 0.0, 0.0, 0.0, 0.0]), calibration)
    slice_factors = [
        (k, problem.measurement_outlier_cost[m])
        for k, m in zip(
            [i for i in range(robust.size()) if isinstance(robust.at(i), gtsam.CustomFactor)][N_POSES:],
            np.concatenate(groups),
            strict=True,
        )
    ]
    outliers = 0
    for index, cap in slice_factors:
        half = gaussian.at(index).error(values)
        factor = robust.at(index)
        assert factor.error(values) == pytest.approx(min(half, cap), rel=1e-12)
        if half > cap:
            outliers += 1
            jacobian, _ = gtsam.JacobianFactor(factor.linearize(values)).jacobian()
            assert not jacobian.any()
    assert outliers > 0  # the 0.3 m shift puts some slices beyond their cap


def test_one_factor_per_group_and_window():
    problem, groups = make_problem(8)
    per_group, keys = build_gtsam_graph(problem, groups, window_poses=None)
    # First-pose prior, one odometry factor, a prior and a slice factor per group, the calibration prior.
    assert per_group.size() == 2 + 2 * len(groups) + 1
    assert keys.calibration() in per_group.at(1).keys()
    assert len(per_group.at(2 + 1).keys()) == len(np.unique(problem.measurement_pose[groups[0]])) + 1
    assert keys.object(0) in per_group.at(2 + 1).keys()
    windowed, _ = build_gtsam_graph(problem, groups, window_poses=5)
    windows = [len(np.unique(problem.measurement_pose[g] // 5)) for g in groups]
    assert windowed.size() == 1 + int(np.ceil((N_POSES - 1) / 5)) + len(groups) + sum(windows) + 1
    per_detection, _ = build_gtsam_graph(problem, groups, per_detection=True)
    assert per_detection.size() == 1 + (N_POSES - 1) + len(groups) + sum(len(g) for g in groups) + 1


def test_a_camera_inside_an_object_is_a_huge_error(reference):
    problem, groups, ours = reference
    graph, keys = build_gtsam_graph(problem, groups)
    poses, objects, _ = state(ours)
    seen_from = poses[problem.measurement_pose[groups[0][0]]]
    objects[0, :2] = seen_from[:2]
    assert graph.error(keys.to_values(poses, objects)) > 1e10


def test_damping_adds_the_scaled_diagonal(reference):
    problem, groups, ours = reference
    graph, keys = build_gtsam_graph(problem, groups)
    linearize = _Linearizer(graph, keys, problem, layout_of(problem, groups))
    linear = linearize(keys.to_values(*state(ours)))
    order = gtsam.Ordering()
    for key in sorted(linearize.dims):
        order.push_back(key)
    hessian = linear.graph.augmentedHessian(order)[:-1, :-1]
    damped = _damped(linear.graph, 0.3, linearize.diagonals(linear)).augmentedHessian(order)[:-1, :-1]
    np.testing.assert_allclose(damped, hessian + 0.3 * np.diag(np.diag(hessian)), rtol=1e-12, atol=1e-9)


# -- configuration, dispatch, timing -----------------------------------------------------------


def test_backend_setting_is_validated_and_read_from_the_mapper_file(repo_root, tmp_path):
    assert SolverConfig().backend == "fast"
    assert load_config(MapperConfig, repo_root / "config" / "mapper.yaml", "mapper").graph.solver.backend == "fast"
    with pytest.raises(ConfigError, match="backend"):
        from_mapping(GraphConfig, {"solver": {"backend": "ceres"}})
    custom = tmp_path / "mapper.yaml"
    custom.write_text("mapper:\n  ros__parameters:\n    solver.backend: gtsam\n")
    assert load_config(MapperConfig, custom, "mapper").graph.solver.backend == "gtsam"


def test_solve_with_backend_dispatches_on_the_setting(reference):
    problem, groups, ours = reference
    fast = solve_with_backend(problem, groups, with_covariances=True)
    np.testing.assert_array_equal(fast.map_T_base, ours.map_T_base)
    assert fast.log_evidence == ours.log_evidence
    on_gtsam = dataclasses.replace(problem, solver=dataclasses.replace(problem.solver, backend="gtsam"))
    theirs = solve_with_backend(on_gtsam, groups, warm_start=ours, drive="optimizer")
    assert theirs.log_evidence == solve_gtsam(problem, groups, warm_start=ours, drive="optimizer").log_evidence


def test_bad_requests_are_refused(reference):
    problem, groups, _ = reference
    with pytest.raises(GtsamBackendError, match="drive"):
        solve_gtsam(problem, groups, drive="isam2")
    with pytest.raises(GtsamBackendError, match="window_poses"):
        build_gtsam_graph(problem, groups, window_poses=0)


def test_upper_edges_cut_by_the_view_are_lower_bounds_in_both_backends(reference):
    problem, groups, ours = reference
    poses, objects, calibration = state(ours)
    # Every third slice's upper edge was cut by the view; half of them read 0.05 rad above
    # the MAP's upper edge (the model's lies below the bound: it costs), half below (free).
    cut = np.zeros(problem.measurement_count, dtype=bool)
    cut[::3] = True
    measured = np.array(problem.measurements)
    owner = ours.object_of_measurement
    at = predict_slices(poses[problem.measurement_pose], objects[owner, :3], objects[owner, 3:], problem.mount)
    offset = np.where(np.arange(problem.measurement_count) % 2 == 0, 0.05, -0.05)
    measured[cut, 3] = at.values[cut, 3] + offset[cut]
    censored = dataclasses.replace(
        problem, measurements=measured, measurement_bounds=bounds_of_cuts(np.zeros(cut.shape, int), cut)
    )
    graph, keys = build_gtsam_graph(censored, groups, per_detection=True, cap_scale=math.inf)
    values = keys.to_values(poses, objects, calibration)
    slice_factors = [i for i in range(graph.size()) if isinstance(graph.at(i), gtsam.CustomFactor)][N_POSES:]
    for index, m in zip(slice_factors, np.concatenate(groups), strict=True):
        error = (at.values[m] - measured[m]) / problem.measurement_stddev[m]
        error[0] = np.angle(np.exp(1j * error[0] * problem.measurement_stddev[m, 0])) / problem.measurement_stddev[m, 0]
        if cut[m] and offset[m] < 0.0:
            error[3] = 0.0  # above the bound: no cost, no information
            jacobian, _ = gtsam.JacobianFactor(graph.at(index).linearize(values)).jacobian()
            assert not jacobian[3].any()
        assert graph.at(index).error(values) == pytest.approx(0.5 * float(error @ error), rel=1e-9, abs=1e-12)
    # Both backends solve the one-sided factors to the same numbers, and they move the map.
    fast = solve(censored, groups, with_covariances=True)
    assert_same_solution(solve_gtsam(censored, groups, with_covariances=True), fast)
    assert np.abs(state(fast)[1] - objects).max() > 1e-4
