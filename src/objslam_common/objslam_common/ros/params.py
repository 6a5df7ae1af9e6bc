"""Mirror a component's typed config as declared ROS parameters.

Every field of the config dataclass becomes a parameter (nested dataclasses become
dotted names) declared with its description and its default; values given with
``--ros-args --params-file`` or ``-p`` override the defaults, and the result is
validated by the same code that validates YAML files (objslam_common.config).
"""

from __future__ import annotations

from typing import Any, TypeVar

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node

from objslam_common.config import flatten, from_mapping, unflatten

T = TypeVar("T")

_EMPTY_LIST_TYPE = ParameterType.PARAMETER_STRING_ARRAY


def declare_config(node: Node, config_cls: type[T]) -> T:
    """Declare the parameters of ``config_cls`` on ``node`` and return the validated config.

    Raises objslam_common.errors.ConfigError for a value that does not validate.
    """
    defaults = config_cls()
    values: dict[str, Any] = {}
    for name, (default, description) in flatten(defaults).items():
        if isinstance(default, list) and not default:
            # An empty list has no type rclpy can infer; declare it as a string array.
            descriptor = ParameterDescriptor(description=description, type=_EMPTY_LIST_TYPE, dynamic_typing=True)
        else:
            # dynamic typing lets a YAML "2" set a float; the config validation checks types.
            descriptor = ParameterDescriptor(description=description, dynamic_typing=True)
        param = node.declare_parameter(name, default, descriptor)
        values[name] = param.value
    return from_mapping(config_cls, unflatten(values))


def config_parameter_names(config_cls: type) -> list[str]:
    return sorted(flatten(config_cls()))
