"""Config dataclasses mirrored as declared ROS parameters (in-process node, no graph needed)."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
import rclpy
from rclpy.parameter import Parameter

from objslam_common.config import setting
from objslam_common.errors import ConfigError
from objslam_common.ros.params import declare_config


@dataclass(frozen=True)
class Inner:
    sigma_rad: float = setting(0.01, "noise", minimum=0.0)


@dataclass(frozen=True)
class Outer:
    samples: int = setting(10, "how many")
    name: str = setting("x", "a name")
    inner: Inner = setting(Inner(), "nested")
    labels: tuple[str, ...] = setting((), "labels")


@pytest.fixture
def rcl():
    rclpy.init()
    yield
    rclpy.try_shutdown()


def test_defaults_are_declared_with_descriptions(rcl):
    node = rclpy.create_node("params_defaults")
    try:
        config = declare_config(node, Outer)
        assert config == Outer()
        descriptor = node.describe_parameter("inner.sigma_rad")
        assert descriptor.description == "noise"
        assert node.get_parameter("samples").value == 10
    finally:
        node.destroy_node()


def test_overrides_are_validated(rcl):
    overrides = [Parameter("inner.sigma_rad", value=2), Parameter("labels", value=["red", "blue"])]
    node = rclpy.create_node("params_overrides", parameter_overrides=overrides)
    try:
        config = declare_config(node, Outer)
        assert config.inner.sigma_rad == 2.0
        assert config.labels == ("red", "blue")
    finally:
        node.destroy_node()


def test_out_of_range_override_is_a_config_error(rcl):
    node = rclpy.create_node("params_bad", parameter_overrides=[Parameter("inner.sigma_rad", value=-1.0)])
    try:
        with pytest.raises(ConfigError, match=r"inner\.sigma_rad"):
            declare_config(node, Outer)
    finally:
        node.destroy_node()
