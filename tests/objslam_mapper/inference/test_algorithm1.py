"""Paper Algorithm 1 on hand-made samples, and the clutter model's numbers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from objslam_mapper.config import ClutterConfig, SliceNoiseConfig
from objslam_mapper.graph.problem import gaussian_log_normalizer
from objslam_mapper.inference.algorithm1 import (
    MapBuildError,
    MapOptions,
    SampleObject,
    SampleSummary,
    build_from_samples,
    is_spurious,
    location_stddev_m,
)

A = frozenset({0, 1, 2, 3})
B = frozenset({4, 5})
A_PLUS_B = A | B
STAMPS = [0, 100, 200]


def obj(identity, x, stddev_m=0.05, size=(0.3, 0.6), label="red"):
    cov = np.diag([stddev_m**2, stddev_m**2, 1e-4])
    return SampleObject(identity, label, np.array([x, 1.0, 0.0]), np.array(size), cov, np.diag([1e-4, 4e-4]))


def trajectory(dx=0.0, theta=0.0):
    return np.array([[0.0 + dx, 0.0, theta], [1.0 + dx, 0.0, theta], [2.0 + dx, 0.0, theta]])


def test_location_stddev_is_the_largest_axis_of_the_horizontal_marginal():
    rotation = np.array([[np.cos(0.4), -np.sin(0.4)], [np.sin(0.4), np.cos(0.4)]])
    cov = np.zeros((3, 3))
    cov[:2, :2] = rotation @ np.diag([0.31**2, 0.1**2]) @ rotation.T
    cov[2, 2] = 4.0  # z_base does not count
    assert location_stddev_m(cov) == pytest.approx(0.31)
    assert is_spurious(obj(A, 0.0, stddev_m=0.31), 0.30)
    assert not is_spurious(obj(A, 0.0, stddev_m=0.29), 0.30)
    assert is_spurious(obj(A, 0.0, stddev_m=math.nan), 0.30)


def test_algorithm_1_bookkeeping():
    samples = [
        # A well determined in all four samples; B spurious in two, determined in one, merged in one.
        (SampleSummary(trajectory(0.0), (obj(A, 1.0), obj(B, 5.0, stddev_m=0.5))), 1),
        (SampleSummary(trajectory(0.2), (obj(A, 1.2), obj(B, 5.2, stddev_m=0.4))), 1),
        (SampleSummary(trajectory(0.4), (obj(A, 1.4, size=(0.4, 0.7)), obj(B, 5.4))), 1),
        (SampleSummary(trajectory(0.6), (obj(A_PLUS_B, 3.0),)), 1),
    ]
    built = build_from_samples(samples, STAMPS, MapOptions(report_min_fraction=0.2), diagnostics={"note": 1})
    assert len(built.objects) == 1 and len(built.rejected) == 2
    a = built.objects[0]
    assert a.existence_probability == pytest.approx(0.75)
    assert a.position_m[0] == pytest.approx(1.2)  # eq. 19: mean over the samples yielding A
    assert a.size_m == pytest.approx((0.1 / 3.0 + 0.3, 0.1 / 3.0 + 0.6))
    assert a.measurement_count == 4
    # Mixture covariance: mean marginal plus the spread of the three means (1.0, 1.2, 1.4).
    assert a.position_covariance[0][0] == pytest.approx(0.05**2 + np.var([1.0, 1.2, 1.4]))
    assert a.position_covariance[1][1] == pytest.approx(0.05**2)
    b, merged = sorted(built.rejected, key=lambda o: o.measurement_count)
    assert b.existence_probability == pytest.approx(0.25) and b.position_m[0] == pytest.approx(5.4)
    assert merged.existence_probability == pytest.approx(0.25) and merged.measurement_count == 6
    assert [o.id for o in (*built.objects, *built.rejected)] == [0, 1, 2]
    # eq. 18: the trajectory averages every sample.
    assert built.trajectory_array()[:, 0] == pytest.approx([0.3, 1.3, 2.3])
    assert [p.stamp_ns for p in built.trajectory] == STAMPS
    assert built.diagnostics["note"] == 1


def test_the_map_reports_error_covariances_and_the_existence_test_reads_the_marginals():
    error = np.diag([1e-6, 4e-6, 1e-6, 1e-6, 1e-6])  # the estimate's error: millimetres
    precise = dataclasses.replace(obj(A, 1.0), error_cov=error)
    # A posterior of 0.5 m is spurious whatever its error covariance says.
    vague = dataclasses.replace(obj(B, 5.0, stddev_m=0.5), error_cov=error)
    built = build_from_samples(
        [(SampleSummary(trajectory(), (precise, vague)), 1)], STAMPS, MapOptions(report_min_fraction=0.2)
    )
    assert len(built.objects) == 1 and len(built.rejected) == 1
    np.testing.assert_allclose(built.objects[0].position_covariance, error[:3, :3])
    np.testing.assert_allclose(built.objects[0].size_covariance, error[3:, 3:])


def test_multiplicities_count_as_repeated_samples():
    first = SampleSummary(trajectory(0.0), (obj(A, 1.0),))
    second = SampleSummary(trajectory(1.0), (obj(A, 2.0, stddev_m=0.5),))
    weighted = build_from_samples([(first, 3), (second, 1)], STAMPS)
    repeated = build_from_samples([(first, 1)] * 3 + [(second, 1)], STAMPS)
    assert weighted == repeated
    assert weighted.objects[0].existence_probability == pytest.approx(0.75)
    assert weighted.objects[0].position_m[0] == pytest.approx(1.0)  # the spurious sample does not count
    assert weighted.trajectory_array()[0, 0] == pytest.approx(0.25)


def test_identities_no_sample_yields_are_rejected_with_probability_zero():
    samples = [(SampleSummary(trajectory(), (obj(B, 4.0 + k, stddev_m=1.0),)), 1) for k in range(3)]
    built = build_from_samples(samples, STAMPS)
    assert not built.objects
    (b,) = built.rejected
    assert b.existence_probability == 0.0 and b.position_m[0] == pytest.approx(5.0)
    assert not build_from_samples(samples, STAMPS, MapOptions(report_min_fraction=1.01)).rejected


def test_headings_are_averaged_on_the_circle():
    samples = [
        (SampleSummary(trajectory(theta=np.pi - 0.1), ()), 1),
        (SampleSummary(trajectory(theta=-np.pi + 0.1), ()), 1),
    ]
    theta = build_from_samples(samples, STAMPS).trajectory_array()[:, 2]
    assert np.abs(np.abs(theta) - np.pi).max() < 1e-9


def test_bad_samples_are_refused():
    with pytest.raises(MapBuildError, match="no samples"):
        build_from_samples([], STAMPS)
    with pytest.raises(MapBuildError, match="trajectories"):
        build_from_samples([(SampleSummary(trajectory(), ()), 1)], [0, 1])


def test_clutter_density_is_uniform_over_the_measurement_space():
    clutter = ClutterConfig(
        false_alarm_rate=0.5, max_angular_width_rad=0.8, min_elevation_rad=-1.0, max_elevation_rad=1.0
    )
    volume = 2 * np.pi * 0.8 * 0.5 * 2.0**2  # bearing x width x {bottom <= top}
    assert clutter.measurement_volume == pytest.approx(volume)
    # The density integrates to the rate: Monte Carlo over a box holding the space.
    rng = np.random.default_rng(0)
    points = rng.uniform([-np.pi, 0.0, -1.0, -1.0], [np.pi, 0.8, 1.0, 1.0], (200_000, 4))
    inside = points[:, 2] <= points[:, 3]
    box = 2 * np.pi * 0.8 * 2.0 * 2.0
    integral = np.exp(clutter.log_likelihood_per_slice) * inside.mean() * box
    assert integral == pytest.approx(0.5, rel=0.01)
    assert clutter.log_likelihood(3) == pytest.approx(3 * (np.log(0.5) - np.log(volume)))
    with pytest.raises(ValueError):
        ClutterConfig(min_elevation_rad=0.5, max_elevation_rad=0.2)


def test_a_fitting_slice_favours_an_object_over_clutter_by_default():
    """The module docstring's numbers: with the default slice noise a slice's Gaussian
    normalizer is about +15 nats, against about -5.4 for one false alarm."""
    noise = SliceNoiseConfig()
    stddev = np.array(
        [
            noise.bearing_stddev_rad,
            noise.angular_width_stddev_rad,
            noise.elevation_bottom_stddev_rad,
            noise.elevation_top_stddev_rad,
        ]
    )
    assert float(gaussian_log_normalizer(stddev)) == pytest.approx(15.0, abs=0.5)
    assert ClutterConfig().log_likelihood_per_slice == pytest.approx(-5.4, abs=0.7)


# -- identities up to a minority of their measurements (identity_overlap) ------------------

CORE = frozenset(range(100))


def _variants(extra_per_sample):
    """Samples of one object: CORE plus a few slices that differ from sample to sample."""
    return [
        (SampleSummary(trajectory(), (obj(CORE | frozenset(extra), 1.0 + 0.01 * k),)), 1)
        for k, extra in enumerate(extra_per_sample)
    ]


def test_variants_of_one_object_that_differ_by_a_few_slices_are_one_identity():
    samples = _variants([range(100, 110), range(110, 115), (), range(120, 130)])
    exact = build_from_samples(samples, STAMPS, MapOptions(identity_overlap=1.0))
    assert not exact.objects  # four variants of 1/4 each: none above 1/2
    grouped = build_from_samples(samples, STAMPS, MapOptions(identity_overlap=0.8))
    assert len(grouped.objects) == 1
    one = grouped.objects[0]
    assert one.existence_probability == pytest.approx(1.0)
    assert one.position_m[0] == pytest.approx(1.015)  # mean over all four samples
    assert grouped.diagnostics["identities"] == 4 and grouped.diagnostics["identity_overlap"] == 0.8


def test_identities_differing_by_more_than_the_overlap_stay_apart():
    half = frozenset(range(50))
    samples = [
        (SampleSummary(trajectory(), (obj(CORE, 1.0),)), 1),
        (SampleSummary(trajectory(), (obj(half, 1.0), obj(CORE - half, 1.5))), 1),
    ]
    built = build_from_samples(samples, STAMPS, MapOptions(identity_overlap=0.8, report_min_fraction=0.0))
    assert sorted(o.measurement_count for o in built.objects + built.rejected) == [50, 50, 100]
    assert all(o.existence_probability == pytest.approx(0.5) for o in built.rejected)


def test_two_objects_of_one_sample_never_join_one_identity():
    """With overlap above 1/2 two disjoint sets cannot both hold that share of a third."""
    a, b = frozenset(range(60)), frozenset(range(60, 100))
    samples = [
        (SampleSummary(trajectory(), (obj(CORE, 1.0),)), 3),
        (SampleSummary(trajectory(), (obj(a, 1.0), obj(b, 1.4))), 1),
    ]
    built = build_from_samples(samples, STAMPS, MapOptions(identity_overlap=0.55, report_min_fraction=0.0))
    assert built.objects[0].existence_probability == pytest.approx(1.0)  # CORE and a (60 % of it) are one
    assert [o.measurement_count for o in built.rejected] == [40]


def test_identity_overlap_must_exceed_one_half():
    with pytest.raises(MapBuildError, match="identity_overlap"):
        build_from_samples(_variants([()]), STAMPS, MapOptions(identity_overlap=0.5))
