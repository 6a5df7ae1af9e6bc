"""Short-lived objects folded into the pose band: the same step and log-determinant as the
plain dense path, for every fold, damped or not; and the cost model folds where it pays."""

from __future__ import annotations

import numpy as np
import pytest

from objslam_common.records import ImageSlices
from objslam_mapper.graph.factorize import _factorize_schur, factorize
from objslam_mapper.graph.fold import _spans, fold_plan, fold_up_to
from objslam_mapper.graph.keyframes import keyframes_of
from objslam_mapper.graph.layout import layout_of
from objslam_mapper.graph.linearize import AssociationSystem
from objslam_mapper.graph.problem import build_problem
from objslam_mapper.graph.solver import initial_calibration, initial_state, solve
from objslam_mapper.synthetic import ellipse_trajectory, simulate_run
from tests.objslam_mapper.graph_scenes import CATALOG, CONFIG, MOUNT, SCENE, STEP_NS


def _problem(seed: int, n_poses: int = 60):
    poses = ellipse_trajectory(n_poses, (3.0, 1.8))
    stamps = [k * STEP_NS for k in range(n_poses)]
    run = simulate_run(poses, stamps, SCENE, CATALOG, np.random.default_rng(seed), config=CONFIG)
    images = list(run.images)
    # One image sees a thing twice (a blob split in two): a folded object's two slices at one pose.
    images[5] = ImageSlices(images[5].stamp_ns, (*images[5].slices, images[5].slices[0]))
    return build_problem(run.odometry, images, MOUNT, CATALOG, CONFIG)


def _tracklet_groups(problem, window: int, whole: int = 1):
    """Each class's slices cut into runs of ``window`` poses (tracklets as objects, as a chain
    from singletons holds them), but the first ``whole`` classes kept whole (long-lived objects)."""
    groups = []
    for rank, label in enumerate(sorted({problem.label_of(m) for m in range(problem.measurement_count)})):
        members = np.array([m for m in range(problem.measurement_count) if problem.label_of(m) == label])
        if rank < whole:
            groups.append(members)
            continue
        cut = problem.measurement_pose[members] // window
        groups += [members[cut == c] for c in np.unique(cut)]
    return groups


@pytest.fixture(scope="module")
def system_at_map():
    problem = _problem(3)
    groups = _tracklet_groups(problem, window=6)
    solution = solve(problem, groups)
    keyframes = keyframes_of(problem)
    layout = layout_of(keyframes.problem, groups)
    system = AssociationSystem(keyframes.problem, layout, dense_object_limit=10_000)
    poses, objects = initial_state(keyframes, layout, solution)
    lin = system.linearize(poses, objects, initial_calibration(keyframes.problem, solution))
    # Away from the optimum, so that the steps are not ~0.
    lin_off = system.linearize(poses + 0.01, objects * 1.02, initial_calibration(keyframes.problem, solution))
    return system, lin, lin_off


@pytest.mark.parametrize("damping", [0.0, 1e-2])
def test_every_fold_gives_the_plain_step_and_log_determinant(system_at_map, damping):
    system, _, lin = system_at_map
    plain = _factorize_schur(system, lin, damping, None)
    spans = np.unique(_spans(system.layout))
    assert len(spans) >= 3 and system.n_objects >= 10
    for limit in spans:
        plan = fold_up_to(system.layout, int(limit))
        assert len(plan.folded) >= 1
        folded = _factorize_schur(system, lin, damping, plan)
        assert folded.folded and not plain.folded
        assert folded.log_det == pytest.approx(plain.log_det, rel=1e-12, abs=1e-9)
        scale = np.abs(plain.step_pose).max()
        assert scale > 1e-6
        np.testing.assert_allclose(folded.step_pose, plain.step_pose, atol=1e-9 * scale)
        np.testing.assert_allclose(folded.step_object, plain.step_object, atol=1e-9 * np.abs(plain.step_object).max())
        np.testing.assert_allclose(folded.step_calib, plain.step_calib, atol=1e-9 * scale)


def test_a_slice_seen_twice_at_one_pose_is_summed_into_one_observation(system_at_map):
    system, _, _ = system_at_map
    layout = system.layout
    plan = fold_up_to(layout, int(_spans(layout).max()))
    assert len(plan.slice_order) > len(plan.obs_pose)  # the duplicated slice shares its observation
    pairs = np.stack([plan.obs_object, plan.obs_pose], axis=1)
    assert len(np.unique(pairs, axis=0)) == len(pairs)


def test_the_cost_model_folds_short_objects_and_leaves_a_map_of_long_ones():
    problem = _problem(4, n_poses=300)
    keyframes = keyframes_of(problem)
    short = layout_of(keyframes.problem, _tracklet_groups(keyframes.problem, window=5))
    plan = fold_plan(short)
    assert plan is not None and len(plan.folded) > len(plan.kept)
    whole = layout_of(keyframes.problem, _tracklet_groups(keyframes.problem, window=10**6))
    assert fold_plan(whole) is None


def test_the_covariances_get_an_unfolded_factorization(system_at_map):
    system, lin, _ = system_at_map
    fac = factorize(system, lin, 0.0, fold=False)
    assert not fac.folded and fac.chol_schur is not None
    forced = _factorize_schur(system, lin, 0.0, fold_up_to(system.layout, 6))
    assert forced.chol_schur is None and forced.chol_pose is None
