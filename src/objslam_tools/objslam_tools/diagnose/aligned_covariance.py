"""Covariance of the object errors that `objslam eval` measures, on an oracle map (the NEES of its covariances).

Usage: objslam diagnose aligned-covariance BAG [--params FILE]

`objslam eval` aligns the map to the ground truth by a least-squares SE(2) fit of the
trajectory before it measures object errors; a map's covariances are about the trajectory
(objslam_mapper.graph.gauge) for that reason, where the graph's plain marginals are anchored at
its first pose. This script works with the posterior (the configured noise; a map reports
the covariance of the estimate's error instead, objslam_mapper.graph.error_covariance): it solves
the ground-truth association of BAG once,
takes the joint covariance of all poses and objects from the solver's (sparse) normal
equations, and propagates it through the linearized trajectory fit: the covariance of
exactly the error `objslam eval` measures. Per object it prints that error, the map's
marginal standard deviations and the aligned ones, and how well the aligned major axis
lines up with the direction from the trajectory's centre (|cos| = 1: radial, a scale
mode); then the mean NEES both ways, and the NEES of all objects at once with their
correlations (which a mean of per-object NEES ignores). A diagnostic of the reported covariances (docs/method.md).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from objslam_common.catalog import load_catalog
from objslam_common.config import default_config_dir, load_config
from objslam_mapper.config import MapperConfig
from objslam_mapper.graph.factorize import factorize
from objslam_mapper.graph.gauge import object_motion, trajectory_gauge
from objslam_mapper.graph.layout import layout_of
from objslam_mapper.graph.linearize import AssociationSystem, cap_schedule
from objslam_mapper.graph.problem import OBJECT_DIM, POSE_DIM
from objslam_mapper.graph.solver import solve
from objslam_tools.trajectory import PoseTrack


def joint_covariance(problem, groups, solution) -> np.ndarray:
    """Inverse of the whole information matrix at the solution (poses, then objects, then calibration)."""
    layout = layout_of(problem, groups)
    system = AssociationSystem(problem, layout, dense_object_limit=-1)  # sparse LU: every variable
    objects = np.array([np.concatenate([o.location_m, o.size_m]) for o in solution.objects])
    system.cap_scale = cap_schedule(problem, layout, solution.map_T_base, objects, True)[-1]
    lin = system.linearize(np.array(solution.map_T_base), objects, np.array(solution.calibration))
    factorization = factorize(system, lin, 0.0)
    return factorization.sparse_lu.solve(np.eye(system.dimension))


def alignment_jacobian(track_xy: np.ndarray, point_xy: np.ndarray, n_variables: int, column: int) -> np.ndarray:
    """(2, n) map from the state error to a point's error after the trajectory fit (linearized).

    The package's own gauge (objslam_mapper.graph.gauge), written out over the whole state:
    the point's error less the rigid motion fitted to the pose errors, ``E - M G``.
    """
    gauge = trajectory_gauge(track_xy)
    jacobian = np.zeros((2, n_variables))
    jacobian[:, : gauge.rows.shape[1]] = -object_motion(point_xy[None], gauge.centroid_xy, 2)[0] @ gauge.rows
    jacobian[:, column : column + 2] += np.eye(2)
    return jacobian


DESCRIPTION = "covariance of the object errors objslam eval measures, on the oracle map (NEES, joint NEES)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="a simulated bag (with ground truth)")
    parser.add_argument("--params", metavar="FILE", default=None, help="mapper parameters (default config/mapper.yaml)")


def run(args: argparse.Namespace) -> int:
    # SciPy's stats, the scorer and the oracle map take about a second to load, and every
    # objslam verb imports this module to build its parser (objslam_tools.subcommands).
    from scipy.stats import chi2

    from objslam_tools.evaluate import align_track, nees_summary
    from objslam_tools.oracle_map import oracle_problem

    config = load_config(MapperConfig, args.params or default_config_dir() / "mapper.yaml", "mapper")
    # One graph pose per image: the fit below is over the poses the map reports.
    keyframes = dataclasses.replace(config.solver.keyframes, enabled=False)
    config = dataclasses.replace(config, solver=dataclasses.replace(config.solver, backend="fast", keyframes=keyframes))
    problem, reference, truth_ids, groups = oracle_problem(args.bag, config, load_catalog(config.catalog_file or None))
    solution = solve(problem, groups)
    covariance = joint_covariance(problem, groups, solution)

    poses = np.asarray(solution.map_T_base)
    alignment = align_track(PoseTrack(problem.stamps_ns, poses), reference.ground_truth_track)
    truth = {o.id: o for o in reference.ground_truth.objects}
    first_object = POSE_DIM * problem.pose_count
    centre = poses[:, :2].mean(axis=0)
    marginal_nees, aligned_nees, jacobians, errors = [], [], [], []
    print(f"{args.bag}: {len(groups)} objects, {problem.pose_count} poses")
    print("  truth  error m  marginal sd m      aligned sd m     |cos| radial  distance m")
    for j, truth_id in enumerate(truth_ids):
        estimate_xy = np.asarray(solution.objects[j].location_m[:2])
        error = estimate_xy - alignment.to_map(truth[truth_id].position_m[:2])[0]
        column = first_object + OBJECT_DIM * j
        marginal = covariance[column : column + 2, column : column + 2]
        jacobian = alignment_jacobian(poses[:, :2], estimate_xy, len(covariance), column)
        aligned = jacobian @ covariance @ jacobian.T
        values, vectors = np.linalg.eigh(aligned)
        radial = estimate_xy - centre
        cos = abs(vectors[:, -1] @ radial) / np.linalg.norm(radial)
        jacobians.append(jacobian)
        errors.append(error)
        marginal_nees.append(float(error @ np.linalg.solve(marginal, error)))
        aligned_nees.append(float(error @ np.linalg.solve(aligned, error)))
        print(
            f"  {truth_id:5d}  {np.linalg.norm(error):7.3f}  "
            f"{np.array2string(np.sqrt(np.linalg.eigvalsh(marginal)), precision=3):>15s}  "
            f"{np.array2string(np.sqrt(values), precision=3):>15s}  {cos:12.2f}  {np.linalg.norm(radial):10.1f}"
        )
    ways = (("marginal, first pose anchored", marginal_nees), ("about the trajectory (the posterior)", aligned_nees))
    for name, values in ways:
        summary = nees_summary(values, 2)
        print(f"  mean NEES xy, {name}: {summary.mean:.2f}  95 % band [{summary.band[0]:.2f}, {summary.band[1]:.2f}]")
    # All objects at once with their correlations: one chi-square of 2K degrees of freedom.
    stacked = np.vstack(jacobians)
    error = np.concatenate(errors)
    joint = float(error @ np.linalg.solve(stacked @ covariance @ stacked.T, error))
    low, high = chi2.ppf([0.025, 0.975], len(error))
    print(f"  joint NEES xy, aligned, all objects: {joint:.1f}  95 % band [{low:.1f}, {high:.1f}] ({len(error)} dof)")
    return 0
