"""The typed config mechanism: parameter files, validation, flattening."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from objslam_common.config import flatten, from_mapping, load_config, setting, unflatten
from objslam_common.errors import ConfigError


@dataclass(frozen=True)
class Noise:
    bearing_rad: float = setting(0.01, "bearing noise", minimum=0.0)


@dataclass(frozen=True)
class Component:
    samples: int = setting(6000, "samples", minimum=1)
    enabled: bool = setting(True, "on")
    noise: Noise = setting(Noise(), "noise")


def test_parameter_file_section_overrides_defaults(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("comp:\n  ros__parameters:\n    samples: 10\n    noise.bearing_rad: 0.5\nother:\n  x: 1\n")
    config = load_config(Component, path, "comp")
    assert config == Component(samples=10, noise=Noise(bearing_rad=0.5))


def test_wildcard_section_applies(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters:\n    enabled: false\n")
    assert load_config(Component, path, "comp").enabled is False


@pytest.mark.parametrize(
    ("mapping", "message"),
    [
        ({"sampels": 1}, "unknown setting 'sampels'"),
        ({"samples": "many"}, "'samples' must be an integer"),
        ({"samples": 0}, "'samples' must be >= 1"),
        ({"enabled": 1}, "'enabled' must be true or false"),
        ({"noise": {"bearing_rad": -1}}, "'noise.bearing_rad' must be >= 0"),
        ({"noise": {"bering_rad": 1}}, "unknown setting 'noise.bering_rad'"),
        ({"noise": {"bearing_rad": float("nan")}}, "'noise.bearing_rad' must be a finite number"),
        ({"noise": {"bearing_rad": float("inf")}}, "'noise.bearing_rad' must be a finite number"),
    ],
)
def test_bad_values_name_the_key(mapping, message):
    with pytest.raises(ConfigError, match=message):
        from_mapping(Component, mapping)


def test_missing_and_malformed_files_are_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(Component, tmp_path / "nope.yaml", "comp")
    bad = tmp_path / "bad.yaml"
    bad.write_text("comp: [unclosed\n")
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(Component, bad, "comp")


def test_a_file_without_this_nodes_settings_is_refused(tmp_path):
    empty = tmp_path / "empty.yaml"
    empty.write_text("# nothing yet\n")
    with pytest.raises(ConfigError, match="is empty: expected 'comp: ros__parameters"):
        load_config(Component, empty, "comp")
    other = tmp_path / "other.yaml"
    other.write_text("detector:\n  ros__parameters:\n    samples: 3\n")
    with pytest.raises(ConfigError, match="no settings for 'comp' \\(it has 'detector'\\)"):
        load_config(Component, other, "comp")


def test_nan_in_a_parameter_file_is_refused(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("comp:\n  ros__parameters:\n    noise:\n      bearing_rad: .nan\n")
    with pytest.raises(ConfigError, match="finite"):
        load_config(Component, path, "comp")


YAML_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=12), inner, max_size=3),
    max_leaves=8,
)
KEYS = st.sampled_from(["samples", "enabled", "noise", "noise.bearing_rad", "bearing_rad", "x"]) | st.text(max_size=8)


@settings(max_examples=300, deadline=None)
@given(
    document=st.one_of(
        YAML_VALUES,
        st.dictionaries(
            st.sampled_from(["comp", "/**", "/comp", "other"]),
            st.one_of(YAML_VALUES, st.fixed_dictionaries({"ros__parameters": st.dictionaries(KEYS, YAML_VALUES)})),
            max_size=2,
        ),
    )
)
def test_any_parameter_file_loads_or_is_one_config_error(tmp_path_factory, document):
    """Fuzzing: whatever YAML a user writes, the loader returns a valid config or a ConfigError."""
    path = tmp_path_factory.mktemp("fuzz") / "p.yaml"
    path.write_text(yaml.safe_dump(document))
    try:
        config = load_config(Component, path, "comp")
    except ConfigError as exc:
        assert str(exc) and "\n" not in str(exc)
    else:
        assert isinstance(config, Component) and config.samples >= 1 and config.noise.bearing_rad >= 0.0


def test_flatten_round_trips_through_unflatten():
    config = Component(samples=3, noise=Noise(0.2))
    flat = flatten(config)
    assert flat["noise.bearing_rad"] == (0.2, "bearing noise")
    assert from_mapping(Component, unflatten({k: v for k, (v, _d) in flat.items()})) == config


def _parameter_names(section: dict, prefix: str = "") -> set[str]:
    names: set[str] = set()
    for key, value in section.items():
        names |= _parameter_names(value, f"{prefix}{key}.") if isinstance(value, dict) else {prefix + key}
    return names


def test_bundled_mapper_parameter_file_lists_every_parameter_at_its_default(repo_root):
    """config/mapper.yaml is the mapper's documentation: every parameter, at its default."""
    import yaml

    from objslam_mapper.config import MapperConfig

    path = repo_root / "config" / "mapper.yaml"
    section = yaml.safe_load(path.read_text())["mapper"]["ros__parameters"]
    assert _parameter_names(section) == set(flatten(MapperConfig()))
    assert load_config(MapperConfig, path, "mapper") == MapperConfig()
