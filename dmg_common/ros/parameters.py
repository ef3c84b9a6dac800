"""Declare a node's ROS parameters from a YAML file under config/, with descriptors.

The file is the single place where defaults, descriptions and ranges live:

    parameters:
      graph.delta:
        value: 0.07
        description: adjacent supervoxels stay connected while ||n_i - n_h|| <= delta
        range: [0.0, 2.0]
        read_only: true

Values given on the command line (`-p name:=value`) or in a `--params-file` override the
defaults as usual; a value outside its range is refused by rclpy with a clear error.
"""
from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node

from dmg_common.config import load_parameter_spec


def _descriptor(name: str, entry: dict[str, Any]) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(name=name, description=str(entry.get("description", "")),
                                     read_only=bool(entry.get("read_only", False)))
    if "range" in entry:
        low, high = entry["range"]
        if isinstance(entry["value"], float):
            descriptor.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high))]
        else:
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high))]
    return descriptor


def declare_from_config(node: Node, name: str) -> dict[str, Any]:
    """Declare every parameter of config/<name>.yaml on `node`; return their current values."""
    values = {}
    for param_name, entry in load_parameter_spec(name).items():
        parameter = node.declare_parameter(param_name, entry["value"], _descriptor(param_name, entry))
        values[param_name] = parameter.value
    return values
