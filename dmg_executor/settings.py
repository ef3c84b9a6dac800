"""The executor core's settings: the values of config/executor.yaml in SI units.

The node fills them from its ROS parameters, tests and tools from the file's defaults, so
both run the same controller on the same numbers.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from dmg_common.config import parameter_defaults


@dataclass(frozen=True)
class ExecutorSettings:
    linear_gain: float
    angular_gain: float
    finger_gain: float
    approach_gain: float
    tilt_gain: float               # m/s per rad
    tilt_speed: float
    tilt_limit: float              # rad
    roll_limit: float              # rad
    approach_speed: float
    push_speed: float
    min_push_speed: float
    max_angular_speed: float
    workspace_min: np.ndarray
    workspace_max: np.ndarray
    holder_travel: float
    tip_radius: float
    clearance: float
    gap: float
    push_depth: float
    edge_margin: float
    finger_length: float
    hand_start: float
    hand_end: float
    hand_radius: float
    max_push_angle: float          # rad
    touch_margin: float
    turn_stall: float              # rad
    rotation_slide: float
    hold_force: float
    slide_force: float
    grip_friction: float
    tilt_hold_margin: float
    slide_squeeze: float
    grip_settle: float
    position_tolerance: float
    goal_position_tolerance: float
    goal_angle_tolerance: float    # rad
    angle_tolerance: float         # rad
    waypoint_tolerance: float
    stale_after: float
    stale_after_held: float
    robot_timeout: float
    slip_distance: float
    slip_angle: float              # rad
    slip_poses: int
    reference_poses: int
    slip_tilt_sigma: float         # rad
    slip_position_sigma: float
    step_timeout: float
    stall_time: float
    blind_pushes: bool
    straddle_opening: float
    holder_turn: float             # rad
    level_tilt: float              # rad

    @classmethod
    def from_values(cls, values: dict[str, Any]) -> "ExecutorSettings":
        """From parameter values named as in config/executor.yaml (angles there in degrees)."""
        converted = {}
        for field in fields(cls):
            if field.name in values:
                value = values[field.name]
            else:
                value = np.deg2rad(float(values[f"{field.name}_deg"]))
            converted[field.name] = (np.asarray(value, float) if field.name.startswith("workspace")
                                     else int(value) if field.type in (int, "int")
                                     else bool(value) if field.type in (bool, "bool") else float(value))
        settings = cls(**converted)
        settings.validate()
        return settings

    @classmethod
    def defaults(cls, **overrides: Any) -> "ExecutorSettings":
        return cls.from_values({**parameter_defaults("executor"), **overrides})

    def validate(self) -> None:
        if self.workspace_min.shape != (3,) or self.workspace_max.shape != (3,) or \
                np.any(self.workspace_min >= self.workspace_max):
            raise ValueError(f"workspace_min {self.workspace_min.tolist()} must be 3 values below "
                             f"workspace_max {self.workspace_max.tolist()}")
        if self.min_push_speed > self.push_speed:
            raise ValueError(f"min_push_speed {self.min_push_speed} exceeds push_speed {self.push_speed}")
        if self.slide_force > self.hold_force:
            raise ValueError(f"slide_force {self.slide_force} N exceeds hold_force {self.hold_force} N")
