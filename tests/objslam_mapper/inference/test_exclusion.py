"""Objects are solid (objslam_mapper.inference.exclusion): the no-overlap term and what it does to the target."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from objslam_mapper.config import ClutterConfig
from objslam_mapper.graph.solver import solve
from objslam_mapper.inference.association import Association
from objslam_mapper.inference.exclusion import near_pairs, no_overlap_log_probability, pairs_log_probability
from objslam_mapper.inference.target import AssociationTarget, TargetOptions
from objslam_mapper.inference.tracklets import tracklets_of_problem
from tests.objslam_mapper.association_scenes import problem_of, simulate


@pytest.fixture(scope="module")
def scene():
    run = simulate()
    problem = problem_of(run)
    chained = tracklets_of_problem(problem)
    return run, problem, chained


def _objects(solution, k=None):
    return np.array([np.r_[o.location_m, o.size_m] for o in solution.objects[:k]])


def test_objects_far_apart_cost_nothing(scene):
    run, problem, _ = scene
    groups = run.groups(problem)
    solution = solve(problem, groups)
    rows = [int(problem.measurement_label[g[0]]) for g in groups]
    value = no_overlap_log_probability(problem, solution.map_T_base, _objects(solution), groups, rows)
    assert value == 0.0  # the closest pair (two reds 0.8 m apart) is far clear of touching


@pytest.mark.parametrize("gap_m", [0.03, 0.01, 0.0, -0.01])
def test_a_pair_pays_the_gaussian_probability_that_its_footprints_overlap(gap_m):
    """The term for one pair against a Monte Carlo of the same Gaussian."""
    rng = np.random.default_rng(0)
    first = np.array([1.0, 2.0, 0.0, 0.30, 0.60])
    second = np.array([1.0, 2.0, 0.0, 0.40, 0.40])
    second[:2] += np.array([0.6, 0.8]) * (0.35 + gap_m)  # footprints gap_m apart (negative: overlapping)
    # Centimetre stddevs, correlated (as a map's): the linearization's curvature error is then negligible.
    root = rng.normal(size=(2, 5, 5)) * 0.004
    covariances = {k: root[k] @ root[k].T + np.diag([1e-4, 4e-5, 1e-5, 4e-5, 1e-5]) for k in range(2)}
    value = pairs_log_probability(np.vstack([first, second]), covariances, (np.array([0]), np.array([1])))
    draws = [rng.multivariate_normal(o, covariances[k], 400_000) for k, o in enumerate((first, second))]
    apart = np.hypot(*(draws[1][:, :2] - draws[0][:, :2]).T) > 0.5 * (draws[0][:, 3] + draws[1][:, 3])
    assert np.exp(value) == pytest.approx(apart.mean(), abs=0.01)


def test_only_near_pairs_are_evaluated():
    objects = np.array([[0.0, 0.0, 0, 0.3, 0.6], [0.5, 0.0, 0, 0.3, 0.6], [3.0, 0.0, 0, 0.3, 0.6]])
    i, j = near_pairs(objects)
    assert list(zip(i, j, strict=True)) == [(0, 1)]


def test_a_duplicate_on_its_object_pays_for_the_overlap(scene):
    """The green tracklet cut in two (alternate slices) and made two objects: both sit on
    one spot. The no-overlap term charges that state heavily and leaves the one-object state alone."""
    run, problem, chained = scene
    green = chained.labels.index("green")
    members = chained.tracklets[green].measurement_indices
    assert len(members) > 10
    halves = (members[::2], members[1::2])
    cut = [t for k, t in enumerate(chained.tracklets) if k != green]
    cut += [dataclasses.replace(chained.tracklets[green], measurement_indices=tuple(h)) for h in halves]
    solid = AssociationTarget(problem, cut, TargetOptions(clutter=ClutterConfig()))
    plain = AssociationTarget(problem, cut, TargetOptions(clutter=ClutterConfig(), exclusion=False))
    # The other tracklets by their true objects (each red object is seen twice).
    true_object = {int(m): k for k, group in enumerate(run.groups(problem)) for m in group}
    others = [true_object[t.measurement_indices[0]] for t in cut[:-2]]
    fresh = max(true_object.values()) + 1
    together = Association.of([*others, fresh, fresh])
    apart = Association.of([*others, fresh, fresh + 1])
    assert solid(together) == pytest.approx(plain(together), abs=1e-9)
    assert solid(apart) < plain(apart) - 50.0
    assert solid(together) > solid(apart) + 50.0
