"""Edges the view cut off are bounds: which component bounds which way, and the one-sided cost."""

from __future__ import annotations

import numpy as np
import pytest

from objslam_common.records import CUT_BOTTOM, CUT_LEFT, CUT_RIGHT, CUT_TOP
from objslam_mapper.model.slice_model import (
    LOWER_BOUND,
    MEASURED,
    UNMEASURED,
    UPPER_BOUND,
    bounds_of_cuts,
    censor,
)


@pytest.mark.parametrize(
    ("cuts", "at_view_top", "expected"),
    [
        (0, False, [MEASURED, MEASURED, MEASURED, MEASURED]),
        (0, True, [MEASURED, MEASURED, MEASURED, LOWER_BOUND]),
        (CUT_LEFT, False, [LOWER_BOUND, LOWER_BOUND, MEASURED, MEASURED]),  # the object reaches further ccw
        (CUT_RIGHT, False, [UPPER_BOUND, LOWER_BOUND, MEASURED, MEASURED]),
        (CUT_LEFT | CUT_RIGHT, False, [UNMEASURED, LOWER_BOUND, MEASURED, MEASURED]),
        (CUT_TOP, False, [MEASURED, MEASURED, MEASURED, LOWER_BOUND]),
        (CUT_BOTTOM, False, [MEASURED, MEASURED, UPPER_BOUND, MEASURED]),
        (15, False, [UNMEASURED, LOWER_BOUND, UPPER_BOUND, LOWER_BOUND]),
    ],
)
def test_each_cut_edge_bounds_its_components(cuts, at_view_top, expected):
    assert bounds_of_cuts([cuts], [at_view_top]).tolist() == [expected]


def test_a_bound_costs_only_on_its_wrong_side():
    bounds = np.array([[LOWER_BOUND, UPPER_BOUND, UNMEASURED, MEASURED]] * 2, dtype=np.int8)
    error = np.array([[0.1, -0.1], [0.1, -0.1], [0.1, -0.1], [0.1, -0.1]])  # predicted - measured, (4, A)
    weights = censor(error, bounds)
    # Lower bound: a prediction above costs nothing, below costs; upper bound the reverse.
    assert weights.tolist() == [[0.0, 1.0], [1.0, 0.0], [0.0, 0.0], [1.0, 1.0]]
