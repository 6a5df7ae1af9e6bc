"""The one-sided floor factor on a thing's base height (objslam_mapper.model.floor)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from objslam_mapper.model.floor import NO_FLOOR, floor_jacobian, floor_log_mass, floor_residual


@settings(max_examples=40, deadline=None)
@given(
    mean=st.floats(-0.5, 2.0),
    stddev=st.floats(0.05, 2.0),
    floor=st.floats(0.005, 1.0),
)
def test_the_renormalised_prior_integrates_to_one(mean, stddev, floor):
    def density(z):
        gauss = math.exp(-0.5 * ((z - mean) / stddev) ** 2) / (math.sqrt(2 * math.pi) * stddev)
        return gauss * math.exp(-0.5 * (min(z, 0.0) / floor) ** 2)

    width = 12 * stddev
    # Below the floor the floor factor alone is under exp(-800) past 40 floor widths: over a range
    # hundreds of times wider than its peak, quad missed part of it (0.5e-6 short at a floor of 8 mm).
    lowest = max(min(mean, 0.0) - width, -40.0 * floor)
    below = quad(
        density, lowest, 0.0, points=[mean] if lowest < mean < 0 else None, limit=200, epsabs=0.0, epsrel=1e-10
    )[0]
    above = quad(
        density, 0.0, max(mean, 0.0) + width, points=[mean] if mean > 0 else None, limit=200, epsabs=0.0, epsrel=1e-10
    )[0]
    assert floor_log_mass(mean, stddev, floor) == pytest.approx(math.log(below + above), abs=1e-7)


def test_a_floor_class_distractor_keeps_half_its_gaussian_and_a_sliver():
    # mu = 0: Phi(0) above the floor, (t / sigma) Phi(0) below it, t ~ the floor stddev.
    assert floor_log_mass(0.0, 1.0, 0.05) == pytest.approx(math.log(0.5 + 0.5 * 0.05 / math.hypot(1.0, 0.05)))
    assert floor_log_mass(0.3, 1.0, NO_FLOOR) == 0.0


def test_residual_and_jacobian_are_one_sided():
    z = np.array([-0.4, -0.01, 0.0, 0.2])
    inv = np.full(4, 1 / 0.05)
    np.testing.assert_allclose(floor_residual(z, inv), [-8.0, -0.2, 0.0, 0.0])
    step = 1e-7
    numeric = (floor_residual(z + step, inv) - floor_residual(z - step, inv)) / (2 * step)
    np.testing.assert_allclose(floor_jacobian(z[[0, 1, 3]], inv[:3]), numeric[[0, 1, 3]], rtol=1e-6)
    # No factor (stddev inf): nothing at all.
    assert floor_residual(np.array([-3.0]), np.zeros(1))[0] == 0.0
    assert floor_jacobian(np.array([-3.0]), np.zeros(1))[0] == 0.0
