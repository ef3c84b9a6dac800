"""The executor core's settings: the values of config/executor.yaml in SI units.

The node fills them from its ROS parameters, tests and tools from the file's defaults, so
both run the same controller on the same numbers.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, get_type_hints

import numpy as np

from dmg_common.config import parameter_defaults
from dmg_common.gripper import load_gripper


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
    judge_wait: float              # s


@dataclass(frozen=True)
class ApproachSettings:
    """Getting the pusher to a push start (`approach.*`)."""

    gain: float                    # 1/s
    speed: float
    clearance: float
    waypoint_tolerance: float
    stall_time: float
    waypoint_turn_tolerance: float   # rad
    exit_margin: float
    headway_distance: float
    headway_turn: float            # rad
    headway_share: float
    other_views: int
    distinct_view: float           # rad
    view_short: float              # rad
    escape_depth: float
    far_side_cost: float
    palm_reach: float


@dataclass(frozen=True)
class PushSettings:
    """Choosing and judging pushes (`push.*`)."""

    linear_gain: float             # 1/s
    angular_gain: float            # 1/s
    speed: float
    min_speed: float
    gap: float
    touch_margin: float
    depth: float
    edge_margin: float
    max_angle: float               # rad
    turn_stall: float              # rad
    rotation_slide: float
    turn_slide: float              # m^2
    grasp_margin: float
    grasp_square: float            # rad
    blind: bool
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

    stale_after: float
    stale_after_held: float
    robot_timeout: float
    dropped_share: float
    forced_open: float
    push_tilt_stop: float
    turn_drift: float


@dataclass(frozen=True)
class HolderSettings:
    """When gripper 1 may go back to where it started (`holder.*`)."""

    turn: float                    # rad
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

    tilt: float                    # rad
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

    opening: float
    margins: np.ndarray
    twist: float                   # rad
    fingers: float                 # rad


@dataclass(frozen=True)
class BetweenSettings:
    """Pushes between gripper 1's fingers on the object's palm side, the pusher coming in across them (`between.*`)."""

    enabled: bool
    fingers: float                 # rad
    twist: float                   # rad


@dataclass(frozen=True)
class CarrySettings:
    """Carries: the object let down along gripper 1's fingers on the pusher's tips (`carry.*`)."""

    enabled: bool
    weight_share: float
    cone: float                    # rad
    follow_lag: float


@dataclass(frozen=True)
class ViewSettings:
    """Which tags the wrist camera would see from a pusher pose (`views.*`)."""

    tilt_limit: float              # rad
    roll_limit: float              # rad
    grid_step: float               # rad
    edge_margin_px: float
    facing_limit: float            # rad
    smallest_side_px: float
    level: float                   # rad
    in_line: float                 # rad
    nearest: float
    surface_slack: float


@dataclass(frozen=True)
class SteeringSettings:
    """Sliding the pusher along the grasp axis to steer a translated object's tilt back (`steering.*`)."""

    gain: float                    # m/s per rad
    speed: float
    turn_offset: float             # m per rad
    turn_offset_limit: float


@dataclass(frozen=True)
class LimitSettings:
    """Where the grippers may go, how fast they turn, how long a step may take (`limits.*`)."""

    workspace_min: np.ndarray
    workspace_max: np.ndarray
    holder_travel: float
    angular_speed: float           # rad/s
    step_timeout: float


@dataclass(frozen=True)
class GripperSettings:
    """The pushing gripper's shape: round fingertips, fingers and the hand behind them (`gripper.*`); the tip
    radius and finger length come from config/gripper.yaml, the description the planner and the sim share."""

    tip_radius: float
    finger_length: float
    hand_start: float
    hand_end: float
    hand_radius: float


@dataclass(frozen=True)
class GripSettings:
    """Gripper 1's grip on the object: held, or loosened for a push (`grip.*`)."""

    hold_force: float
    slide_force: float
    friction: float
    tilt_hold_margin: float
    torsional_friction: float
    turn_hold_margin: float
    slide_squeeze: float
    settle: float
    finger_gain: float


@dataclass(frozen=True)
class ToleranceSettings:
    """When a push (and the run) is close enough (`tolerances.*`)."""

    position: float
    angle: float                   # rad
    goal_position: float
    goal_angle: float              # rad


@dataclass(frozen=True)
class SlipSettings:
    """What counts as a slip, and how sure a pose must be to show one (`slip.*`)."""

    distance: float
    angle: float                   # rad
    tilt_sigma: float              # rad
    position_sigma: float
    poses: int
    reference_poses: int


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


@dataclass(frozen=True)
class ExecutorSettings:
    """Every tunable of the executor core, in groups named as the parameters' prefixes."""

    campaign: CampaignSettings
    approach: ApproachSettings
    push: PushSettings
    steering: SteeringSettings
    fingertips: FingertipSettings
    monitors: MonitorSettings
    holder: HolderSettings
    look: LookSettings
    level: LevelSettings
    straddle: StraddleSettings
    between: BetweenSettings
    carry: CarrySettings
    views: ViewSettings
    limits: LimitSettings
    gripper: GripperSettings
    grip: GripSettings
    tolerances: ToleranceSettings
    slip: SlipSettings

    @classmethod
    def from_values(cls, values: dict[str, Any]) -> "ExecutorSettings":
        """From parameter values named as in config/executor.yaml (angles there in degrees; a group's
        parameters are named `<group>.<field>`); the gripper's tip radius and finger length, unless given,
        from config/gripper.yaml."""
        gripper = load_gripper()
        values = {"gripper.tip_radius": gripper.tip_radius, "gripper.finger_length": gripper.finger_length, **values}
        settings = cls(**{field.name: _group(_GROUPS[field.name], field.name, values) for field in fields(cls)})
        settings.validate()
        return settings

    @classmethod
    def defaults(cls, **overrides: Any) -> "ExecutorSettings":
        return cls.from_values({**parameter_defaults("executor"), **overrides})

    def validate(self) -> None:
        limits, push, grip = self.limits, self.push, self.grip
        if limits.workspace_min.shape != (3,) or limits.workspace_max.shape != (3,) or \
                np.any(limits.workspace_min >= limits.workspace_max):
            raise ValueError(f"limits.workspace_min {limits.workspace_min.tolist()} must be 3 values below "
                             f"limits.workspace_max {limits.workspace_max.tolist()}")
        if push.min_speed > push.speed:
            raise ValueError(f"push.min_speed {push.min_speed} exceeds push.speed {push.speed}")
        if grip.slide_force > grip.hold_force:
            raise ValueError(f"grip.slide_force {grip.slide_force} N exceeds grip.hold_force {grip.hold_force} N")


_GROUPS = get_type_hints(ExecutorSettings)
