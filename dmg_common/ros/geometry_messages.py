"""geometry_msgs and builtin_interfaces <-> numpy, shared by the nodes (no tf2 here)."""
from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose

from dmg_common.transforms import homogeneous, position_quaternion

QUATERNION_TOLERANCE = 1e-3


def pose_message(transform: np.ndarray) -> Pose:
    position, (x, y, z, w) = position_quaternion(transform)
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in position)
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = float(x), float(y), float(z), float(w)
    return pose


def transform_from_pose(pose: Pose, what: str = "pose") -> np.ndarray:
    """4x4 transform of a Pose; ValueError naming `what` for non-finite values or a non-unit quaternion."""
    p, q = pose.position, pose.orientation
    values = [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what} has non-finite values: {values}")
    norm = math.sqrt(q.x**2 + q.y**2 + q.z**2 + q.w**2)
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        raise ValueError(f"{what} orientation is not a unit quaternion (norm {norm:.6f})")
    return homogeneous(values[:3], values[3:])


def time_message(seconds: float) -> Time:
    nanoseconds = int(round(seconds * 1e9))
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def seconds(stamp: Time) -> float:
    return stamp.sec + stamp.nanosec * 1e-9
