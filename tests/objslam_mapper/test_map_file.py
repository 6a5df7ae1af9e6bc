"""The map YAML: round trip, contract field names, errors."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from objslam_mapper.map_file import BuiltMap, MapFileError, MappedObject, TrajectoryPose, read_map, write_map


def _map() -> BuiltMap:
    cov = tuple(tuple(float(v) for v in row) for row in np.diag([0.01, 0.02, 0.0001]))
    return BuiltMap(
        objects=(
            MappedObject(
                3, "red", (1.0, 2.0, 0.0), (0.3, 0.6), 0.93, cov, ((1e-4, 0.0), (0.0, 4e-4)), 42, (0.9, 0.96, 0.93)
            ),
        ),
        rejected=(MappedObject(7, "cyan", (4.0, -1.0, 0.75), (0.15, 0.25), 0.2),),
        trajectory=(TrajectoryPose(1_700_000_000_250_000_000, 0.5, -0.25, 0.1),),
        diagnostics={"samples": 6000, "burn_in": 2500, "acceptance": {"merge": np.float64(0.1)}},
    )


def test_round_trip_keeps_everything(tmp_path):
    path = write_map(tmp_path / "sub" / "map.yaml", _map())
    assert read_map(path) == _map()


def test_file_uses_the_contract_field_names(tmp_path):
    data = yaml.safe_load(write_map(tmp_path / "m.yaml", _map()).read_text())
    assert set(data) >= {"objects", "rejected", "trajectory", "diagnostics"}
    obj = data["objects"][0]
    assert obj["position"] == [1.0, 2.0, 0.0] and obj["size"] == [0.3, 0.6]
    assert obj["existence_probability"] == 0.93 and obj["measurement_count"] == 42
    assert data["trajectory"][0] == {
        "stamp": 1700000000.25,
        "x": 0.5,
        "y": -0.25,
        "theta": 0.1,
        "stamp_ns": 1_700_000_000_250_000_000,
    }


def test_not_a_map_is_one_clear_error(tmp_path):
    path = tmp_path / "x.yaml"
    path.write_text("hello: 1\n")
    with pytest.raises(MapFileError, match="not an objslam map file"):
        read_map(path)


# Fuzzing: `objslam eval` and `objslam figures` read map files a user names; whatever the
# file holds, read_map gives a map or one MapFileError, nothing else.
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis.strategies import binary as st_binary  # noqa: E402

from objslam_mapper.map_file import map_to_dict  # noqa: E402
from tests.fuzz import mutated  # noqa: E402

_VALID = yaml.safe_load(yaml.safe_dump(map_to_dict(_map())))


def _read_document(document, directory) -> None:
    path = directory / "fuzzed.yaml"
    path.write_text(yaml.safe_dump(document, allow_unicode=True))
    try:
        built = read_map(path)
    except MapFileError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc)
        return
    assert isinstance(built, BuiltMap)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(document=mutated(_VALID))
def test_any_map_file_reads_or_is_one_map_file_error(tmp_path, document):
    _read_document(document, tmp_path)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st_binary())
def test_any_bytes_as_a_map_file_read_or_are_one_error(tmp_path, data):
    from objslam_common.errors import ConfigError

    path = tmp_path / "bytes.yaml"
    path.write_bytes(data)
    try:
        read_map(path)
    except (MapFileError, ConfigError) as exc:
        assert "\n" not in str(exc)
