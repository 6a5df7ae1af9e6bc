"""The odometry calibration variable: its factor Jacobians, its recovery, and switching it off.

The odometry factor with calibration ``c = (s_d, s_t, b)`` predicts the measured increment
as ``((1 + s_d) R_i^T (t_j - t_i), (1 + s_t) wrap(theta_j - theta_i) + b L)``; the plain
formula is written out here once more and differentiated numerically.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from objslam_common.catalog import load_catalog
from objslam_common.geometry import between, wrap_angle
from objslam_mapper.config import GraphConfig, OdometryCalibrationConfig
from objslam_mapper.graph.covariance import object_covariance
from objslam_mapper.graph.factorize import factorize
from objslam_mapper.graph.layout import layout_of
from objslam_mapper.graph.linearize import AssociationSystem
from objslam_mapper.graph.problem import build_problem
from objslam_mapper.graph.solver import solve
from objslam_mapper.synthetic import ellipse_trajectory, office_scene, simulate_run

CATALOG = load_catalog()
ON = GraphConfig()
OFF = dataclasses.replace(
    ON, odometry=dataclasses.replace(ON.odometry, calibration=OdometryCalibrationConfig(enabled=False))
)


def run_and_problem(seed, n_poses, config=ON, calibration=(0.0, 0.0, 0.0), laps=1.5):
    poses = ellipse_trajectory(n_poses, (3.0, 2.0), laps=laps)
    stamps = [k * 200_000_000 for k in range(n_poses)]
    run = simulate_run(
        poses, stamps, office_scene(), CATALOG, np.random.default_rng(seed), odometry_calibration=calibration
    )
    return run, build_problem(run.odometry, run.images, config.camera_mount.to_mount(), CATALOG, config)


def odometry_residuals(problem, poses, calib):
    """Whitened odometry, first-pose and calibration-prior residuals, written out plainly."""
    out = []
    for i in range(problem.pose_count - 1):
        true = between(poses[i], poses[i + 1])
        predicted = np.r_[
            (1 + calib[0]) * true[:2], (1 + calib[1]) * true[2] + calib[2] * problem.increment_path_length_m[i]
        ]
        err = predicted - problem.increments[i]
        err[2] = wrap_angle(err[2])
        out.append(err / problem.increment_stddev[i])
    first = poses[0] - problem.odometry_poses[0]
    first[2] = wrap_angle(first[2])
    out.append(first / problem.first_pose_stddev)
    out.append(calib / problem.calibration_prior_stddev)
    return np.concatenate(out)


SMALL = run_and_problem(1, 12)


@settings(max_examples=30, deadline=None)
@given(
    calib=st.tuples(*[st.floats(-0.2, 0.2)] * 3),
    seed=st.integers(0, 2**16),
    heading=st.floats(-np.pi, np.pi),
)
def test_normal_equations_match_finite_differences(calib, seed, heading):
    _, problem = SMALL
    rng = np.random.default_rng(seed)
    poses = np.array(problem.odometry_poses) + rng.normal(0.0, [0.1, 0.1, 0.2], problem.odometry_poses.shape)
    poses[:, 2] = wrap_angle(poses[:, 2] + heading)  # headings across +-pi included
    calib = np.array(calib)
    system = AssociationSystem(problem, layout_of(problem, []), 40)
    lin = system.linearize(poses, np.zeros((0, 5)), calib)

    theta = np.r_[poses.ravel(), calib]
    n = 3 * problem.pose_count

    def residuals(x):
        return odometry_residuals(problem, x[:n].reshape(-1, 3), x[n:])

    step = 1e-6
    jac = np.column_stack(
        [(residuals(theta + step * e) - residuals(theta - step * e)) / (2 * step) for e in np.eye(len(theta))]
    )
    r = residuals(theta)
    assert lin.cost == pytest.approx(0.5 * r @ r, rel=1e-12)
    np.testing.assert_allclose(np.r_[lin.grad_pose, lin.grad_calib], jac.T @ r, rtol=1e-6, atol=1e-5)
    info = jac.T @ jac
    dense = np.zeros_like(info)
    for i in range(problem.pose_count):
        dense[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = lin.pose_diag[i]
        dense[3 * i : 3 * i + 3, n:] = lin.pose_calib[i]
        dense[n:, 3 * i : 3 * i + 3] = lin.pose_calib[i].T
        if i + 1 < problem.pose_count:
            dense[3 * i : 3 * i + 3, 3 * i + 3 : 3 * i + 6] = lin.pose_off[i]
            dense[3 * i + 3 : 3 * i + 6, 3 * i : 3 * i + 3] = lin.pose_off[i].T
    dense[n:, n:] = lin.calib_diag
    np.testing.assert_allclose(dense, info, rtol=1e-6, atol=1e-3)


def quieter(config, factor):
    """``config`` with every random-walk rate of the odometry scaled by ``factor``."""
    odo = config.odometry
    return dataclasses.replace(
        config,
        odometry=dataclasses.replace(
            odo,
            xy_stddev_per_sqrt_m=factor * odo.xy_stddev_per_sqrt_m,
            xy_stddev_per_sqrt_rad=factor * odo.xy_stddev_per_sqrt_rad,
            theta_stddev_per_sqrt_m=factor * odo.theta_stddev_per_sqrt_m,
            theta_stddev_per_sqrt_rad=factor * odo.theta_stddev_per_sqrt_rad,
        ),
    )


@pytest.fixture(scope="module")
def drifting():
    """1.5 laps with a systematic odometry error well inside the prior, drawn and solved with one model.

    The random walk is a fifth of the default: at the default rates a 8 cm step gets 1.4 cm of
    noise in each direction, and since the model takes the noise level from the measured
    increment (as it must), the weights then correlate with the noise enough to bias a scale.
    """
    truth = np.array([0.03, -0.04, 0.015])
    config = quieter(ON, 0.2)
    poses = ellipse_trajectory(300, (3.0, 2.0), laps=1.5)
    stamps = [k * 200_000_000 for k in range(300)]
    rng = np.random.default_rng(0)
    run = simulate_run(poses, stamps, office_scene(), CATALOG, rng, config=config, odometry_calibration=tuple(truth))
    problem = build_problem(run.odometry, run.images, config.camera_mount.to_mount(), CATALOG, config)
    return truth, run, problem, config


@pytest.mark.parametrize("dense_object_limit", [40, 0], ids=["schur", "sparse"])
def test_systematic_error_is_recovered_within_its_covariance(drifting, dense_object_limit):
    truth, run, problem, _ = drifting
    problem = dataclasses.replace(
        problem, solver=dataclasses.replace(problem.solver, dense_object_limit=dense_object_limit)
    )
    solution = solve(problem, run.groups(problem), with_covariances=True)
    assert solution.converged
    err = solution.calibration - truth
    assert err @ np.linalg.solve(solution.calibration_cov, err) < chi2.ppf(0.999, 3)
    # The data pin the distance scale and the bias far better than the prior does.
    assert np.sqrt(solution.calibration_cov[0, 0]) < 0.01
    assert np.sqrt(solution.calibration_cov[2, 2]) < 0.01


def test_estimating_the_calibration_makes_the_object_covariances_consistent(drifting):
    _, run, problem, config = drifting
    off_config = dataclasses.replace(
        config, odometry=dataclasses.replace(config.odometry, calibration=OdometryCalibrationConfig(enabled=False))
    )
    off = build_problem(run.odometry, run.images, config.camera_mount.to_mount(), CATALOG, off_config)
    groups = run.groups(problem)
    assert [list(g) for g in groups] == [list(g) for g in run.groups(off)]
    with_calib = solve(problem, groups, with_covariances=True)
    without = solve(off, groups, with_covariances=True)
    seen = [run.objects[j] for j in run.seen_objects()]

    def nees(solution):
        out = []
        for obj, est in zip(seen, solution.objects, strict=True):
            assert est.label == obj.label
            err = est.location_m[:2] - np.asarray(obj.location_m[:2])
            out.append(float(err @ np.linalg.solve(est.location_cov[:2, :2], err)))
        return np.array(out)

    # Mean of 12 chi-square(2) draws: 95 % within [1.2, 3.1] if consistent (correlated here, so looser).
    assert np.mean(nees(with_calib)) < 3.5
    # The random walk alone cannot explain the drift: the objects' covariances are far too small.
    assert np.mean(nees(without)) > 10 * max(np.mean(nees(with_calib)), 1.0)


def test_switched_off_the_graph_has_no_calibration_variable():
    run, problem = run_and_problem(2, 40, config=OFF)
    assert problem.calibration_dim == 0
    on = build_problem(run.odometry, run.images, ON.camera_mount.to_mount(), CATALOG, ON)
    assert on.calibration_dim == 3
    # The prior's normalizer is the only difference of the fixed terms.
    assert on.trajectory_log_normalizer - problem.trajectory_log_normalizer == pytest.approx(
        -0.5 * np.sum(np.log(2 * np.pi * on.calibration_prior_stddev**2))
    )
    solution = solve(problem, run.groups(problem), with_covariances=True)
    assert solution.calibration.shape == (0,)
    assert solution.calibration_cov.shape == (0, 0)


# Solutions of office_run(0, n_poses=60) under its true association by the solver as it was
# before the calibration existed (commit 732468c): (log evidence, chi2, log|Lambda|, iterations,
# x of the last pose, var x of the first object). Bit-identical on the machine that made them;
# the tolerance only leaves room for another BLAS. The variance is the first-pose-anchored
# marginal of then: reported covariances are now about the trajectory (objslam_mapper.graph.gauge).
BEFORE_CALIBRATION = {
    40: (5483.240755505172, 1877.640183351579, 2608.457801002481, 6, -2.979882043802778, 0.00013259660126879443),
    0: (5483.240755505172, 1877.6401833515815, 2608.4578010024807, 6, -2.9798820438027787, 0.00013259660126879762),
}


@pytest.mark.parametrize("dense_object_limit", [40, 0], ids=["schur", "sparse"])
def test_switched_off_the_solution_is_the_one_before_calibration_existed(dense_object_limit):
    from objslam_mapper.synthetic import office_run

    run = office_run(0, n_poses=60)
    # The outlier model (objslam_mapper.model.outliers) came later too: off, every slice is Gaussian.
    config = dataclasses.replace(
        OFF,
        solver=dataclasses.replace(OFF.solver, dense_object_limit=dense_object_limit),
        slice_noise=dataclasses.replace(OFF.slice_noise, outlier_probability=0.0),
    )
    problem = build_problem(run.odometry, run.images, config.camera_mount.to_mount(), CATALOG, config)
    groups = run.groups(problem)
    s = solve(problem, groups, with_covariances=True)
    system = AssociationSystem(problem, layout_of(problem, groups), dense_object_limit)
    objects = np.array([np.r_[o.location_m, o.size_m] for o in s.objects])
    anchored = object_covariance(system, factorize(system, system.linearize(s.map_T_base, objects, s.calibration), 0.0))
    got = (
        s.log_evidence,
        s.chi2,
        s.log_det_information,
        s.iterations,
        s.map_T_base[-1, 0],
        anchored[0, 0, 0],
    )
    expected = BEFORE_CALIBRATION[dense_object_limit]
    assert got[3] == expected[3]
    np.testing.assert_allclose(np.delete(got, 3), np.delete(expected, 3), rtol=1e-12)
