"""objslam_tools.evaluate and ``objslam eval`` on a small synthetic scene with known answers."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from objslam_mapper.map_file import MappedObject, write_map
from objslam_tools.cli import main
from objslam_tools.errors import UserError
from objslam_tools.evaluate import align_map, load_reference, nees_summary, score_map
from objslam_tools.trajectory import PoseTrack, fit_se2, transform_poses
from tests.objslam_tools import synthetic_scene as scene


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    return load_reference(scene.write_scene_bag(tmp_path_factory.mktemp("eval") / "bag"))


@given(
    x=st.floats(-50, 50),
    y=st.floats(-50, 50),
    theta=st.floats(-3.1, 3.1),
    seed=st.integers(0, 1000),
)
@settings(max_examples=50, deadline=None)
def test_fit_se2_recovers_a_known_transform(x, y, theta, seed):
    pts = np.random.default_rng(seed).uniform(-5, 5, size=(8, 2))
    target = transform_poses([x, y, theta], np.column_stack([pts, np.zeros(8)]))[:, :2]
    got = fit_se2(pts, target)
    np.testing.assert_allclose(got[:2], [x, y], atol=1e-8)
    assert abs(np.angle(np.exp(1j * (got[2] - theta)))) < 1e-9


def test_fit_se2_is_least_squares():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-5, 5, size=(30, 2))
    target = transform_poses([1.0, 2.0, 0.4], np.column_stack([pts, np.zeros(30)]))[:, :2] + rng.normal(0, 0.1, (30, 2))
    best = fit_se2(pts, target)

    def cost(p):
        moved = transform_poses(p, np.column_stack([pts, np.zeros(30)]))[:, :2]
        return float(np.sum((moved - target) ** 2))

    for delta in np.eye(3) * 1e-3:
        assert cost(best) <= cost(best + delta) and cost(best) <= cost(best - delta)


def test_alignment_recovers_the_odom_frame(reference):
    alignment = align_map(scene.perfect_map(), reference.ground_truth_track)
    np.testing.assert_allclose(alignment.gt_T_map, scene.GT_T_ODOM, atol=1e-9)
    assert alignment.ate_m < 1e-9
    assert alignment.pose_count == 30


def test_perfect_map_scores_perfectly(reference):
    score = score_map(scene.perfect_map(), reference)
    m = score.metrics()
    assert m["precision"] == 1.0 and m["recall"] == 1.0
    assert m["true_positives"] == 5 and m["false_positives"] == 0 and m["misses"] == 0
    assert m["xy_error_max_m"] < 1e-6 and m["z_error_mean_m"] < 1e-9
    assert m["diameter_error_mean_m"] < 1e-9 and m["height_error_mean_m"] < 1e-9
    assert m["trajectory_ate_m"] < 1e-6
    # The raw odometry drifts by up to 0.25 rad about the start: clearly worse than the map.
    assert m["odometry_ate_m"] > 0.1
    assert score.nees_xy.mean < 1e-6 and score.nees_xy.verdict == "pessimistic"


def test_moving_an_object_by_30cm_is_an_error(reference):
    score = score_map(scene.moved(scene.perfect_map(), 12, 0.3), reference)
    m = score.metrics()
    assert m["precision"] == 1.0 and m["recall"] == 1.0
    assert m["xy_error_max_m"] == pytest.approx(0.3, abs=1e-6)
    (match,) = [x for x in score.matches if x.map_id == 12]
    # Covariance in the odom frame is diag(0.01, 0.02): NEES of a 0.3 m error along gt x, rotated.
    c, s = np.cos(scene.GT_T_ODOM[2]), np.sin(scene.GT_T_ODOM[2])
    rot = np.array([[c, -s], [s, c]])
    cov_gt = rot @ np.diag([0.01, 0.02]) @ rot.T
    e = np.array([0.3, 0.0])
    assert match.nees_xy == pytest.approx(float(e @ np.linalg.solve(cov_gt, e)), rel=1e-9)


def test_moving_an_object_by_1m_is_a_false_positive_and_a_miss(reference):
    score = score_map(scene.moved(scene.perfect_map(), 12, 1.0), reference)
    m = score.metrics()
    assert m["true_positives"] == 4 and m["false_positives"] == 1 and m["misses"] == 1
    assert m["precision"] == pytest.approx(0.8) and m["recall"] == pytest.approx(0.8)
    (fp,) = score.false_positives
    assert fp.map_id == 12 and fp.existence_probability == 0.9
    assert fp.nearest_truth_m == pytest.approx(1.0, abs=1e-6)
    assert score.misses[0].truth_id == 2


def test_hungarian_prefers_the_global_assignment(reference):
    # Reds at x = 2.0 and 2.4; map reds at 2.1 (nearest to the first) and 1.55 (only the first within the gate).
    # Greedy nearest-first would match 2.1 -> 2.0 and leave 1.55 unmatched; the assignment matches both.
    truth = reference.ground_truth
    reds = (
        replace(truth.objects[0], position_m=(2.0, 1.0, 0.0)),
        replace(truth.objects[1], position_m=(2.4, 1.0, 0.0)),
    )
    ref = replace(reference, ground_truth=replace(truth, objects=reds))
    base = scene.perfect_map()
    objs = (
        MappedObject(20, "red", scene.to_odom((2.1, 1.0, 0.0)), (0.3, 0.6), 0.9),
        MappedObject(21, "red", scene.to_odom((1.55, 1.0, 0.0)), (0.3, 0.6), 0.9),
    )
    score = score_map(replace(base, objects=objs), ref, gate_m=0.5)
    assert {(m.map_id, m.truth_id) for m in score.matches} == {(20, 1), (21, 0)}
    assert not score.false_positives and not score.misses


def test_distractor_object_and_rejected_miss(reference):
    base = scene.perfect_map()
    poster = MappedObject(30, "yellow", scene.to_odom((0.2, 2.1, 0.0)), (0.5, 0.3), 0.7)
    green = next(o for o in base.objects if o.label == "green")
    objects = (*[o for o in base.objects if o.label != "green"], poster)
    score = score_map(replace(base, objects=objects, rejected=(replace(green, existence_probability=0.3),)), reference)
    m = score.metrics()
    assert m["distractors_as_objects"] == 1 and m["misses_rejected"] == 1
    assert score.false_positives[0].distractor_kind == "poster"


def test_map_without_trajectory_is_a_user_error(reference):
    with pytest.raises(UserError, match="no trajectory"):
        score_map(replace(scene.perfect_map(), trajectory=()), reference)


def test_map_from_another_time_is_a_user_error(reference):
    base = scene.perfect_map()
    shifted = tuple(replace(p, stamp_ns=p.stamp_ns + 10**12) for p in base.trajectory)
    with pytest.raises(UserError, match="another bag"):
        score_map(replace(base, trajectory=shifted), reference)


def test_nees_band_matches_chi_square():
    rng = np.random.default_rng(0)
    values = np.sum(rng.normal(size=(2000, 2)) ** 2, axis=1)
    s = nees_summary(values, 2)
    assert s.band[0] < 2.0 < s.band[1] and s.verdict == "consistent"
    assert nees_summary(values * 3, 2).verdict == "overconfident"
    assert nees_summary([], 2).verdict == "n/a"


def test_pose_track_interpolation():
    track = PoseTrack(np.array([0, 10]), np.array([[0.0, 0.0, 3.0], [1.0, 2.0, -3.0]]))
    mid = track.interpolate([5])[0]
    np.testing.assert_allclose(mid[:2], [0.5, 1.0])
    assert abs(abs(mid[2]) - np.pi) < 1e-9
    np.testing.assert_allclose(track.interpolate([-5, 20]), track.poses)


def test_cli_table_and_json(reference, tmp_path, capsys):
    bag = tmp_path / "bag"
    scene.write_scene_bag(bag, storage="sqlite3")
    good = write_map(tmp_path / "good.yaml", scene.perfect_map())
    bad = write_map(tmp_path / "bad.yaml", scene.moved(scene.perfect_map(), 12, 1.0))
    assert main(["eval", str(good), str(bad), "--bag", str(bag), "--label", "perfect", "moved"]) == 0
    out = capsys.readouterr().out
    header = next(line for line in out.splitlines() if "perfect" in line)
    assert "moved" in header
    precision = next(line for line in out.splitlines() if line.startswith("precision"))
    assert precision.split()[1:] == ["1.000", "0.800"]
    assert "false positives" in out and "P=0.90" in out

    assert main(["eval", str(bad), "--bag", str(bag), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["maps"][0]["metrics"]["false_positives"] == 1
    assert data["maps"][0]["false_positives"][0]["existence_probability"] == 0.9


def test_cli_user_errors(tmp_path, capsys):
    bag = scene.write_scene_bag(tmp_path / "bag")
    good = write_map(tmp_path / "good.yaml", scene.perfect_map())
    assert main(["eval", str(tmp_path / "none.yaml"), "--bag", str(bag)]) == 2
    assert "map file not found" in capsys.readouterr().err
    assert main(["eval", str(good), "--bag", str(tmp_path / "nobag")]) == 2
    assert "bag not found" in capsys.readouterr().err
    assert main(["eval", str(good), "--bag", str(bag), "--label", "a", "b"]) == 2
    assert "--label gives 2 names for 1 maps" in capsys.readouterr().err
    (bag / "ground_truth.yaml").unlink()
    assert main(["eval", str(good), "--bag", str(bag)]) == 2
    assert "no ground truth" in capsys.readouterr().err


def test_objects_of_one_class_closer_than_their_diameters_count_as_duplicates():
    from objslam_tools.evaluate import overlapping_pairs

    def obj(i, label, x_m, diameter_m):
        return MappedObject(i, label, (x_m, 1.0, 0.0), (diameter_m, 0.5), 1.0)

    # 0.15 m apart: overlapping at 0.2 m across, clear at 0.1 m; other classes never count.
    assert overlapping_pairs([obj(0, "blue", 0.0, 0.2), obj(1, "blue", 0.15, 0.2)]) == 1
    assert overlapping_pairs([obj(0, "blue", 0.0, 0.1), obj(1, "blue", 0.15, 0.1)]) == 0
    assert overlapping_pairs([obj(0, "blue", 0.0, 0.2), obj(1, "red", 0.15, 0.2)]) == 0
    triple = [obj(k, "yellow", 0.1 * k, 0.5) for k in range(3)]
    assert overlapping_pairs(triple) == 3
