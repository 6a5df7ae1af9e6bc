"""Typed, validated configuration shared by every component.

Each component has one frozen dataclass of settings. Fields are declared with
``setting(default, description)`` so that the same object can be

- loaded from a ROS 2 parameter file (``config/*.yaml``, ``<node>: ros__parameters:``),
- mirrored as declared ROS parameters with descriptions (nested dataclasses become
  dotted names, e.g. ``odometry.sigma_xy_per_m``),
- validated once: unknown keys, wrong types and out-of-range values raise ConfigError
  naming the key.
"""

from __future__ import annotations

import dataclasses
import math
import os
import textwrap
import typing
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

import yaml

from objslam_common.errors import ConfigError

T = TypeVar("T")


def setting(
    default: Any,
    description: str,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    expert: bool = False,
) -> Any:
    """A dataclass field with its one description (and optional bounds) for ROS parameters,
    parameter files and the docs. ``expert``: a setting (or a whole section) that only
    someone who knows the method should change; marked so in config/*.yaml and the docs."""
    metadata = {"description": description, "minimum": minimum, "maximum": maximum, "expert": expert}
    if isinstance(default, (list, dict)) or dataclasses.is_dataclass(default):
        return dataclasses.field(default_factory=lambda: default, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def default_config_dir() -> Path:
    """The directory holding the bundled ``config/*.yaml``.

    ``OBJSLAM_CONFIG_DIR`` wins; then the repository's ``config/`` (source checkouts,
    editable and symlink installs); then the copy installed in the ament share dir.
    """
    env = os.environ.get("OBJSLAM_CONFIG_DIR")
    if env:
        return Path(env)
    repo_config = Path(__file__).resolve().parents[3] / "config"
    if (repo_config / "catalog.yaml").is_file():
        return repo_config
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory("objslam_common")) / "config"
    except Exception as exc:  # ament index absent or package not installed
        raise ConfigError("cannot find the bundled config directory; set OBJSLAM_CONFIG_DIR") from exc


def read_yaml(path: str | os.PathLike[str]) -> Any:
    """Parse a YAML file, turning every failure into one ConfigError line."""
    path = Path(path)
    try:
        with path.open() as stream:
            return yaml.safe_load(stream)
    except FileNotFoundError as exc:
        raise ConfigError(f"config file not found: {path}") from exc
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:  # a binary file is not UTF-8
        raise ConfigError(f"cannot read {path}: {exc}".splitlines()[0]) from exc


def read_ros_parameters(path: str | os.PathLike[str], node_name: str) -> dict[str, Any]:
    """The ``ros__parameters`` of ``node_name`` (or ``/**``) from a ROS 2 parameter file.

    Nested mappings are kept nested; dotted keys are expanded into nesting.
    """
    data = read_yaml(path)
    if data is None:
        raise ConfigError(f"{path} is empty: expected '{node_name}: ros__parameters: ...' (see `objslam params`)")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping of node names")
    keys = ("/**", node_name, f"/{node_name}")
    if not any(key in data for key in keys):
        found = ", ".join(repr(str(k)) for k in data) or "nothing"
        raise ConfigError(f"{path} has no settings for '{node_name}' (it has {found}); is it the other node's file?")
    merged: dict[str, Any] = {}
    for key in keys:
        section = data.get(key)
        if section is None:
            continue
        params = section.get("ros__parameters") if isinstance(section, dict) else None
        if not isinstance(params, dict):
            raise ConfigError(f"{path}: '{key}' has no 'ros__parameters' mapping")
        _deep_update(merged, unflatten(params))
    return merged


def _deep_update(target: dict[str, Any], source: dict[str, Any]) -> None:
    for key, value in source.items():
        if isinstance(value, dict) and isinstance(target.get(key), dict):
            _deep_update(target[key], value)
        else:
            target[key] = value


def unflatten(flat: dict[str, Any]) -> dict[str, Any]:
    """{'a.b': 1} -> {'a': {'b': 1}}; already nested mappings pass through."""
    nested: dict[str, Any] = {}
    for key, value in flat.items():
        parts = str(key).split(".")
        node = nested
        for k, part in enumerate(parts[:-1]):
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(f"'{'.'.join(parts[: k + 1])}' is given both as a value and as a section")
        if isinstance(value, dict):
            section = node.setdefault(parts[-1], {})
            if not isinstance(section, dict):
                raise ConfigError(f"'{key}' is given both as a value and as a section")
            _deep_update(section, unflatten(value))
        elif isinstance(node.get(parts[-1]), dict):
            raise ConfigError(f"'{key}' is given both as a value and as a section")
        else:
            node[parts[-1]] = value
    return nested


def _coerce(name: str, value: Any, annotation: Any, meta: dict[str, Any]) -> Any:
    origin = typing.get_origin(annotation)
    if dataclasses.is_dataclass(annotation):
        if not isinstance(value, dict):
            raise ConfigError(f"'{name}' must be a mapping")
        return from_mapping(typing.cast(type, annotation), value, prefix=f"{name}.")
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"'{name}' must be true or false, got {value!r}")
        return value
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"'{name}' must be an integer, got {value!r}")
        result: Any = value
    elif annotation is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"'{name}' must be a number, got {value!r}")
        result = float(value)
        if not math.isfinite(result):  # YAML's .nan and .inf are numbers, but no setting takes them
            raise ConfigError(f"'{name}' must be a finite number, got {value!r}")
    elif annotation is str:
        if not isinstance(value, str):
            raise ConfigError(f"'{name}' must be a string, got {value!r}")
        return value
    elif origin in (tuple, list):
        (item_type, *_rest) = typing.get_args(annotation) or (Any,)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"'{name}' must be a list, got {value!r}")
        items = [_coerce(f"{name}[{i}]", v, item_type, {}) if item_type is not Any else v for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    else:
        return value
    lo, hi = meta.get("minimum"), meta.get("maximum")
    if lo is not None and result < lo:
        raise ConfigError(f"'{name}' must be >= {lo}, got {result}")
    if hi is not None and result > hi:
        raise ConfigError(f"'{name}' must be <= {hi}, got {result}")
    return result


def from_mapping(cls: type[T], mapping: dict[str, Any], prefix: str = "") -> T:
    """Build and validate a config dataclass from a (nested) mapping; missing keys keep defaults."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(mapping) - set(fields))
    if unknown:
        raise ConfigError(f"unknown setting '{prefix}{unknown[0]}' (known: {', '.join(sorted(fields))})")
    kwargs = {}
    for key, value in mapping.items():
        kwargs[key] = _coerce(prefix + key, value, hints[key], dict(fields[key].metadata))
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{prefix or cls.__name__}: {exc}") from exc


def load_config(cls: type[T], path: str | os.PathLike[str] | None, node_name: str) -> T:
    """Defaults of ``cls`` overridden by the node's section of a parameter file (if given)."""
    if path is None:
        return cls()
    return from_mapping(cls, read_ros_parameters(path, node_name))


def flatten(config: Any, prefix: str = "") -> dict[str, tuple[Any, str]]:
    """Dotted parameter name -> (value, description), for declaring ROS parameters."""
    return {p.name: (p.value, p.description) for p in parameters(config, prefix)}


class Parameter(NamedTuple):
    """One leaf setting of a config, as a parameter file and the docs show it."""

    name: str  # dotted, e.g. "sampler.screen.floor"
    value: Any  # the config's value (tuples as lists)
    description: str
    expert: bool  # the setting or a section above it is marked expert
    minimum: float | None
    maximum: float | None
    section: str  # the description of the section it is in ("" at the top)


def parameters(config: Any, prefix: str = "", expert: bool = False, section: str = "") -> list[Parameter]:
    """Every leaf setting of ``config`` in declaration order (nested dataclasses flattened)."""
    found: list[Parameter] = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        name = prefix + f.name
        meta = f.metadata
        is_expert = expert or bool(meta.get("expert", False))
        if dataclasses.is_dataclass(value):
            found += parameters(value, name + ".", is_expert, meta.get("description", ""))
        else:
            shown = list(value) if isinstance(value, tuple) else value
            found.append(
                Parameter(
                    name=name,
                    value=shown,
                    description=meta.get("description", ""),
                    expert=is_expert,
                    minimum=meta.get("minimum"),
                    maximum=meta.get("maximum"),
                    section=section,
                )
            )
    return found


def to_mapping(config: Any) -> dict[str, Any]:
    """Nested plain mapping of a config (for YAML output)."""
    return unflatten({k: v for k, (v, _d) in flatten(config).items()})


EXPERT_MARK = "[expert]"


def parameter_file(config: Any, node_name: str, title: str, width: int = 100) -> str:
    """A ROS 2 parameter file of ``config`` (its values, each under its description as a
    comment, expert settings and sections marked ``[expert]``), which loads back to ``config``.

    Lists that are empty are left as comments: a ROS 2 parameter file cannot hold one.
    """
    lines = [f"# {line}" for line in textwrap.wrap(title, width - 2)]
    lines += [
        "# Generated from the settings' descriptions in the code by `objslam params`; every key is",
        f"# optional. {EXPERT_MARK} marks what only someone who knows the method should change.",
        f"{node_name}:",
        "  ros__parameters:",
    ]
    lines += _parameter_lines(config, "    ", width)
    return "\n".join(lines) + "\n"


def _parameter_lines(config: Any, indent: str, width: int) -> list[str]:
    lines: list[str] = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        description = str(f.metadata.get("description", ""))
        if f.metadata.get("expert", False):
            description = f"{EXPERT_MARK} {description}"
        lines += [f"{indent}# {line}" for line in textwrap.wrap(description, width - len(indent) - 2)]
        if dataclasses.is_dataclass(value):
            lines.append(f"{indent}{f.name}:")
            lines += _parameter_lines(value, indent + "  ", width)
        elif isinstance(value, (list, tuple)) and not value:
            lines.append(f"{indent}# {f.name}: []  (empty: a ROS 2 parameter file cannot hold an empty list)")
        else:
            shown = list(value) if isinstance(value, tuple) else value
            text = yaml.safe_dump({f.name: shown}, default_flow_style=True, width=10_000).strip()[1:-1]
            lines.append(f"{indent}{text}")
    return lines
