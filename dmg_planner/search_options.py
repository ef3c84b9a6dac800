"""What a plan request may choose (the search's costs and margins) and the statuses a plan ends with.

Apart from the search itself (which needs the graph and open3d), so that the CLI and the message
conversions can name them without loading it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from dmg_common.gripper import gripper_description

# The costs a request may set (PlanRepositioning's SearchOptions, `dmg graph plan`); the rest is configuration.
PENALTIES = ("rotation_penalty", "opening_change_penalty", "pull_penalty", "arm_collision_penalty", "unpushable_penalty")


class PlanStatus(IntEnum):
    """Same values as the error codes of dmg_interfaces/srv/PlanRepositioning."""

    OK = 0
    UNKNOWN_OBJECT = 1
    INVALID_START = 2
    INVALID_GOAL = 3
    DIFFERENT_COMPONENTS = 4
    NO_PATH = 5
    BAD_REQUEST = 6
    NOT_READY = 7


@dataclass(frozen=True)
class SearchOptions:
    principal_finger: int = -1          # -1 = try both, keep the cheaper; 0; 1
    rotation_penalty: float = 0.01
    opening_change_penalty: float = 1.0
    pull_penalty: float = 1.0
    arm_collision_penalty: float = 0.05
    merge_tolerance: float = 0.0        # 0 = half the graph's seed resolution
    unpushable_penalty: float = 10.0
    pusher_tip_radius: float = field(default_factory=lambda: gripper_description().tip_radius)   # m, config/gripper.yaml
    pusher_clearance: float = 0.002     # m a fingertip needs all round beside the face it pushes

    def validate(self) -> None:
        if self.principal_finger not in (-1, 0, 1):
            raise ValueError(f"principal_finger must be -1, 0 or 1, not {self.principal_finger}")
        for name in (*PENALTIES, "merge_tolerance", "pusher_tip_radius", "pusher_clearance"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} = {value}: must be finite and >= 0")
