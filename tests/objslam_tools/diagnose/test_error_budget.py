"""`objslam diagnose error-budget`: the parts of an oracle map's object errors add up to the errors."""

from __future__ import annotations

import numpy as np

from objslam_mapper.graph.problem import build_problem
from objslam_mapper.graph.solver import solve
from objslam_mapper.synthetic import ellipse_trajectory, simulate_run
from objslam_tools.diagnose import error_budget
from tests.objslam_mapper.graph_scenes import CATALOG, CONFIG, MOUNT, STEP_NS, draw_scene


def test_the_parts_add_up_to_the_errors_about_the_trajectory():
    rng = np.random.default_rng(3)
    poses = ellipse_trajectory(60, (3.0, 1.8))
    calibration = (0.02, -0.02, 0.001)
    run = simulate_run(
        poses,
        [k * STEP_NS for k in range(60)],
        draw_scene(rng, 0.0),
        CATALOG,
        rng,
        config=CONFIG,
        odometry_calibration=calibration,
    )
    problem = build_problem(run.odometry, run.images, MOUNT, CATALOG, CONFIG)
    groups = run.groups(problem)
    solution = solve(problem, groups, with_covariances=True)
    seen = run.seen_objects()
    objects = np.array([np.r_[run.objects[j].location_m, run.objects[j].size_m] for j in seen])
    budget = error_budget.error_budget(problem, groups, solution, (run.true_map_T_base, objects, np.array(calibration)))
    total = sum(budget.parts.values())
    assert np.abs(budget.actual[:, :3]).max() > 1e-3  # there is an error to explain
    np.testing.assert_allclose(total[:, :3], budget.actual[:, :3], atol=0.1 * np.abs(budget.actual[:, :3]).max())
    assert {"elevation_bottom bias", "prior size", "prior calibration"} <= set(budget.model)
