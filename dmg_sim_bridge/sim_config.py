"""config/sim.yaml: the cell's physics options and gripper, as MJCF and GripperSpec."""
from __future__ import annotations

import yaml

from dmg_planner.objects import config_dir
from dmg_sim_bridge.gripper import GripperSpec


def load_sim_config() -> dict:
    return yaml.safe_load((config_dir() / "sim.yaml").read_text())


def option_xml(config: dict) -> str:
    physics = config["physics"]
    return (f'<option timestep="{physics["timestep"]}" cone="{physics["cone"]}" impratio="{physics["impratio"]}" '
            f'noslip_iterations="{physics["noslip_iterations"]}"/>')


def gripper_spec(config: dict) -> GripperSpec:
    values = dict(config["gripper"])
    values["friction"] = tuple(values["friction"])
    return GripperSpec(**values)
