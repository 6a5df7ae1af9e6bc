"""Scenario generation: the robot never drives through anything, scenes are as the scenarios promise."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from objslam_common.catalog import load_catalog
from objslam_tools.errors import UserError
from objslam_tools.ground_truth import (
    GroundTruth,
    ground_truth_from_dict,
    ground_truth_to_dict,
    load_ground_truth,
    write_ground_truth,
)
from objslam_tools.sim import SCENARIO_NAMES, build_scenario
from objslam_tools.sim.motion import OdometryNoise, align_start
from objslam_tools.sim.scene import SIGN_POST_RADIUS_M

CATALOG = load_catalog()
SEEDS = (0, 1, 2, 7)


def surface_distances(scenario, xy: np.ndarray) -> dict[str, float]:
    """Smallest distance from robot positions to each solid thing's surface, computed from the ground truth."""
    gt = scenario.ground_truth()
    out = {}
    for o in gt.objects:
        out[f"object {o.id}"] = float(np.min(np.hypot(*(xy - o.position_m[:2]).T)) - o.radius_m)
    for t in gt.tables:
        out[f"table {t.id}"] = float(np.min(np.hypot(*(xy - t.position_m[:2]).T)) - t.radius_m)
    for d in gt.distractors:
        if d.kind == "sign":  # the board's edge points and its post
            for k, corner in enumerate(d.corners_m()[:, :2]):
                out[f"sign {d.id} corner {k}"] = float(np.min(np.hypot(*(xy - corner).T)))
            post = np.asarray(d.center_m[:2])
            out[f"sign {d.id} post"] = float(np.min(np.hypot(*(xy - post).T)) - SIGN_POST_RADIUS_M)
    return out


@pytest.mark.parametrize("name", SCENARIO_NAMES)
@pytest.mark.parametrize("seed", SEEDS)
def test_path_keeps_clear_of_every_object_and_table(name: str, seed: int) -> None:
    scenario = build_scenario(name, seed)
    for xy in (scenario.path.xy_m, scenario.true_poses[:, :2], scenario.image_poses[:, :2]):
        distances = surface_distances(scenario, xy)
        closest = min(distances, key=distances.get)
        assert distances[closest] >= 0.4, f"{name} seed {seed}: passes {distances[closest]:.2f} m from {closest}"
    room = scenario.scene.room
    xy = scenario.true_poses[:, :2]
    assert np.all((xy[:, 0] > room.x_min_m + 0.5) & (xy[:, 0] < room.x_max_m - 0.5))
    assert np.all((xy[:, 1] > room.y_min_m + 0.5) & (xy[:, 1] < room.y_max_m - 0.5))


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_scenarios_are_deterministic_per_seed(name: str) -> None:
    a, b, c = build_scenario(name, 3), build_scenario(name, 3), build_scenario(name, 4)
    assert a.scene == b.scene
    assert np.array_equal(a.true_poses, b.true_poses) and np.array_equal(a.odom_poses, b.odom_poses)
    assert a.scene.objects != c.scene.objects


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_scenario_properties(name: str) -> None:
    scenario = build_scenario(name, 1)
    objects = scenario.scene.objects
    # Instances vary by up to 10 % around the nominal size.
    for o in objects:
        cls = CATALOG[o.label]
        assert abs(o.size_m[0] / cls.diameter_m - 1) <= 0.1 + 1e-9
        assert abs(o.size_m[1] / cls.height_m - 1) <= 0.1 + 1e-9
    # Elevated objects stand on grey tables as tall as their base.
    raised = [o for o in objects if o.position_m[2] > 0]
    assert len(scenario.scene.tables) == len(raised)
    for o in raised:
        (table,) = [t for t in scenario.scene.tables if t.object_id == o.id]
        assert table.size_m[1] == pytest.approx(o.position_m[2])
        assert table.position_m[:2] == pytest.approx(o.position_m[:2])
        assert 0.4 <= table.size_m[0] <= 0.5 and 0.7 <= o.position_m[2] <= 0.8
    # A realistic speed, a path that ends where it should, a ground-truth start that is not the identity.
    assert 0.3 <= scenario.mean_speed_mps <= 0.5
    start = scenario.true_poses[0]
    assert np.hypot(*start[:2]) > 0.5
    assert np.array_equal(scenario.odom_poses[0], np.zeros(3))
    # Every object is seen from 1-4 m at some point of the drive.
    for o in objects:
        d = np.hypot(*(scenario.image_poses[:, :2] - o.position_m[:2]).T)
        assert np.any((d > 1.0) & (d < 4.0)), f"object {o.id} is never 1-4 m away"
    # Stamps: images at 5 Hz, odometry at 50 Hz covering every image.
    assert np.all(np.diff(scenario.image_stamps_ns) == 200_000_000)
    assert np.all(np.diff(scenario.odom_stamps_ns) == 20_000_000)
    assert scenario.odom_stamps_ns[0] <= scenario.image_stamps_ns[0]
    assert scenario.odom_stamps_ns[-1] >= scenario.image_stamps_ns[-1]


def test_scenario_contents() -> None:
    small = build_scenario("small", 1)
    assert 4 <= len(small.scene.objects) <= 5 and 80 <= small.frames <= 120
    office = build_scenario("office", 2)
    assert {o.label for o in office.scene.objects} == set(CATALOG.labels)
    assert 10 <= len(office.scene.objects) <= 14 and office.frames == 400
    assert [d.kind for d in office.scene.distractors] == ["poster"] * 3
    twins = build_scenario("twins", 0)
    pairs = 0
    for i, a in enumerate(twins.scene.objects):
        for b in twins.scene.objects[i + 1 :]:
            if a.label == b.label and 0.7 <= np.hypot(*np.subtract(a.position_m[:2], b.position_m[:2])) <= 1.0:
                pairs += 1
    assert pairs >= 4
    clutter = build_scenario("clutter", 0)
    kinds = [d.kind for d in clutter.scene.distractors]
    assert len(kinds) >= 15 and {"poster", "sign", "floor_patch", "low_patch"} <= set(kinds)
    assert all(d.center_m[2] < 0.4 for d in clutter.scene.distractors if d.kind in ("floor_patch", "low_patch"))
    loop = build_scenario("loop", 0)
    assert loop.frames == 900
    turned = np.sum(np.diff(np.unwrap(loop.true_poses[:, 2])))
    assert abs(turned) > 4 * np.pi - 0.5, "two laps"
    # Revisits: late in the run the robot passes within 0.5 m of where it was early on.
    first, last = loop.image_poses[:200, :2], loop.image_poses[500:, :2]
    gaps = np.min(np.hypot(*(last[:, None, :] - first[None, :, :]).transpose(2, 0, 1)), axis=1)
    assert np.mean(gaps < 0.5) > 0.3


def test_frames_resample_the_same_path() -> None:
    base = build_scenario("office", 2)
    double = build_scenario("office", 2, frames=800)
    few = build_scenario("office", 2, frames=10)
    assert double.frames == 800 and few.frames == 10
    assert double.scene == base.scene
    assert np.array_equal(double.path.xy_m, base.path.xy_m)
    for s in (double, few):  # the first image comes 10 ms after the start, the last one at the stop
        np.testing.assert_allclose(s.image_poses[0], base.image_poses[0], atol=1e-3)
        np.testing.assert_allclose(s.image_poses[-1], base.image_poses[-1], atol=1e-3)
    # Frame 2k of the doubled run is (nearly) where frame k of the base run is.
    np.testing.assert_allclose(double.image_poses[200, :2], base.image_poses[100, :2], atol=0.1)


def test_odometry_follows_the_noise_model() -> None:
    scenario = build_scenario("loop", 5)
    truth = scenario.true_poses
    # Without the random part the drift is the systematic one: repeat it here from the documented figures.
    noise = OdometryNoise()
    assert scenario.odometry_noise == noise
    step = np.diff(truth[:, :2], axis=0)
    distance = np.hypot(*step.T)
    turn = np.angle(np.exp(1j * np.diff(truth[:, 2])))
    d_meas = distance * (1 + noise.distance_scale)
    t_meas = turn * (1 + noise.turn_scale) + noise.turn_bias_rad_per_m * distance
    theta = np.r_[0.0, np.cumsum(t_meas)]
    mid = theta[:-1] + t_meas / 2
    xy = np.vstack([[0, 0], np.cumsum(np.column_stack([d_meas * np.cos(mid), d_meas * np.sin(mid)]), axis=0)])
    systematic = align_start(np.column_stack([xy, theta]), truth[0])
    drift = np.hypot(*(systematic[:, :2] - truth[:, :2]).T)
    assert drift.max() > 0.3, "the systematic error must make a real drift"
    # The random part moves the end by a plausible amount around the systematic drift.
    noisy = align_start(scenario.odom_poses, truth[0])
    assert 0.01 < np.hypot(*(noisy[-1, :2] - systematic[-1, :2])) < 2.0


def test_unknown_scenario_and_bad_arguments() -> None:
    with pytest.raises(UserError, match="unknown scenario 'nope'"):
        build_scenario("nope")
    with pytest.raises(UserError, match="frames"):
        build_scenario("small", frames=1)
    with pytest.raises(UserError, match="seed"):
        build_scenario("small", seed=-1)


def test_ground_truth_round_trip(tmp_path) -> None:
    gt = build_scenario("clutter", 0).ground_truth()
    write_ground_truth(tmp_path, gt)
    loaded = load_ground_truth(tmp_path)
    assert loaded.frame_id == "world" and loaded.mount == gt.mount and loaded.room == gt.room
    assert len(loaded.objects) == len(gt.objects) and len(loaded.distractors) == len(gt.distractors)
    for a, b in zip(loaded.objects, gt.objects, strict=True):
        assert a.label == b.label and a.id == b.id
        np.testing.assert_allclose(a.position_m, b.position_m, atol=1e-6)
        np.testing.assert_allclose(a.size_m, b.size_m, atol=1e-6)
    for a, b in zip(loaded.distractors, gt.distractors, strict=True):
        assert (a.kind, a.label, a.color_rgb) == (b.kind, b.label, b.color_rgb)
        np.testing.assert_allclose(a.corners_m(), b.corners_m(), atol=1e-5)
    assert loaded.simulation["scenario"] == "clutter"
    assert ground_truth_from_dict(ground_truth_to_dict(loaded)) == loaded


def test_distractor_geometry() -> None:
    gt = ground_truth_from_dict(
        {
            "objects": [],
            "distractors": [
                {
                    "kind": "poster",
                    "label": "red",
                    "color_rgb": [200, 30, 30],
                    "center": [0, 0, 1],
                    "size": [2, 1],
                    "yaw": 0,
                },
                {
                    "kind": "floor_patch",
                    "label": "red",
                    "color_rgb": [200, 30, 30],
                    "center": [0, 0, 0],
                    "size": [2, 1],
                },
            ],
        }
    )
    poster, patch = gt.distractors
    # A poster facing +x spans y (width) and z (height).
    np.testing.assert_allclose(np.ptp(poster.corners_m(), axis=0), [0, 2, 1])
    # A floor patch with yaw 0 spans x (width) and y.
    np.testing.assert_allclose(np.ptp(patch.corners_m(), axis=0), [2, 1, 0])
    assert poster.is_vertical and not patch.is_vertical


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "not found"),
        ("objects: [", "cannot read"),
        ("[1, 2]", "malformed"),
        ("objects:\n  - {label: red, position: [1, 2], size: [0.3, 0.6]}\n", "position"),
        ("objects:\n  - {label: red, size: [0.3, 0.6]}\n", "missing key"),
        (
            "objects: []\ndistractors:\n"
            "  - {kind: mural, label: red, color_rgb: [1,2,3], center: [0,0,0], size: [1,1]}\n",
            "kind",
        ),
        ("objects:\n  - {label: red, position: [1, 2, 0], size: [0.3, -0.6]}\n", "positive"),
    ],
)
def test_load_ground_truth_errors_are_one_clear_line(tmp_path, content, message) -> None:
    if content is not None:
        (tmp_path / "ground_truth.yaml").write_text(content)
    with pytest.raises(UserError, match=message) as info:
        load_ground_truth(tmp_path)
    assert "\n" not in str(info.value)


def test_ground_truth_defaults() -> None:
    gt = ground_truth_from_dict({"objects": [{"label": "red", "position": [1, 2, 0], "size": [0.3, 0.6]}]})
    assert isinstance(gt, GroundTruth) and gt.objects[0].id == 0 and gt.tables == () and gt.room is None
    assert dataclasses.asdict(gt.mount) == {
        "height_m": 0.5, "offset_x_m": 0.0, "offset_y_m": 0.0, "yaw_rad": 0.0, "roll_rad": 0.0, "pitch_rad": 0.0,
    }  # fmt: skip
