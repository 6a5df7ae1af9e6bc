"""``objslam eval-detector``: scoring on a small rendered bag, matching rules, user errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from objslam_common.mount import CameraMount
from objslam_common.records import SliceMeasurement
from objslam_detector import Detector
from objslam_tools.cli import main
from objslam_tools.detector_eval import (
    DetectorEvaluation,
    EvalOptions,
    distractor_sector,
    evaluate_bag,
    format_report,
    match,
    score_frame,
)
from objslam_tools.ground_truth import Distractor, GroundTruth
from objslam_tools.silhouette import VisibleObject
from objslam_tools.sim import build_scenario, write_bag


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("bags") / "small"
    write_bag(build_scenario("small", frames=6), out)
    return out


def test_detector_scores_well_on_a_rendered_bag(small_bag):
    evaluation = evaluate_bag(small_bag, Detector())
    overall = evaluation.to_dict()["overall"]
    assert evaluation.frames == 6 and overall["visible"] > 0
    assert overall["recall"] == 1.0 and overall["unexplained"] == 0
    assert overall["bearing_deg"]["median"] < 0.3 and overall["width_rel"]["median"] < 0.1
    assert "targets (overall)" in format_report(evaluation)


def test_cli_prints_json(small_bag, capsys):
    assert main(["eval-detector", str(small_bag), "--frames", "2", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["frames"] == 2 and set(data["targets"]) >= {"recall", "bearing_deg"}


def test_cli_refuses_a_folder_that_is_not_a_bag(tmp_path, capsys):
    assert main(["eval-detector", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a rosbag2 bag" in err[0]


def view(object_id: int, bearing_deg: float, width_deg: float = 5.0) -> VisibleObject:
    r = math.radians
    return VisibleObject(object_id, "red", r(bearing_deg), r(width_deg), r(-8.0), r(2.0), 3.0, 0.0, True, 15.0)


def detection(bearing_deg: float, width_deg: float = 5.0) -> SliceMeasurement:
    r = math.radians
    return SliceMeasurement("red", 1.0, r(bearing_deg), r(width_deg), r(-8.0), r(2.0), 0, 0, 0, 0, 100)


def test_matching_pairs_neighbours_one_to_one_and_flags_duplicates():
    objects = [view(0, 10.0), view(1, 20.0)]
    slices = [detection(19.5), detection(10.2), detection(11.5, 1.0), detection(60.0)]
    assigned, duplicate = match(slices, objects, EvalOptions())
    assert assigned == [1, 0, 0, None]
    assert duplicate == [False, False, True, False]


def test_unmatched_detections_are_split_into_from_a_distractor_and_unexplained():
    r = math.radians
    height = CameraMount().height_m
    # A red poster 3 m ahead, centred at camera height and facing the robot at the origin:
    # it spans +-atan(0.3 / 3) = +-5.7 deg of azimuth and +-atan(0.2 / 3) = +-3.8 deg of elevation.
    poster = Distractor(0, "poster", "red", (255, 0, 0), (3.0, 0.0, height), (0.6, 0.4), math.pi)
    gt = GroundTruth(objects=(), distractors=(poster,))
    distractors = [(poster, *distractor_sector(poster, gt, np.zeros(3)))]
    objects = [view(0, 60.0)]

    def sl(label: str, bearing_deg: float, bottom_deg: float = -3.8, top_deg: float = 3.8) -> SliceMeasurement:
        return SliceMeasurement(label, 1.0, r(bearing_deg), r(11.4), r(bottom_deg), r(top_deg), 0, 0, 0, 0, 100)

    evaluation = DetectorEvaluation(bag="by hand")
    trouble = score_frame(
        [
            detection(60.0),  # the real object
            sl("red", 0.5),  # the poster
            sl("red", 25.0),  # beside the poster
            sl("red", 0.0, 20.0, 30.0),  # above it
            sl("blue", 0.0),  # on it, but the poster is not blue
        ],
        objects,
        distractors,
        evaluation,
        EvalOptions(),
    )
    red, blue = evaluation.tallies["red"], evaluation.tallies["blue"]
    assert (red.detections, red.by_object, red.from_distractor, red.unexplained) == (4, 1, 1, 2)
    assert (blue.detections, blue.by_object, blue.from_distractor, blue.unexplained) == (1, 0, 0, 1)
    assert trouble  # unexplained detections are trouble ...
    overall = evaluation.to_dict()["overall"]
    assert (overall["from_distractor"], overall["unexplained"]) == (1, 3)

    alone = DetectorEvaluation(bag="by hand")
    # ... detections from a distractor are not.
    assert not score_frame([sl("red", 0.5)], [], distractors, alone, EvalOptions())
    assert (alone.tallies["red"].from_distractor, alone.tallies["red"].unexplained) == (1, 0)


def test_recall_is_binned_by_the_true_width_and_range_of_visible_objects():
    r = math.radians
    narrow = VisibleObject(0, "red", r(10.0), r(1.2), r(-8.0), r(2.0), 9.0, 0.0, True, 7.0)
    wide = VisibleObject(1, "red", r(40.0), r(7.0), r(-8.0), r(2.0), 3.0, 0.0, True, 40.0)
    evaluation = DetectorEvaluation(bag="by hand")
    # Two images: the wide object found in both, the narrow one in the first only.
    score_frame([detection(10.0, 1.2), detection(40.0, 7.0)], [narrow, wide], [], evaluation, EvalOptions())
    score_frame([detection(40.0, 7.0)], [narrow, wide], [], evaluation, EvalOptions())
    overall = evaluation.to_dict()["overall"]
    by_width = [(row["from"], row["visible"], row["found"], row["recall"]) for row in overall["recall_by_width_deg"]]
    assert by_width == [(1.0, 2, 1, 0.5), (6.0, 2, 2, 1.0)]
    by_range = [(row["from"], row["to"], row["recall"]) for row in overall["recall_by_range_m"]]
    assert by_range == [(2.0, 4.0, 1.0), (8.0, 10.0, 0.5)]
    assert sum(overall["recall_by_width_deg"][k]["visible"] for k in range(2)) == overall["visible"]
    assert "recall by true width (deg)" in format_report(evaluation)
