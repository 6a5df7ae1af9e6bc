"""The fast solver's Levenberg-Marquardt loop: objects no slice places, and when it has converged."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from objslam_mapper.config import SolverConfig
from objslam_mapper.graph import solver as solver_module
from objslam_mapper.graph.factorize import Factorization, factorize
from objslam_mapper.graph.gtsam_backend import _drive_python, _Linearizer, build_gtsam_graph
from objslam_mapper.graph.keyframes import keyframes_of
from objslam_mapper.graph.layout import layout_of
from objslam_mapper.graph.linearize import AssociationSystem, Linearization
from objslam_mapper.graph.solver import hold_lost_objects, lost_objects, solve
from tests.objslam_mapper.graph.test_graph import SOLVERS, make_run, with_limit
from tests.objslam_mapper.graph_scenes import CONFIG

FAR_XY_M = np.array([30.0, 20.0])  # where the first object is put: every one of its slices beyond its cap


def lost_first_object(dense_object_limit: int = 40):
    """A solved scene's system at the true caps, its solution's state with the first object
    moved FAR_XY_M away, and that solution."""
    run, problem = make_run(3, solve_config=with_limit(CONFIG, dense_object_limit))
    groups = run.groups(problem)
    solved = solve(problem, groups)
    graph_problem = keyframes_of(problem).problem
    system = AssociationSystem(graph_problem, layout_of(graph_problem, groups), dense_object_limit)
    system.cap_scale = 1.0
    poses = keyframes_of(problem).restrict(np.array(solved.map_T_base))
    objects = np.array([np.r_[o.location_m, o.size_m] for o in solved.objects])
    objects[0, :2] = FAR_XY_M
    return system, (poses, objects, np.zeros(graph_problem.calibration_dim)), solved


def test_an_object_whose_slices_are_all_beyond_their_caps_is_lost():
    system, state, _ = lost_first_object()
    lin = system.linearize(*state)
    assert lin.outliers == len(system.layout.groups[0])
    assert lost_objects(system, lin).tolist() == [True] + [False] * (system.n_objects - 1)


@pytest.mark.parametrize("damping", [0.0, 0.5])
def test_a_lost_object_is_held_and_the_rest_of_the_step_is_unchanged(damping):
    system, state, _ = lost_first_object()
    lin = system.linearize(*state)
    free = factorize(system, lin, damping)
    held = dataclasses.replace(free, step_object=free.step_object.copy())
    hold_lost_objects(lin, held, damping, lost_objects(system, lin))
    # Held by its prior alone, the Gauss-Newton step jumps the object toward the prior's
    # mean (the first pose, where the robot stood): that jump is what is dropped.
    offset = FAR_XY_M - system.prior_mean[0, :2]
    np.testing.assert_allclose(free.step_object[:2], -offset / (1.0 + damping), rtol=1e-6)
    np.testing.assert_array_equal(held.step_object[:2], 0.0)
    np.testing.assert_array_equal(held.step_object[2:], free.step_object[2:])
    np.testing.assert_array_equal(held.step_pose, free.step_pose)
    # The model's decrease loses exactly what that jump predicted: 1/2 (-g s + damping d s^2).
    information = system.prior_inv_sigma[0, :2] ** 2
    gradient, step = offset * information, free.step_object[:2]
    dropped = 0.5 * np.sum(-gradient * step + damping * information * step**2)
    assert free.predicted_decrease - held.predicted_decrease == pytest.approx(dropped, rel=1e-9)


@SOLVERS
def test_a_lost_object_starts_again_from_its_own_slices(dense_object_limit):
    system, state, solved = lost_first_object(dense_object_limit)
    lin = system.linearize(*state)
    (_, objects, _), lin, _, _, converged = solver_module._minimize(system, state, lin, SolverConfig(), 50)
    assert converged
    np.testing.assert_allclose(objects[0, :2], solved.objects[0].location_m[:2], atol=0.01)
    assert lin.cost == pytest.approx(0.5 * solved.chi2, abs=0.01)


def test_gtsam_finds_a_lost_object_again_as_the_fast_solver_does():
    system, state, _ = lost_first_object()
    problem, layout = system.problem, system.layout
    ours, ours_lin, *_ = solver_module._minimize(system, state, system.linearize(*state), SolverConfig(), 50)
    graph, keys = build_gtsam_graph(problem, layout.groups, cap_scale=1.0)
    linearize = _Linearizer(graph, keys, problem, layout)
    start = keys.to_values(*state)
    assert linearize.lost(linearize(start)).tolist() == [True] + [False] * (system.n_objects - 1)
    driven = _drive_python(linearize, start, SolverConfig(), 50)
    assert driven.converged
    _, objects = keys.from_values(driven.values)
    np.testing.assert_allclose(objects, ours[1], atol=1e-3)
    assert driven.linear.cost == pytest.approx(ours_lin.cost, abs=0.01)


# -- when the loop has converged ----------------------------------------------------------------


def minimize_after_failures(monkeypatch, failures: int, check_undamped: bool = True):
    """The loop from an optimum, its first ``failures`` factorizations failing
    (each raises the damping, by a growing factor, as where the information is not positive
    definite or a step fails): (iterations, converged, factorizations)."""
    system, state, _ = lost_first_object()
    state, lin, *_ = solver_module._minimize(system, state, system.linearize(*state), SolverConfig(), 50)
    calls = []

    def failing(graph, lin, damping, **kwargs):
        calls.append(damping)
        if len(calls) <= failures:
            raise np.linalg.LinAlgError("not positive definite")
        return factorize(graph, lin, damping, **kwargs)

    monkeypatch.setattr(solver_module, "factorize", failing)
    if not check_undamped:
        monkeypatch.setattr(solver_module, "_undamped", lambda *_args: None)
    *_, iterations, converged = solver_module._minimize(system, state, lin, SolverConfig(), 50)
    return iterations, converged, calls


def test_at_an_optimum_a_damped_loop_converges_on_the_undamped_step(monkeypatch):
    iterations, converged, calls = minimize_after_failures(monkeypatch, failures=7)
    assert calls[7] > 100.0  # the damping when the factorizations succeed again
    assert converged and iterations == 1
    assert calls[-1] == 0.0  # the last factorization: the undamped one, which decided


def test_without_the_undamped_step_a_damped_loop_creeps_to_convergence(monkeypatch):
    """What the check saves: each step that stops short shrinks the damping by 3 at most, and
    only at initial_lambda did the loop look at a nearly undamped step."""
    iterations, converged, _ = minimize_after_failures(monkeypatch, failures=7, check_undamped=False)
    assert converged and iterations > 10


KINK = 0.05  # slopes KINK and -2 KINK either side of the optimum, as where a slice sits at its cap's edge


class KinkedSystem:
    """One variable (a pose's x) with cost 1/2 x^2 + KINK x (x > 0) or 1/2 x^2 - 2 KINK x
    (x < 0), linearized as Gauss-Newton sees it from the side it is on (information 1)."""

    n_objects = 0

    def linearize(self, poses, objects, calib):
        x = float(poses[0, 0])
        slope = KINK if x > 0.0 else -2.0 * KINK
        return Linearization(cost=0.5 * x**2 + slope * x, valid=True, grad_pose=np.array([x + slope, 0.0, 0.0]))


def kinked_factorize(system, lin, damping, **_kwargs):
    step = -lin.grad_pose / (1.0 + damping)
    predicted = 0.5 * float(-lin.grad_pose @ step + damping * step @ step)
    return Factorization(0.0, step, np.zeros(0), predicted, np.zeros(0))


def test_a_kink_whose_undamped_step_predicts_more_than_the_tolerance_is_no_convergence(monkeypatch):
    """Damped steps there predict nothing, but the undamped one predicts at least 1/2 KINK^2
    > 1e-4: the loop must not call that converged (it gives up at max_lambda)."""
    monkeypatch.setattr(solver_module, "factorize", kinked_factorize)
    system = KinkedSystem()
    state = (np.array([[1.0, 0.0, 0.0]]), np.zeros((0, 5)), np.zeros(0))
    (poses, _, _), _, _, iterations, converged = solver_module._minimize(
        system, state, system.linearize(*state), SolverConfig(), 500
    )
    assert abs(float(poses[0, 0])) < 1e-3  # at the kink
    assert not converged and iterations < 500
