"""Fault monitors: what ends a run whatever step it is in (limits, a slip in the grip).

Each check is a pure function of the observation and what the executor believes; the executor
runs them every tick before its current step, and a fault ends the run with the object held.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import distance
from dmg_executor.belief import HeldPose
from dmg_executor.contract import Observation
from dmg_executor.settings import ExecutorSettings


def limit_violation(obs: Observation, holder_start: np.ndarray, s: ExecutorSettings) -> str | None:
    """Why a gripper is out of bounds (outside the workspace box, or gripper 1 moved more than
    `holder_travel` from where the run started), or None."""
    for name, pose in (("holding", obs.holder), ("pushing", obs.pusher)):
        where = pose[:3, 3]
        if np.any(where < s.limits.workspace_min) or np.any(where > s.limits.workspace_max):
            return (f"the {name} gripper at {np.round(where, 3).tolist()} m left the "
                    f"workspace {s.limits.workspace_min.tolist()} .. {s.limits.workspace_max.tolist()}")
    travel = float(np.linalg.norm(obs.holder[:3, 3] - holder_start[:3, 3]))
    if travel > s.limits.holder_travel:
        return f"the holding gripper moved {travel * 1000:.0f} mm from its start (limit {s.limits.holder_travel * 1000:.0f} mm)"
    return None


def turn_since(reference: np.ndarray, now: np.ndarray) -> np.ndarray:
    """Rotation vector (holder frame) the object has turned by from pose `reference` to `now`."""
    return Rotation.from_matrix(now[:3, :3] @ reference[:3, :3].T).as_rotvec()


def tilt_since(reference: np.ndarray, now: np.ndarray) -> float:
    """rad the object has turned about axes across the grasp axis (x) from `reference` to `now`."""
    return float(np.linalg.norm(turn_since(reference, now)[1:]))


def moved_in_grip(obs: Observation, held: HeldPose, s: ExecutorSettings) -> str | None:
    """How the object moved against the held reference, when this pose and the reference are both
    certain enough of their position to tell and it moved more than `slip_distance`/`slip_angle`; a turn
    counts only by a pose certain of its orientation too (sim, a generated bar: views after a blind push,
    1.0 mm and 2.3-2.6 deg sure of themselves, turned 6.4-6.6 deg from a still object's reference)."""
    if held.reference is None or max(obs.object_position_sigma, held.sigma) > s.slip.position_sigma:
        return None     # no evidence either way
    moved, turned = distance(held.reference, obs.object_in_holder)
    if obs.object_tilt_sigma > s.slip.tilt_sigma:
        turned = 0.0
    if moved <= s.slip.distance and turned <= s.slip.angle:
        return None
    return (f"the object moved {moved * 1000:.1f} mm and {np.rad2deg(turned):.1f} deg in the closed grip "
            f"(that pose's uncertainty {obs.object_position_sigma * 1000:.1f} mm, "
            f"{np.rad2deg(obs.object_tilt_sigma):.1f} deg)")


def tilted_while_pushed(obs: Observation, pushed_reference: np.ndarray, s: ExecutorSettings) -> str | None:
    """How far the pushed object tilted off the grasp axis since its push began, when that is more than
    `slip_angle` by a pose certain of its tilt (a lone tag seen obliquely is not)."""
    tilt = tilt_since(pushed_reference, obs.object_in_holder)
    if tilt <= s.slip.angle or obs.object_tilt_sigma > s.slip.tilt_sigma:
        return None
    return (f"the pushed object tilted {np.rad2deg(tilt):.1f} deg off the grasp axis (that pose's uncertainty "
            f"{np.rad2deg(obs.object_tilt_sigma):.1f} deg)")


def tilted_further_while_pressed(obs: Observation, began: float, now: float, s: ExecutorSettings) -> str | None:
    """How far a level press tilted the object further off the goal's grasp axis than the `began` [rad] it started
    at (`now` [rad] off it), when that is more than `slip_angle` by a pose certain of its tilt. A press turns the
    object back towards the goal's axis on purpose, by as much as the tilt it began with: only a tilt growing away
    from it is a slip."""
    if now - began <= s.slip.angle or obs.object_tilt_sigma > s.slip.tilt_sigma:
        return None
    return (f"the pressed object tilted {np.rad2deg(now - began):.1f} deg further off the goal's grasp axis (that "
            f"pose's uncertainty {np.rad2deg(obs.object_tilt_sigma):.1f} deg)")


def poses_agree(poses: list[np.ndarray], s: ExecutorSettings) -> bool:
    """Are these object poses each within the slip limits of the last?"""
    return all(moved <= s.slip.distance and turned <= s.slip.angle
               for moved, turned in (distance(pose, poses[-1]) for pose in poses[:-1]))


@dataclass
class SlipStreak:
    """Consecutive perceived poses that each showed a slip: `slip_poses` of them in a row are a slip,
    a single stray estimate (a lone tag's mirrored pose) is none."""

    poses: list[np.ndarray] = field(default_factory=list)
    pose_time: float = -math.inf

    def clear(self) -> None:
        self.poses = []

    def add(self, obs: Observation) -> int:
        """Count this tick's pose (once per image); how many in a row so far."""
        if obs.object_time != self.pose_time:
            self.pose_time = obs.object_time
            self.poses.append(obs.object_in_holder.copy())
        return len(self.poses)


@dataclass
class Persisting:
    """A condition that counts only once it has held for `window` seconds without a break (a robot's
    poses found too old: after this process itself stalls, the clock can jump ahead of pose messages
    still on their way, and the next ticks take them in)."""

    window: float
    since: float | None = None   # when it began to hold

    def holds(self, condition: bool, now: float) -> bool:
        """Take this tick's condition; has it now held for the whole window?"""
        if not condition:
            self.since = None
            return False
        if self.since is None:
            self.since = now
        return now - self.since >= self.window

    @property
    def began(self) -> bool:
        return self.since is not None
