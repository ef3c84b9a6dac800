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
class CampaignSettings:
    """How many pushes a primitive and the plan's end get, and when pushing stops (`campaign.*`)."""

    max_pushes_per_primitive: int
    max_corrections: int
    retry_factor: float
    no_headway: float
    settled_share: float
    unreachable_cone: float        # rad
    shortfall_cone: float          # rad
    partial_miss_turn: float       # rad


@dataclass(frozen=True)
class ApproachSettings:
    """Getting the pusher to a push start (`approach.*`)."""

    waypoint_turn_tolerance: float   # rad
    exit_margin: float
    headway_distance: float
    headway_turn: float            # rad
    other_views: int
    distinct_view: float           # rad
    view_short: float              # rad
    escape_depth: float
    far_side_cost: float
    palm_reach: float


@dataclass(frozen=True)
class PushSettings:
    """Choosing and judging pushes (`push.*`)."""

    lever_shares: np.ndarray
    off_middle_shares: np.ndarray
    face_rays: int
    detour_limit: float            # rad
    same_push: float               # rad
    turn_gain: float               # rad
    missed_turn: float             # rad
    missed_near_distance: float
    missed_near: float             # rad
    touched: float
    slant_limit: float             # rad
    translation_slant: float       # rad


@dataclass(frozen=True)
class FingertipSettings:
    """Where the pusher's round fingertips meet a face (`fingertips.*`)."""

    leading_tip: float
    tip_clearance: float
    rims: np.ndarray               # rad
    rim_turn_step: float           # rad
    sweep_limit: float             # rad
    sweep_step: float              # rad
    sweep_reach: float
    sweep_back: float


@dataclass(frozen=True)
class MonitorSettings:
    """Stops and faults read from the grip and the object's turn (`monitors.*`)."""

    dropped_share: float
    forced_open: float
    push_tilt_stop: float
    turn_drift: float


@dataclass(frozen=True)
class HolderSettings:
    """When gripper 1 may go back to where it started (`holder.*`)."""

    moved_distance: float
    moved_turn: float              # rad


@dataclass(frozen=True)
class LookSettings:
    """Looking for the object or for a certain pose of it (`look.*`)."""

    turns: np.ndarray              # rad
    places: int
    same_place: float
    view_poses: int
    fruitless_near: float


@dataclass(frozen=True)
class LevelSettings:
    """Pressing a tilted grasp level (`level.*`)."""

    done: float                    # rad
    slack: float
    press_give: float
    pushes: int
    slide: float
    levers: np.ndarray
    off_axis: np.ndarray           # rad
    reach_cone: float              # rad


@dataclass(frozen=True)
class StraddleSettings:
    """Straddle pushes: the pusher's tips either side of gripper 1's fingers (`straddle.*`)."""

    margins: np.ndarray
    twist: float                   # rad
    fingers: float                 # rad


@dataclass(frozen=True)
class ViewSettings:
    """Which tags the wrist camera would see from a pusher pose (`views.*`)."""

    grid_step: float               # rad
    edge_margin_px: float
    facing_limit: float            # rad
    smallest_side_px: float
    level: float                   # rad
    in_line: float                 # rad
    nearest: float
    surface_slack: float


def _value(annotation: Any, name: str, values: dict[str, Any]) -> Any:
    """values[name] (or values[name + "_deg"] in radians) as the field's type."""
    degrees = name not in values
    value = values[f"{name}_deg"] if degrees else values[name]
    if annotation in (int, "int"):
        return int(value)
    if annotation in (bool, "bool"):
        return bool(value)
    array = np.asarray(value, float)
    array = np.deg2rad(array) if degrees else array
    return array if annotation in (np.ndarray, "np.ndarray") else float(array)


def _group(group_class: type, prefix: str, values: dict[str, Any]) -> Any:
    inner = {key[len(prefix) + 1:]: value for key, value in values.items() if key.startswith(prefix + ".")}
    return group_class(**{f.name: _value(f.type, f.name, inner) for f in fields(group_class)})


GROUPS = {"campaign": CampaignSettings, "approach": ApproachSettings, "push": PushSettings,
          "fingertips": FingertipSettings, "monitors": MonitorSettings, "holder": HolderSettings,
          "look": LookSettings, "level": LevelSettings, "straddle": StraddleSettings, "views": ViewSettings}


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
    campaign: CampaignSettings
    approach: ApproachSettings
    push: PushSettings
    fingertips: FingertipSettings
    monitors: MonitorSettings
    holder: HolderSettings
    look: LookSettings
    level: LevelSettings
    straddle: StraddleSettings
    views: ViewSettings

    @classmethod
    def from_values(cls, values: dict[str, Any]) -> "ExecutorSettings":
        """From parameter values named as in config/executor.yaml (angles there in degrees; a group's
        parameters are named `<group>.<field>`)."""
        converted = {}
        for field in fields(cls):
            if field.name in GROUPS:
                converted[field.name] = _group(GROUPS[field.name], field.name, values)
            elif field.name.startswith("workspace"):
                converted[field.name] = np.asarray(values[field.name], float)
            else:
                converted[field.name] = _value(field.type, field.name, values)
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
