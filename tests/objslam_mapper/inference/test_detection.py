"""Missed detections (objslam_mapper.inference.detection): what is in view, and what a miss costs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import betabinom

from objslam_common.catalog import load_catalog
from objslam_common.mount import CameraMount
from objslam_mapper.config import DetectionConfig, GraphConfig
from objslam_mapper.graph.problem import build_problem
from objslam_mapper.inference.detection import (
    MissTerms,
    Sight,
    View,
    camera_view,
    detection_log_likelihood,
    detection_rate,
    hidden,
    own_rate_log_likelihood,
    share,
    sight,
    sightings,
    table_sight,
    visible,
)
from objslam_mapper.synthetic import SyntheticObject, ellipse_trajectory, simulate_run

CONFIG = DetectionConfig()
MOUNT = CameraMount()


class _Problem:
    """The fields the detection term reads of a GraphProblem (slices of unknown bearing unless given)."""

    def __init__(self, measurement_pose=(), measurements=None):
        self.mount = MOUNT
        self.measurement_pose = np.asarray(measurement_pose, dtype=np.int64)
        shape = (len(self.measurement_pose), 4)
        self.measurements = np.full(shape, np.nan) if measurements is None else np.asarray(measurements, dtype=float)


VIEW = View(0.4)


def _shown(poses, things, config=CONFIG, view=VIEW):
    seen = sight(_Problem(), np.asarray(poses, dtype=float), np.asarray(things, dtype=float), config, view)
    return visible(seen, seen, config)


ROBOT = [[0.0, 0.0, 0.0]]


def test_a_nearer_object_hides_one_behind_it():
    near = [2.0, 0.0, 0.0, 0.4, 0.4]
    far_behind = [4.0, 0.05, 0.0, 0.3, 0.6]
    far_aside = [4.0, 2.0, 0.0, 0.3, 0.6]
    shown = _shown(ROBOT, [near, far_behind, far_aside])
    assert shown.tolist() == [[True, False, True]]
    # Half hidden is still seen (cover must exceed one half).
    assert _shown(ROBOT, [near, [4.0, 0.45, 0.0, 0.3, 0.6]]).tolist() == [[True, True]]  # a third hidden


def test_things_that_share_floor_space_do_not_hide_each_other():
    # A duplicate 0.1 m in front of an object 0.4 m across covers it from the robot; one of the two
    # is not there, so neither excuses the other's misses. A third thing behind both is hidden.
    original = [2.0, 0.0, 0.0, 0.4, 0.6]
    duplicate = [1.9, 0.01, 0.0, 0.4, 0.6]
    behind = [4.0, 0.0, 0.0, 0.3, 0.4]
    seen = sight(_Problem(), np.array(ROBOT, dtype=float), np.array([original, duplicate, behind]), CONFIG, VIEW)
    assert hidden(seen, seen, CONFIG).tolist() == [[False, False, True]]
    # Just clear of each other (footprints 1 cm apart), the nearer one hides the other.
    clear = [1.59, 0.0, 0.0, 0.4, 0.6]
    seen = sight(_Problem(), np.array(ROBOT, dtype=float), np.array([original, clear]), CONFIG, VIEW)
    assert hidden(seen, seen, CONFIG).tolist() == [[True, False]]
    # A table hides a floor object just behind it, unless the object stands on the table's floor space.
    on_table = [2.0, 0.0, 0.7, 0.15, 0.25]
    for x_m, expected in ((2.4, True), (2.1, False)):
        floor_object = [x_m, 0.0, 0.0, 0.15, 0.9]
        things = np.array([on_table, floor_object])
        seen = sight(_Problem(), np.array(ROBOT, dtype=float), things, CONFIG, VIEW)
        tables = table_sight(_Problem(), np.array(ROBOT, dtype=float), things, np.array([True, False]), CONFIG)
        assert hidden(seen, Sight.join([seen, tables]), CONFIG)[0, 1] == expected


def test_fragments_of_one_distractor_share_their_hits_and_objects_do_not():
    # Ten images of four things: a poster seen as two tracklets (two distractors of one class at one
    # place), a distractor of that class elsewhere, and an object where the poster is.
    poses = np.column_stack([np.linspace(0.0, 1.0, 10), np.full(10, -2.0), np.zeros(10)])
    first, second = [2.0, 1.0, 0.5, 0.6, 0.6], [2.1, 1.05, 0.5, 0.5, 0.6]
    elsewhere, on_it = [-2.0, 1.0, 0.5, 0.6, 0.6], [2.0, 1.0, 0.0, 0.3, 0.6]
    things = np.array([first, second, elsewhere, on_it])
    # Slices: the first fragment in images 0-4, the second in 5-9, the other and the object in 0-4.
    problem = _Problem(measurement_pose=[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 0, 1, 2, 3, 4, 0, 1, 2, 3, 4])
    groups = [np.arange(0, 5), np.arange(5, 10), np.arange(10, 15), np.arange(15, 20)]
    kin = np.array([3, 3, 3, -1])  # the three distractors share a class; the object is no distractor
    seen = sightings(problem, poses, things, groups, CONFIG, EVERYWHERE_BUT_HIGH, kin=kin)
    assert seen.sight.in_view.all() and not seen.hidden.any()
    # Together the fragments are seen in every image; the distractor elsewhere and the object, which
    # stands where the fragments do, keep their own five misses each.
    assert seen.missed.sum(axis=0).tolist() == [0, 0, 5, 5]
    # Without sharing, each fragment misses the other's five images.
    alone = sightings(problem, poses, things, groups, CONFIG, EVERYWHERE_BUT_HIGH)
    assert alone.missed.sum(axis=0).tolist() == [5, 5, 5, 5]
    # Another class at the same place shares nothing.
    hit = np.eye(2, dtype=bool)
    should = np.ones((2, 2), dtype=bool)
    footprint = np.array([[0.0, 0.0], [0.0, 0.0], [0.3, 0.3]])
    assert [a.tolist() for a in share(hit, should, footprint, np.array([3, 4]))] == [hit.tolist(), should.tolist()]
    shared_hit, counted = share(hit, should, footprint, np.array([3, 3]))
    assert shared_hit.tolist() == [[True, True], [True, True]]
    assert counted.tolist() == [[True, False], [True, False]]


def test_a_fragment_seen_over_a_thing_is_a_hit_for_it_wherever_its_fit_lies():
    """A poster seen as two tracklets, one fitted 3 m behind the other along the line of sight
    (a short tracklet seen from afar is placed no better): their footprints are apart, yet in
    each image the slice of one lies over the other's predicted bearing interval, so neither
    misses the other's images. An image where the slice of its kind lies elsewhere stays a
    miss, and an object or another kind gives no hits."""
    poses = np.column_stack([np.linspace(0.0, 1.0, 10), np.full(10, -2.0), np.zeros(10)])
    near, far = [2.0, 1.0, 0.5, 0.6, 0.2], [3.5, 4.0, 0.5, 0.6, 1.2]  # the near one too short to hide the other
    things = np.array([near, far])
    seen = sight(_Problem(), poses, things, CONFIG, EVERYWHERE_BUT_HIGH)
    assert seen.in_view.all() and not hidden(seen, seen, CONFIG).any()
    assert np.hypot(2.0 - 3.5, 1.0 - 4.0) > seen.footprint[2].sum()  # no overlap: share() joins nothing
    pose = np.arange(10)
    owner = np.repeat([0, 1], 5)  # the near fit's slices in images 0-4, the far one's in 5-9
    measured = np.column_stack([seen.bearing[pose, owner], seen.width[pose, owner], np.zeros(10), np.zeros(10)])
    groups = [np.arange(0, 5), np.arange(5, 10)]

    def missed(kin, measurements=measured):
        problem = _Problem(measurement_pose=pose, measurements=measurements)
        return sightings(problem, poses, things, groups, CONFIG, EVERYWHERE_BUT_HIGH, kin=np.array(kin)).missed

    assert missed([3, 3]).sum(axis=0).tolist() == [0, 0]
    for apart in ([3, 4], [3, -1], [-1, -1]):
        assert missed(apart).sum(axis=0).tolist() == [5, 5]
    elsewhere = measured.copy()
    elsewhere[9, 0] += 1.0  # image 9's slice of the far fragment, 1 rad off the near one
    assert np.flatnonzero(missed([3, 3], elsewhere)[:, 0]).tolist() == [9]


def test_fragments_of_one_distractor_are_missed_once_per_image():
    """Four fragments of one poster (four passes of a loop, four distractors at one place) and
    an image between the passes where the poster should be seen and none has a slice: the
    thing is missed there once, not once per fragment. Fragments apart, or of another kind,
    count their own."""
    hit = np.zeros((3, 4), dtype=bool)
    hit[0, 0] = hit[1, 1] = True  # image 2: no slice of any fragment
    should = np.ones((3, 4), dtype=bool)
    together = np.array([[0.0, 0.1, 0.0, 0.05], [0.0, 0.0, 0.1, 0.05], [0.25, 0.25, 0.25, 0.25]])
    for kin, footprint, misses in (
        ([3, 3, 3, 3], together, 1),
        ([3, 4, 3, 4], together, 2 + 2),  # two kinds at one place: one thing of each, missed twice
        ([3, 3, 3, 3], together * [[1.0], [1.0], [0.01]], 2 + 2 + 3 + 3),  # too small to overlap
        ([-1, -1, -1, -1], together, 2 + 2 + 3 + 3),  # objects and distractors like their class
    ):
        shared_hit, counted = share(hit, should, footprint, np.array(kin))
        assert int(np.count_nonzero(counted & ~shared_hit)) == misses, kin


EVERYWHERE_BUT_HIGH = View(1.5)


@settings(max_examples=100, deadline=None)
@given(
    hits=st.integers(0, 400),
    misses=st.integers(0, 600),
    prior=st.floats(0.1, 50.0),
    probability=st.floats(0.05, 0.95),
)
def test_a_thing_detected_at_a_rate_of_its_own_scores_the_beta_binomial_of_its_hits(hits, misses, prior, probability):
    config = DetectionConfig(probability=probability, distractor_rate_prior=prior)
    a, b = prior * probability, prior * (1.0 - probability)
    # The probability of one sequence with these counts (scipy's pmf counts every order), less what
    # the hits cost in every association.
    expected = (
        betabinom.logpmf(hits, hits + misses, a, b)
        - (math.lgamma(hits + misses + 1) - math.lgamma(hits + 1) - math.lgamma(misses + 1))
        - hits * math.log(probability)
    )
    assert own_rate_log_likelihood(hits, misses, config) == pytest.approx(expected, rel=1e-9, abs=1e-7)
    # A rare detection is cheaper at a rate of its own than at P_d; a strong prior is P_d itself.
    if misses >= 10 * (hits + 1) and probability >= 0.5:
        assert own_rate_log_likelihood(hits, misses, config) > misses * math.log1p(-probability)
    sure = dataclasses.replace(config, distractor_rate_prior=1e10)
    assert own_rate_log_likelihood(hits, misses, sure) == pytest.approx(misses * math.log1p(-probability), abs=0.01)


def test_only_things_of_their_own_rate_leave_the_miss_count_and_only_when_the_prior_is_set():
    should = np.ones((10, 3), dtype=bool)
    hit = np.zeros((10, 3), dtype=bool)
    hit[:2, 0] = hit[:6, 1] = hit[:9, 2] = True  # 8, 4 and 1 misses
    own = np.array([True, False, True])
    assert MissTerms.of(should, hit, own, CONFIG) == MissTerms(13)
    config = DetectionConfig(distractor_rate_prior=2.0)
    terms = MissTerms.of(should, hit, own, config)
    assert terms.misses == 4
    assert terms.own_rate_log_likelihood == pytest.approx(
        own_rate_log_likelihood(2, 8, config) + own_rate_log_likelihood(9, 1, config)
    )
    assert terms.log_likelihood(config) == pytest.approx(4 * math.log1p(-0.7) + terms.own_rate_log_likelihood)
    assert (terms - terms).log_likelihood(config) == 0.0


def test_too_narrow_too_far_or_above_the_view_is_not_in_view():
    narrow = [8.0, 0.0, 0.0, 0.12, 0.25]  # 0.015 rad wide, below the detector's narrowest blob (0.0175)
    far = [11.0, 3.0, 0.0, 0.5, 0.3]  # wide enough but beyond 10 m
    high = [0.5, 0.0, 0.75, 0.15, 0.25]  # on a table, close: its lower edge above the view
    ok = [2.0, -1.0, 0.0, 0.3, 0.6]
    assert _shown(ROBOT, [narrow, far, high, ok]).tolist() == [[False, False, False, True]]


def test_each_image_in_view_without_a_slice_costs_log_one_minus_pd():
    poses = np.column_stack([np.linspace(0.0, 2.0, 10), np.zeros(10), np.zeros(10)])
    thing = np.array([[2.0, 2.0, 0.0, 0.4, 0.4]])
    # Slices of the object in 3 of the 10 images (measurement -> pose 0, 4, 9).
    problem = _Problem(measurement_pose=[0, 4, 9])
    value = detection_log_likelihood(problem, poses, thing, [np.array([0, 1, 2])], CONFIG, View(0.4))
    assert value == pytest.approx(7 * math.log1p(-CONFIG.probability))
    assert (
        detection_log_likelihood(
            problem, poses, thing, [np.array([0, 1, 2])], DetectionConfig(enabled=False), View(0.4)
        )
        == 0
    )


def test_the_detection_rate_rises_linearly_from_the_narrowest_blob_to_the_full_width():
    narrowest, full = CONFIG.narrowest_width_rad, CONFIG.min_angular_width_rad
    widths = np.array([0.0, 0.9 * narrowest, 0.5 * (narrowest + full), full, 2 * full])
    assert detection_rate(widths, CONFIG).tolist() == pytest.approx([0.01, 0.01, 0.5, 1.0, 1.0])
    step = DetectionConfig(narrowest_width_rad=full, narrow_hit_probability=1.0)
    assert detection_rate(widths, step).tolist() == [1.0] * 5


def test_a_thing_too_narrow_to_be_detected_pays_for_its_slices_and_a_narrow_one_for_its_misses():
    poses = np.column_stack([np.linspace(0.0, 2.0, 10), np.zeros(10), np.zeros(10)])
    problem = _Problem(measurement_pose=[0, 4, 9])
    groups = [np.array([0, 1, 2])]
    # 0.12 m wide at about 8 m: 0.015 rad from every pose, below the narrowest blob.
    far = np.array([[1.0, 8.0, 0.0, 0.12, 0.25]])
    value = detection_log_likelihood(problem, poses, far, groups, CONFIG, View(0.4))
    assert value == pytest.approx(3 * math.log(CONFIG.narrow_hit_probability))
    # The same thing at half the range is 0.030 rad wide: its slices and its 7 misses are
    # worth what its detection rate there makes them.
    near = np.array([[1.0, 4.0, 0.0, 0.12, 0.25]])
    seen = sight(problem, poses, near, CONFIG, View(0.4))
    assert seen.in_view.all() and (seen.width < CONFIG.min_angular_width_rad).all()
    rate = detection_rate(seen.width[:, 0], CONFIG)
    hit = np.isin(np.arange(10), [0, 4, 9])
    expected = np.log(rate[hit]).sum() + np.log1p(-CONFIG.probability * rate[~hit]).sum()
    assert detection_log_likelihood(problem, poses, near, groups, CONFIG, View(0.4)) == pytest.approx(expected)
    # With the step of the paper's model (no ramp, slices free) neither pays anything.
    step = DetectionConfig(narrowest_width_rad=CONFIG.min_angular_width_rad, narrow_hit_probability=1.0)
    assert detection_log_likelihood(problem, poses, far, groups, step, View(0.4)) == 0.0
    assert detection_log_likelihood(problem, poses, near, groups, step, View(0.4)) == 0.0


def test_the_view_top_is_read_off_the_slices_upper_edges():
    poses = ellipse_trajectory(40, (3.0, 1.8))
    scene = (
        SyntheticObject("red", (2.2, 0.3, 0.0), (0.31, 0.58)),
        SyntheticObject("cyan", (0.4, -0.9, 0.75), (0.15, 0.26)),
    )
    run = simulate_run(poses, [k * 250_000_000 for k in range(40)], scene, load_catalog(), np.random.default_rng(0))
    problem = build_problem(run.odometry, run.images, MOUNT, load_catalog(), GraphConfig())
    view = camera_view(problem, CONFIG)
    assert view.top_rad == pytest.approx(np.quantile(problem.measurements[:, 3], 0.995))
    assert view.top_rad > 0.0  # the cyan object's top is above the camera
    # Two objects leave most bearings without a slice: the view looks limited there, which
    # only stops counting misses where no slice ever was (camera_view's docstring).


def test_a_camera_that_looks_one_way_has_a_view_read_off_the_slices():
    # Slices only between -40 and +40 degrees (a forward camera): the view is that span.
    bearings = np.radians([-38.0, -10.0, 5.0, 37.0])
    widths = np.radians([4.0, 2.0, 2.0, 6.0])
    measurements = np.column_stack([bearings, widths, [-0.3, -0.2, -0.25, -0.1], [0.1, 0.2, 0.3, 0.15]])
    view = camera_view(_Measured(measurements), CONFIG)
    assert view.azimuth_lo_rad == pytest.approx(np.radians(-40.0))
    assert view.azimuth_span_rad == pytest.approx(np.radians(80.0))
    assert view.bottom_rad == pytest.approx(np.quantile(measurements[:, 2], 0.005))
    # A thing wholly inside the bearings is in view, one outside or across the edge is not.
    ahead, aside, across = [3.0, 0.0, 0.0, 0.3, 0.6], [0.0, 3.0, 0.0, 0.3, 0.6], [3.0, 2.5, 0.0, 0.3, 0.6]
    seen = sight(_Problem(), np.array(ROBOT, dtype=float), np.array([ahead, aside, across]), CONFIG, view)
    assert seen.in_view.tolist() == [[True, False, False]]


class _Measured:
    def __init__(self, measurements):
        self.measurements = np.asarray(measurements, dtype=float)
        self.measurement_count = len(self.measurements)


def test_a_thing_is_hidden_by_any_nearer_one_that_covers_it():
    near = [2.0, 0.0, 0.0, 0.4, 0.4]
    nearer = [1.0, 0.02, 0.0, 0.3, 0.6]
    far = [5.0, 0.0, 0.0, 0.4, 0.4]
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, np.pi / 2]])
    seen = sight(_Problem(), poses, np.array([near, nearer, far]), CONFIG, VIEW)
    # The far one is behind both, the near one behind the nearer (the heading does not matter).
    assert hidden(seen, seen, CONFIG).tolist() == [[True, False, True]] * 2
    assert hidden(seen, seen.columns([2]), CONFIG).tolist() == [[False, False, False]] * 2  # nothing behind
    assert visible(seen, seen, CONFIG).tolist() == [[False, True, False]] * 2


def test_nearer_things_hide_what_they_cover_together():
    far = [5.0, 0.0, 0.0, 0.4, 0.4]
    # Side by side, each covers less than half of the far one's bearing interval; together all of it.
    left, right = [2.5, 0.06, 0.0, 0.12, 0.4], [2.5, -0.06, 0.0, 0.12, 0.4]
    assert _shown(ROBOT, [far, left]).tolist() == [[True, True]]
    assert _shown(ROBOT, [far, right]).tolist() == [[True, True]]
    assert _shown(ROBOT, [far, left, right]).tolist() == [[False, True, True]]


def test_a_short_thing_does_not_hide_a_tall_one_that_stands_out_above_it():
    tall = [4.0, 0.0, 0.0, 0.2, 0.9]  # its silhouette reaches 0.1 rad above the camera
    short = [2.0, 0.0, 0.0, 0.5, 0.2]  # in front of all of its bearing interval, but only its lower third
    assert _shown(ROBOT, [tall, short]).tolist() == [[True, True]]
    assert _shown(ROBOT, [tall, [2.0, 0.0, 0.0, 0.5, 0.6]]).tolist() == [[False, True]]


def _sightings_with_tables(things, on_table, poses=ROBOT):
    return sightings(
        _Problem(),
        np.asarray(poses, dtype=float),
        np.asarray(things, dtype=float),
        [np.zeros(0, np.int64)] * len(things),
        CONFIG,
        VIEW,
        on_table=on_table,
    )


def test_a_table_hides_what_is_behind_it_but_not_the_object_on_it():
    on_table = [2.0, 0.0, 0.72, 0.15, 0.25]
    behind = [4.0, 0.1, 0.0, 0.3, 0.6]
    # The object on the table alone is above what is behind it and too narrow; its table hides it.
    assert not _sightings_with_tables([on_table, behind], [False, False]).hidden.any()
    assert _sightings_with_tables([on_table, behind], [True, False]).hidden.tolist() == [[False, True]]
    # Tables stand under their objects only: no table, or none configured, hides nothing.
    tables = table_sight(_Problem(), np.array(ROBOT, float), np.array([on_table, behind]), [True, False], CONFIG)
    assert tables.range_m[0, 1] == np.inf and not tables.in_view.any()
    assert tables.width[0, 0] == pytest.approx(2 * np.arcsin(CONFIG.table_diameter_m / 2 / 2.0))
    assert tables.top[0, 0] == pytest.approx(np.arctan2(0.72 - MOUNT.height_m, 2.0 - CONFIG.table_diameter_m / 2))
    no_tables = DetectionConfig(table_diameter_m=0.0)
    seen = sightings(
        _Problem(),
        np.array(ROBOT, float),
        np.array([on_table, behind]),
        [np.zeros(0, np.int64)] * 2,
        no_tables,
        VIEW,
        on_table=[True, False],
    )
    assert not seen.hidden.any()


def test_an_object_on_a_table_behind_another_table_shows_above_it_unless_far_behind():
    near = [2.0, 0.0, 0.72, 0.15, 0.25]
    # Beside the near object, behind its table: 0.6 m behind, the table covers the lowest 40 % of
    # its silhouette; 2 m behind, all of it (from 0.5 m high, the near table's edge is higher in
    # the image than the far object's top).
    just_behind, far_behind = [2.6, 0.2, 0.72, 0.15, 0.25], [4.0, 0.3, 0.72, 0.15, 0.25]
    assert _sightings_with_tables([near, just_behind], [True, True]).hidden.tolist() == [[False, False]]
    assert _sightings_with_tables([near, far_behind], [True, True]).hidden.tolist() == [[False, True]]


def _rectangle(bearing, width, bottom, top, range_m):
    """A thing seen from one pose at the origin, standing ``range_m`` ahead, too thin to overlap another."""
    footprint = np.array([[range_m], [0.0], [0.0]])
    values = (np.array([[v]], dtype=float) for v in (bearing, width, bottom, top, range_m))
    return Sight(*values, np.array([[True]]), footprint, np.array([[True]]))


@settings(max_examples=200, deadline=None)
@given(
    offset=st.floats(-0.3, 0.3),
    width=st.floats(0.02, 0.4),
    occ_width=st.floats(0.02, 0.6),
    bottom=st.floats(-0.5, 0.2),
    height=st.floats(0.02, 0.4),
    occ_bottom=st.floats(-0.6, 0.3),
    occ_height=st.floats(0.02, 0.8),
)
def test_the_cover_of_one_occluder_is_the_share_of_the_silhouette_it_overlaps(
    offset, width, occ_width, bottom, height, occ_bottom, occ_height
):
    row = _rectangle(0.1, width, bottom, bottom + height, 4.0)
    occluder = _rectangle(0.1 + offset, occ_width, occ_bottom, occ_bottom + occ_height, 2.0)
    in_bearing = max(0.0, min(width / 2, offset + occ_width / 2) - max(-width / 2, offset - occ_width / 2)) / width
    top = min(bottom + height, occ_bottom + occ_height)
    in_elevation = max(0.0, top - max(bottom, occ_bottom)) / height
    share = in_bearing * in_elevation
    # Measured on a grid of 16 x 16 points: exact but near the threshold.
    if abs(share - CONFIG.occlusion_cover) > 2.5 / 16:
        assert hidden(row, occluder, CONFIG)[0, 0] == (share > CONFIG.occlusion_cover)
    # Only nearer things hide.
    assert not hidden(row, _rectangle(0.1 + offset, occ_width, occ_bottom, occ_bottom + occ_height, 5.0), CONFIG)[0, 0]
