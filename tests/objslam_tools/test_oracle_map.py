"""objslam_tools.oracle_map and ``objslam map --association``: the ground-truth association's map."""

from __future__ import annotations

import numpy as np
import pytest

from objslam_common.catalog import load_catalog
from objslam_common.mount import CameraMount
from objslam_common.records import ImageSlices, OdometrySample, SliceMeasurement
from objslam_mapper.config import MapperConfig
from objslam_mapper.graph.problem import build_problem
from objslam_mapper.model.slice_model import predict_slices
from objslam_tools.cli import main
from objslam_tools.evaluate import Reference, score_map
from objslam_tools.ground_truth import GroundTruth
from objslam_tools.oracle_map import build_oracle_map, oracle_groups, oracle_problem
from objslam_tools.trajectory import PoseTrack, transform_poses
from tests.objslam_tools import synthetic_scene as scene

TRUTH = GroundTruth(objects=scene.OBJECTS, distractors=scene.DISTRACTORS)
STAMPS, POSES = scene.ground_truth_poses()
GT_TRACK = PoseTrack(STAMPS, POSES)
ODOM_POSES = transform_poses(scene._inverse(scene.GT_T_ODOM), scene.drifting_odometry(POSES))
NOISE_RAD = np.array([0.003, 0.006, 0.005, 0.005])


def _inputs(seed: int = 3, merged_images: range = range(0)):
    """Slices of every real object from the true poses (small noise), plus a poster's slice in each image.

    In ``merged_images`` the blue object's blob is merged with a blue sign beside it: the slice
    is widened by 0.2 rad on one side (its bearing moves by half of that).
    """
    rng = np.random.default_rng(seed)
    objs = TRUTH.objects
    images = []
    for stamp, pose in zip(STAMPS, POSES, strict=True):
        pred = predict_slices(
            pose, [o.position_m for o in objs], [o.size_m for o in objs], CameraMount(), jacobians=False
        )
        slices = []
        for values, valid, obj in zip(pred.values, pred.valid, objs, strict=True):
            if valid:
                b, w, lo, hi = values + rng.normal(0.0, NOISE_RAD)
                if obj.label == "blue" and len(images) in merged_images:
                    b, w = b + 0.1, w + 0.2
                slices.append(SliceMeasurement(obj.label, 1.0, float(b), float(w), float(lo), float(hi)))
        # A yellow poster (no yellow object exists), fixed in the image: chains into tracklets.
        slices.append(SliceMeasurement("yellow", 1.0, 1.0, 0.15, 0.2, 0.35))
        images.append(ImageSlices(int(stamp), tuple(slices)))
    odometry = tuple(OdometrySample(int(s), *map(float, p)) for s, p in zip(STAMPS, ODOM_POSES, strict=True))
    return odometry, images


def test_oracle_map_matches_ground_truth():
    odometry, images = _inputs()
    built = build_oracle_map(odometry, images, load_catalog(), MapperConfig(), TRUTH, GT_TRACK)
    assert built.diagnostics["association"] == "oracle"
    # The poster's chained slices are explained by no real object: left out, not a yellow object.
    assert 0 < built.diagnostics["clutter_measurements"] <= len(images)
    assert not built.rejected and all(o.existence_probability == 1.0 for o in built.objects)
    assert sorted(o.label for o in built.objects) == sorted(o.label for o in TRUTH.objects)

    odom_track = PoseTrack(STAMPS, ODOM_POSES)
    score = score_map(built, Reference(TRUTH, GT_TRACK, odom_track), gate_m=0.5)
    m = score.metrics()
    assert m["precision"] == 1.0 and m["recall"] == 1.0
    assert m["xy_error_max_m"] < 0.05
    assert m["diameter_error_mean_m"] < 0.03 and m["height_error_mean_m"] < 0.03
    assert m["trajectory_ate_m"] < 0.5 * m["odometry_ate_m"]


def test_oracle_on_a_bag_without_ground_truth_is_one_line_exit_2(tmp_path, capsys):
    bag = scene.write_scene_bag(tmp_path / "bag")
    (bag / "ground_truth.yaml").unlink()
    code = main(["map", str(bag), "--out", str(tmp_path / "map.yaml"), "--association", "oracle"])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "--association oracle needs the bag's ground truth" in err
    assert not (tmp_path / "map.yaml").exists()


@pytest.mark.parametrize("choice", ["bogus"])
def test_unknown_association_is_refused(tmp_path, capsys, choice):
    with pytest.raises(SystemExit) as exc:
        main(["map", str(tmp_path), "--out", str(tmp_path / "m.yaml"), "--association", choice])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err


def test_merged_blobs_are_left_out_of_the_known_association():
    merged = range(20, 35)
    odometry, images = _inputs(merged_images=merged)
    config = MapperConfig()
    problem = build_problem(odometry, images, config.graph.camera_mount.to_mount(), load_catalog(), config.graph)
    groups, inconsistent = oracle_groups(problem, images, TRUTH, GT_TRACK)
    blue = next(o.id for o in TRUTH.objects if o.label == "blue")
    merged_slices = {
        m
        for m in range(problem.measurement_count)
        if problem.measurement_image[m] in merged and problem.label_of(m) == "blue"
    }
    # The oracle's geometric gates take the merged slices (the sectors overlap); the model's gate does not.
    assert len(merged_slices) == len(merged) and inconsistent == len(merged)
    assert not merged_slices & set(groups[blue])
    assert sum(len(g) for g in groups.values()) == problem.measurement_count - len(images) - len(merged)

    built = build_oracle_map(odometry, images, load_catalog(), config, TRUTH, GT_TRACK)
    assert built.diagnostics["inconsistent_measurements"] > 0
    score = score_map(built, Reference(TRUTH, GT_TRACK, PoseTrack(STAMPS, ODOM_POSES)), gate_m=0.5)
    assert score.metrics()["xy_error_max_m"] < 0.05


def test_oracle_problem_of_a_bag_groups_the_slices_by_their_real_object(repo_root):
    problem, reference, truth_ids, groups = oracle_problem(
        str(repo_root / "bags" / "small"), MapperConfig(), load_catalog()
    )
    truth = {o.id: o for o in reference.ground_truth.objects}
    assert sorted(truth_ids) == truth_ids and set(truth_ids) <= set(truth)
    assert len(truth_ids) == len(truth)  # bags/small: every object is seen
    for truth_id, members in zip(truth_ids, groups, strict=True):
        assert len(members) > 10
        assert {problem.label_of(m) for m in members} == {truth[truth_id].label}
    assert len({m for g in groups for m in g}) == sum(len(g) for g in groups)  # no slice in two groups
