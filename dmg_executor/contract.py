"""The executor's contract: what it is fed each control tick, what it answers, how a run ends.

`PlanExecutor.update(Observation) -> Command`; `progress` and `result` report on it. The node, the
in-process closed loop (`dmg eval`) and the tests all speak these types; the enums carry the numbers
of dmg_interfaces/action/ExecuteRepositioning's constants, so the node only copies them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np


class Step(IntEnum):
    """Same values as the feedback steps of dmg_interfaces/action/ExecuteRepositioning."""

    FIND_CONTACT = 0
    APPROACH = 1
    EXECUTE = 2
    LEAVE = 3


class Outcome(IntEnum):
    """Same values as the result codes of dmg_interfaces/action/ExecuteRepositioning."""

    OK = 0
    BAD_REQUEST = 1
    PLANNING_FAILED = 2
    OBJECT_LOST = 3
    SLIP = 4
    STEP_TIMEOUT = 5
    CANCELED = 6
    LIMIT_VIOLATION = 7
    OUT_OF_TOLERANCE = 8
    ROBOT_LOST = 9
    INTERNAL_ERROR = 10


@dataclass
class Observation:
    """What the executor knows at one control tick (base frame unless said otherwise)."""

    time: float                              # s, the controller's clock
    holder: np.ndarray                       # 4x4 holding gripper's grasp frame
    pusher: np.ndarray                       # 4x4 pushing gripper's grasp frame
    object_in_holder: np.ndarray | None      # 4x4 latest perceived object pose in the holder's frame
    object_time: float                       # s, when that pose was seen (-inf: never)
    opening: float                           # m between the holder's fingertips
    object_covariance: np.ndarray | None = None   # 6x6 of that pose (holder frame; None: taken as certain)

    @property
    def object_tilt_sigma(self) -> float:
        """rad, the object pose's standard deviation of turn off the grasp axis."""
        return 0.0 if self.object_covariance is None else tilt_sigma(self.object_covariance)

    @property
    def object_position_sigma(self) -> float:
        """m, the object pose's standard deviation of position along its least certain direction."""
        return 0.0 if self.object_covariance is None else position_sigma(self.object_covariance)


@dataclass
class GripCommand:
    opening: float      # m
    max_force: float    # N per finger


@dataclass
class Command:
    holder: np.ndarray = field(default_factory=lambda: np.zeros(6))   # twist (linear, angular) of the holder's grasp frame
    pusher: np.ndarray = field(default_factory=lambda: np.zeros(6))
    holder_grip: GripCommand | None = None
    pusher_grip: GripCommand | None = None


@dataclass
class Progress:
    primitive_index: int
    primitive_count: int
    step: Step
    contact_error: float     # m, remaining principal contact displacement of the current primitive
    angle_error: float       # rad, remaining angle about the grasp axis
    pushes: int              # pushes done on the current primitive
    contact: np.ndarray      # m, perceived principal contact in the object frame (NaN before a pose)


@dataclass
class Result:
    outcome: Outcome
    message: str
    primitives_completed: int
    position_error: float    # m, principal contact vs the goal contact (nan if never seen)
    angle_error: float       # rad, gripper orientation vs the goal's
    duration: float          # s


def _largest_sigma(covariance: np.ndarray, axes: slice) -> float:
    """The larger standard deviation of a pose over some of its 6x6 covariance's axes (x, y, z,
    rotation about x, y, z), correlations included; inf if that block is not finite."""
    block = np.asarray(covariance, float).reshape(6, 6)[axes, axes]
    if not np.all(np.isfinite(block)):
        return math.inf
    return float(np.sqrt(max(float(np.linalg.eigvalsh(block)[-1]), 0.0)))


def tilt_sigma(covariance: np.ndarray) -> float:
    """rad: how uncertain a pose (holder frame) is in its turn off the grasp axis x (rotation about y, z)."""
    return _largest_sigma(covariance, slice(4, 6))


def position_sigma(covariance: np.ndarray) -> float:
    """m: how uncertain a pose is in its position, along its least certain direction."""
    return _largest_sigma(covariance, slice(0, 3))
