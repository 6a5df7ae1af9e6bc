"""The max-mixture slice likelihood (objslam_mapper.model.outliers) and what it does to a solve."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from objslam_common.catalog import load_catalog
from objslam_common.records import ImageSlices
from objslam_mapper.config import GraphConfig
from objslam_mapper.graph.problem import build_problem, gaussian_log_normalizer
from objslam_mapper.graph.solver import solve
from objslam_mapper.model.outliers import half_chi2, inlier_log_weight, outlier_cost, truncate
from objslam_mapper.synthetic import SyntheticObject, ellipse_trajectory, simulate_run

CATALOG = load_catalog()
CONFIG = GraphConfig()
STDDEV = np.array([0.006, 0.012, 0.01, 0.01])


@settings(max_examples=50, deadline=None)
@given(
    st.floats(1e-4, 0.3),
    st.floats(1.0, 100.0),
    st.lists(st.floats(-60.0, 60.0), min_size=4, max_size=4),
)
def test_the_capped_cost_is_the_larger_mixture_component(probability, volume, residual):
    """-log max((1 - eps) N(r), eps / V) = -log(1 - eps) - log N_0 + min(q, tau), and it is
    within log 2 of the mixture's -log((1 - eps) N(r) + eps / V)."""
    log_n0 = float(gaussian_log_normalizer(STDDEV))
    tau = float(outlier_cost(np.array([log_n0]), probability, volume)[0])
    whitened = np.array(residual, dtype=float)[:, None]
    q = float(half_chi2(whitened)[0])
    inlier = truncate(whitened, np.array([tau]))
    capped = float(half_chi2(whitened)[0])
    assert capped == pytest.approx(min(q, tau), rel=1e-12)
    assert bool(inlier[0]) == (q <= tau)
    gaussian = math.log1p(-probability) + log_n0 - q
    uniform = math.log(probability / volume)
    max_mixture = -inlier_log_weight(probability) - log_n0 + capped
    assert max_mixture == pytest.approx(-max(gaussian, uniform), abs=1e-9)
    mixture = -np.logaddexp(gaussian, uniform)
    assert -1e-9 <= max_mixture - mixture <= math.log(2.0) + 1e-9


def test_no_outlier_probability_means_no_cap():
    assert np.all(np.isinf(outlier_cost(np.array([1.0, 2.0]), 0.0, 10.0)))
    assert inlier_log_weight(0.0) == 0.0
    whitened = np.full((4, 2), 1e3)
    assert truncate(whitened, np.full(2, np.inf)).all() and (whitened == 1e3).all()


def test_the_default_cap_is_near_seven_sigma():
    """With the default noise a floor object's slice turns outlier beyond chi-square ~46."""
    noise = CONFIG.slice_noise
    log_n0 = float(gaussian_log_normalizer(STDDEV))
    tau = float(outlier_cost(np.array([log_n0]), noise.outlier_probability, noise.outlier_volume_rad4)[0])
    assert 40.0 < 2.0 * tau < 50.0
    assert tau == pytest.approx(log_n0 + math.log(0.99) - math.log(0.01 / 22.746), abs=1e-9)


SCENE = (
    SyntheticObject("red", (2.2, 0.3, 0.0), (0.31, 0.58)),
    SyntheticObject("green", (-0.5, 1.0, 0.0), (0.41, 0.39)),
    SyntheticObject("blue", (0.8, -1.1, 0.0), (0.21, 0.88)),
)


def _run_with_merged_blobs(seed: int = 3, corrupted: int = 4):
    """A run whose red object's last slices are blobs merged with a wider neighbour beside
    it: 2.5 times as wide and their bearing pulled a width aside (tens of sigma)."""
    poses = ellipse_trajectory(40, (3.0, 1.8))
    stamps = [k * 250_000_000 for k in range(40)]
    run = simulate_run(poses, stamps, SCENE, CATALOG, np.random.default_rng(seed), config=CONFIG)
    images = list(run.images)
    red = [(k, i) for k, image in enumerate(images) for i, s in enumerate(image.slices) if s.label == "red"]
    for k, i in red[-corrupted:]:
        s = images[k].slices[i]
        wider = 2.5 * s.angular_width_rad
        merged = dataclasses.replace(s, bearing_rad=s.bearing_rad + s.angular_width_rad, angular_width_rad=wider)
        images[k] = ImageSlices(
            images[k].stamp_ns, tuple(merged if j == i else x for j, x in enumerate(images[k].slices))
        )
    return run, images


def test_merged_blobs_become_outliers_and_leave_the_object_where_it_is():
    run, images = _run_with_merged_blobs()
    mount = CONFIG.camera_mount.to_mount()
    robust = build_problem(run.odometry, images, mount, CATALOG, CONFIG)
    gaussian_config = dataclasses.replace(
        CONFIG, slice_noise=dataclasses.replace(CONFIG.slice_noise, outlier_probability=0.0)
    )
    gaussian = build_problem(run.odometry, images, mount, CATALOG, gaussian_config)
    clean = build_problem(run.odometry, run.images, mount, CATALOG, CONFIG)
    groups = run.groups(robust)

    def red(problem):
        solution = solve(problem, groups)
        return np.r_[solution.objects[0].location_m, solution.objects[0].size_m], solution

    reference, _ = red(clean)  # the same slices, none merged
    robust_red, solution = red(robust)
    gaussian_red, _ = red(gaussian)
    assert np.abs(gaussian_red - reference).max() > 0.01  # the merged blobs drag a Gaussian fit aside
    np.testing.assert_allclose(robust_red, reference, atol=1e-3)
    # Exactly the corrupted slices are beyond their cap at the MAP: cost tau each, no information.
    from objslam_mapper.graph.layout import layout_of
    from objslam_mapper.graph.linearize import count_outliers

    layout = layout_of(robust, groups)
    objects = np.array([np.r_[o.location_m, o.size_m] for o in solution.objects])
    assert count_outliers(robust, layout, np.asarray(solution.map_T_base), objects) == 4


def test_a_cold_solve_from_drifted_odometry_still_fits_every_slice():
    """Started from odometry that drifted well beyond the caps, the Gaussian first phase
    pulls the poses in; the truncated cost alone would leave the drifted slices out."""
    poses = ellipse_trajectory(60, (3.0, 1.8))
    stamps = [k * 250_000_000 for k in range(60)]
    run = simulate_run(poses, stamps, SCENE, CATALOG, np.random.default_rng(6), config=CONFIG, odometry_noise_scale=3.0)
    problem = build_problem(run.odometry, run.images, CONFIG.camera_mount.to_mount(), CATALOG, CONFIG)
    groups = run.groups(problem)
    from objslam_mapper.graph.layout import layout_of
    from objslam_mapper.graph.linearize import count_outliers

    layout = layout_of(problem, groups)
    starts = np.array([np.r_[o.location_m, o.size_m] for o in SCENE])
    # At the odometry and the true objects most slices are beyond their cap ...
    assert count_outliers(problem, layout, np.asarray(problem.odometry_poses), starts) > 0.5 * problem.measurement_count
    solution = solve(problem, groups)
    objects = np.array([np.r_[o.location_m, o.size_m] for o in solution.objects])
    # ... at the solve's MAP none is, and the objects are where they are.
    assert count_outliers(problem, layout, np.asarray(solution.map_T_base), objects) == 0
    assert np.abs(objects - starts).max() < 0.03
