"""Fuzzing the ground-truth reader (``objslam eval``, ``eval-detector``, the oracle): whatever
``ground_truth.yaml`` holds, a GroundTruth or one UserError line, nothing else."""

from __future__ import annotations

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from objslam_tools.errors import UserError
from objslam_tools.ground_truth import GroundTruth, load_ground_truth
from tests.conftest import BAGS
from tests.fuzz import mutated

_VALID = yaml.safe_load((BAGS / "small" / "ground_truth.yaml").read_text())
_FIXTURES = [HealthCheck.function_scoped_fixture]


def _load(path) -> None:
    try:
        truth = load_ground_truth(path)
    except UserError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc)
        return
    assert isinstance(truth, GroundTruth)


@settings(max_examples=150, deadline=None, suppress_health_check=_FIXTURES)
@given(document=mutated(_VALID))
def test_any_ground_truth_loads_or_is_one_user_error(tmp_path, document):
    path = tmp_path / "ground_truth.yaml"
    path.write_text(yaml.safe_dump(document, allow_unicode=True))
    _load(path)


@settings(max_examples=40, deadline=None, suppress_health_check=_FIXTURES)
@given(data=st.binary(max_size=64))
def test_any_bytes_as_ground_truth_are_one_user_error(tmp_path, data):
    path = tmp_path / "ground_truth.yaml"
    path.write_bytes(data)
    _load(path)


def test_an_infinite_id_is_one_user_error(tmp_path):
    document = {**_VALID, "objects": [{**_VALID["objects"][0], "id": float("inf")}]}
    path = tmp_path / "ground_truth.yaml"
    path.write_text(yaml.safe_dump(document))
    try:
        load_ground_truth(path)
    except UserError as exc:
        assert "malformed ground truth: cannot convert float infinity to integer" in str(exc)
    else:
        raise AssertionError("an infinite id was accepted")
