"""Where an oracle map's object errors come from: each measurement group's errors at the ground truth.

Usage: objslam diagnose error-budget BAG [--params FILE] [--calibration DS TS TB]

Solves the ground-truth association of a simulated BAG (as `objslam map --association
oracle` does), then evaluates every factor at the ground truth, taken into the map's
frame by the trajectory fit of `objslam eval`. Linearized at the truth (where the
odometry calibration's bilinear terms leave the MAP's curvature a poor guide), the
estimate's error is ``-Λ⁻¹ (Σ_k J_kᵀ r_k + P (x_true - μ))``: each noise group's whitened errors at
the truth ``r_k`` and each prior's offset of the truth from its mean add their own part.
Slice groups are split into each object's mean error (its bias) and the rest (white or
serially correlated). The objects' errors are taken about the trajectory, as the map's
covariances are (objslam_mapper.graph.gauge). Printed: per object the real error beside the
sum of the parts (the linearization's check), the map's error covariance against the
real base-height error, and per part the root mean square over the objects of the xy
and z errors it makes, beside what the map's error covariance expects of it; last, the
slice biases' parts again with each object's bias replaced by its class's mean, and by
the mean over all objects (biases common to many objects move the map's scale). The truth of the odometry
calibration is the simulator's default (``objslam_tools.sim.motion.OdometryNoise``)
unless given. A diagnostic of the reported covariances (docs/method.md).
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from objslam_common.catalog import load_catalog
from objslam_common.config import default_config_dir, load_config
from objslam_common.geometry import inverse, transform_points, wrap_angle
from objslam_mapper.config import MapperConfig
from objslam_mapper.graph.covariance import noise_groups, prior_scale
from objslam_mapper.graph.error_covariance import owner_rows
from objslam_mapper.graph.factorize import information_matrix
from objslam_mapper.graph.gauge import GAUGE_DIM, object_motion, trajectory_gauge
from objslam_mapper.graph.keyframes import keyframes_of
from objslam_mapper.graph.layout import layout_of
from objslam_mapper.graph.linearize import AssociationSystem, cap_schedule
from objslam_mapper.graph.problem import OBJECT_DIM, POSE_DIM, GraphProblem
from objslam_mapper.graph.solver import GraphSolution, solve
from objslam_tools.trajectory import fit_se2, transform_poses

Z = 2  # z_base in an object's (x, y, z_base, diameter, height)


class ErrorBudget(NamedTuple):
    actual: np.ndarray  # (K, 5) the MAP's object errors about the trajectory
    parts: dict[str, np.ndarray]  # name -> (K, 5) the part of each group or prior (they sum to about `actual`)
    model: dict[str, np.ndarray]  # part -> (K, 5) its stddev as the map's error covariance models it
    shared: dict[str, np.ndarray]  # a slice bias part again, with the objects' biases replaced by common ones
    error_covariance: np.ndarray | None  # (K, 5, 5) what the map reports


def error_budget(
    problem: GraphProblem,
    groups: Sequence[Sequence[int]],
    solution: GraphSolution,
    truth: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> ErrorBudget:
    """The parts of the object errors of ``solution`` (module docstring).

    ``truth`` is (poses (N, 3), objects (K, 5), calibration (C,)) in any frame: it is
    taken into the map's by the least-squares fit of the trajectories.
    """
    keyframes = keyframes_of(problem)
    if keyframes.problem.pose_count != problem.pose_count:
        raise ValueError("the budget needs one graph pose per image (solver.keyframes.enabled: false)")
    layout = layout_of(problem, groups)
    system = AssociationSystem(problem, layout, problem.solver.dense_object_limit)
    poses = np.asarray(solution.map_T_base)
    objects = np.array([np.r_[o.location_m, o.size_m] for o in solution.objects])
    calib = np.asarray(solution.calibration)
    system.cap_scale = cap_schedule(problem, layout, poses, objects, True)[-1]
    shares = problem.solver.error_covariance.bias_shares()
    kept = system.inlier_slices(poses, objects)  # the slices the MAP kept (within their caps there)
    map_information = information_matrix(system, system.linearize(poses, objects, calib))
    priors = map_information - sum(
        (g.jacobian.T @ g.jacobian).toarray() for g in noise_groups(system, poses, objects, calib, shares, kept)
    )

    true_poses, true_objects, true_calib = (np.array(t, dtype=float) for t in truth)
    map_T_truth = inverse(fit_se2(poses[:, :2], true_poses[:, :2]))
    true_poses = transform_poses(map_T_truth, true_poses)
    true_objects[:, :2] = transform_points(map_T_truth, true_objects[:, :2])

    # Linearized at the truth: the odometry calibration enters bilinearly, and along its weak
    # directions the curvature at the MAP, a standard deviation away, predicts the error poorly.
    truth_groups = noise_groups(system, true_poses, true_objects, true_calib, shares, kept)
    covariance = np.linalg.inv(priors + sum((g.jacobian.T @ g.jacobian).toarray() for g in truth_groups))

    k, split = system.n_objects, POSE_DIM * system.n_poses
    rows = np.zeros((OBJECT_DIM * k, system.dimension))
    rows[:, split : split + OBJECT_DIM * k] = np.eye(OBJECT_DIM * k)
    gauge = trajectory_gauge(poses[:, :2], keyframes.images_per_keyframe)
    rows[:, :split] -= object_motion(objects[:, :2], gauge.centroid_xy, OBJECT_DIM).reshape(-1, GAUGE_DIM) @ gauge.rows
    solved = covariance @ rows.T  # X = Λ⁻¹ Rᵀ

    def per_object(vector: np.ndarray) -> np.ndarray:
        return vector.reshape(k, OBJECT_DIM)

    estimate = np.concatenate([poses.ravel(), objects.ravel(), calib])
    true_state = np.concatenate([true_poses.ravel(), true_objects.ravel(), true_calib])
    difference = estimate - true_state
    difference[2:split:POSE_DIM] = wrap_angle(difference[2:split:POSE_DIM])

    parts, model, shared = {}, {}, {}
    for group in truth_groups:
        residual = group.residual
        if group.owner is None:
            parts[group.name] = per_object(-(solved.T @ (group.jacobian.T @ residual)))
            continue
        count = np.maximum(np.bincount(group.owner, minlength=k), 1)
        means = np.bincount(group.owner, weights=residual, minlength=k) / count  # (K,) each object's bias
        mean = means[group.owner]
        parts[f"{group.name} bias"] = per_object(-(solved.T @ (group.jacobian.T @ mean)))
        # The same biases if every object had its class's mean, or all the mean of all objects.
        class_means = np.array([means[layout.labels == label].mean() for label in layout.labels])
        for common, what in ((class_means, "class means"), (np.full(k, means.mean()), "one mean")):
            shared[f"{group.name} bias, {what}"] = per_object(-(solved.T @ (group.jacobian.T @ common[group.owner])))
        parts[f"{group.name} rest"] = per_object(-(solved.T @ (group.jacobian.T @ (residual - mean))))
        # Each object's bias moves every object (through the poses): the stddevs over all of them.
        unit = owner_rows(group, np.ones(len(residual))) @ (group.jacobian @ solved)  # (K owners, 5K)
        model[f"{group.name} bias"] = group.bias_share * per_object(np.sqrt(np.sum(unit**2, axis=0)))

    offsets = np.zeros(system.dimension)  # P (x_true - μ) of the priors
    first = true_poses[0] - problem.odometry_poses[0]
    first[2] = wrap_angle(first[2])
    offsets[:POSE_DIM] = first / problem.first_pose_stddev**2
    offsets[split : split + OBJECT_DIM * k] = ((true_objects - system.prior_mean) * system.prior_inv_sigma**2).ravel()
    if len(calib):
        offsets[-len(calib) :] = true_calib / problem.calibration_prior_stddev**2
    # Each prior's information scaled to the spread of the truth about its mean, as the map's
    # error covariance counts it (objslam_mapper.graph.error_covariance).
    counted = np.diag(priors) * prior_scale(system) ** 2
    calibration_columns = np.arange(split + OBJECT_DIM * k, system.dimension)
    for name, index in (
        ("prior base height", split + OBJECT_DIM * np.arange(k) + Z),
        ("prior size", split + OBJECT_DIM * np.repeat(np.arange(k), 2) + np.tile([3, 4], k)),
        ("prior xy", split + OBJECT_DIM * np.repeat(np.arange(k), 2) + np.tile([0, 1], k)),
        ("prior calibration", calibration_columns),
        ("prior first pose (the gauge)", np.arange(POSE_DIM)),
    ):
        chosen = np.zeros(system.dimension)
        chosen[index] = offsets[index]
        parts[name] = per_object(-(solved.T @ chosen))
        model[name] = per_object(np.sqrt(np.sum(solved[index] ** 2 * counted[index, None], axis=0)))
    error_cov = None
    if all(o.error_cov is not None for o in solution.objects):
        error_cov = np.array([o.error_cov for o in solution.objects])
    return ErrorBudget(per_object(rows @ difference), parts, model, shared, error_cov)


def _rms_xy(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(errors[:, :2] ** 2, axis=1))))


def _rms_z(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(errors[:, Z] ** 2)))


DESCRIPTION = "an oracle map's object errors split into each measurement group's and prior's part"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="a simulated bag (with ground truth)")
    parser.add_argument("--params", metavar="FILE", default=None, help="mapper parameters (default config/mapper.yaml)")
    parser.add_argument(
        "--calibration",
        nargs=3,
        type=float,
        metavar=("DS", "TS", "TB"),
        default=None,
        help="the odometry's true distance scale, turn scale and turn bias (rad/m) (default: the simulator's)",
    )


def run(args: argparse.Namespace) -> int:
    # The oracle map loads the scorer and SciPy (about a second); every objslam verb imports
    # this module to build its parser (objslam_tools.subcommands), so only when run.
    from objslam_tools.oracle_map import oracle_problem
    from objslam_tools.sim.motion import OdometryNoise

    calibration = args.calibration
    if calibration is None:
        default = OdometryNoise()
        calibration = (default.distance_scale, default.turn_scale, default.turn_bias_rad_per_m)
    config = load_config(MapperConfig, args.params or default_config_dir() / "mapper.yaml", "mapper")
    # One graph pose per image, for the truth's poses (as `objslam diagnose aligned-covariance`).
    keyframes = dataclasses.replace(config.solver.keyframes, enabled=False)
    config = dataclasses.replace(config, solver=dataclasses.replace(config.solver, keyframes=keyframes))
    problem, reference, ids, groups = oracle_problem(args.bag, config, load_catalog(config.catalog_file or None))
    solution = solve(problem, groups, with_covariances=True)
    truth_objects = {o.id: o for o in reference.ground_truth.objects}
    true_objects = np.array([np.r_[truth_objects[i].position_m, truth_objects[i].size_m] for i in ids])
    true_poses = reference.ground_truth_track.interpolate(problem.stamps_ns)
    true_calib = np.array(calibration)[: problem.calibration_dim]
    budget = error_budget(problem, groups, solution, (true_poses, true_objects, true_calib))

    predicted = sum(budget.parts.values())
    print(f"{args.bag}: {len(ids)} objects; errors about the trajectory, mm")
    print("  id label     real xy         parts' sum xy     real z  sum z   map's z stddev  z NEES")
    z_nees = []
    for j, i in enumerate(ids):
        real, part = budget.actual[j] * 1e3, predicted[j] * 1e3
        line = (
            f"  {i:2d} {truth_objects[i].label:7s} ({real[0]:6.1f}, {real[1]:6.1f})  ({part[0]:6.1f}, {part[1]:6.1f})"
            f"  {real[Z]:6.1f} {part[Z]:6.1f}"
        )
        if budget.error_covariance is not None:
            var_z = budget.error_covariance[j, Z, Z]
            z_nees.append(budget.actual[j, Z] ** 2 / var_z)
            line += f"   {np.sqrt(var_z) * 1e3:10.1f}   {z_nees[-1]:6.2f}"
        print(line)
    if z_nees:
        print(f"  mean z NEES {np.mean(z_nees):.2f} over {len(z_nees)} objects (1 expected)")
    print("parts: rms over the objects of the errors each makes, mm (model: what the error covariance expects)")
    for name, part in budget.parts.items():
        line = f"  {name:32s} xy {_rms_xy(part) * 1e3:7.2f}   z {_rms_z(part) * 1e3:6.2f}"
        if name in budget.model:
            expected = budget.model[name]
            line += f"   (model: xy {_rms_xy(expected) * 1e3:6.2f}, z {_rms_z(expected) * 1e3:5.2f})"
        print(line)
    print("slice biases made common: each object's bias replaced by its class's mean, or by the mean of all")
    for name, part in budget.shared.items():
        print(f"  {name:44s} xy {_rms_xy(part) * 1e3:7.2f}   z {_rms_z(part) * 1e3:6.2f}")
    return 0
