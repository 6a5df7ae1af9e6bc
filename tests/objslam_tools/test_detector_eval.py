"""``objslam eval-detector``: scoring on a small rendered bag, matching rules, user errors."""

from __future__ import annotations

import json
import math

import pytest

from objslam_detector import DetectedSlice, Detector
from objslam_tools.cli import main
from objslam_tools.detector_eval import EvalOptions, evaluate_bag, format_report, match
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


def detection(bearing_deg: float, width_deg: float = 5.0) -> DetectedSlice:
    r = math.radians
    return DetectedSlice("red", 1.0, r(bearing_deg), r(width_deg), r(-8.0), r(2.0), 0, 0, 0, 0, 100)


def test_matching_pairs_neighbours_one_to_one_and_flags_duplicates():
    objects = [view(0, 10.0), view(1, 20.0)]
    slices = [detection(19.5), detection(10.2), detection(11.5, 1.0), detection(60.0)]
    assigned, duplicate = match(slices, objects, EvalOptions())
    assert assigned == [1, 0, 0, None]
    assert duplicate == [False, False, True, False]
