"""The linearized trajectory fit of `objslam diagnose aligned-covariance` against the fit itself."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from objslam_tools.diagnose import aligned_covariance
from objslam_tools.trajectory import fit_se2, transform_poses


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_the_alignment_jacobian_predicts_the_error_left_after_the_fit(seed):
    rng = np.random.default_rng(seed)
    n = 30
    track_xy = np.cumsum(rng.normal(0.0, 0.5, (n, 2)), axis=0)
    point_xy = rng.normal(0.0, 3.0, 2)
    column = 3 * n
    error = np.zeros(3 * n + 2)
    error[: 3 * n].reshape(n, 3)[:, :2] = rng.normal(0.0, 1e-4, (n, 2))
    error[column:] = rng.normal(0.0, 1e-4, 2)

    estimate_track = track_xy + error[: 3 * n].reshape(n, 3)[:, :2]
    gt_T_estimate = fit_se2(estimate_track, track_xy)
    estimate_point = np.concatenate([point_xy + error[column:], [0.0]])
    left = transform_poses(gt_T_estimate, estimate_point[None, :])[0, :2] - point_xy

    jacobian = aligned_covariance.alignment_jacobian(track_xy, point_xy, len(error), column)
    np.testing.assert_allclose(jacobian @ error, left, atol=1e-7)
