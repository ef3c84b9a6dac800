"""Rigid transforms as 4x4 homogeneous matrices, shared by the sim, perception and executor.

Quaternions are (x, y, z, w), as in geometry_msgs and scipy.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def homogeneous(position, quaternion_xyzw) -> np.ndarray:
    """4x4 transform from a position and an (x, y, z, w) quaternion (normalised here)."""
    transform = np.eye(4)
    transform[:3, :3] = Rotation.from_quat(quaternion_xyzw).as_matrix()
    transform[:3, 3] = position
    return transform


def from_rotation(rotation: np.ndarray, position) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3] = rotation
    transform[:3, 3] = position
    return transform


def position_quaternion(transform: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position, (x, y, z, w) quaternion) of a 4x4 transform."""
    return transform[:3, 3].copy(), Rotation.from_matrix(transform[:3, :3]).as_quat()


def apply(transform: np.ndarray, points) -> np.ndarray:
    """Points (3,) or (n, 3) mapped by a 4x4 transform."""
    return np.asarray(points, float) @ transform[:3, :3].T + transform[:3, 3]


def invert(transform: np.ndarray) -> np.ndarray:
    inverse = np.eye(4)
    inverse[:3, :3] = transform[:3, :3].T
    inverse[:3, 3] = -transform[:3, :3].T @ transform[:3, 3]
    return inverse


def distance(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(translation distance [m], rotation angle [rad]) between two transforms."""
    relative = invert(a) @ b
    return float(np.linalg.norm(relative[:3, 3])), turn_between(a[:3, :3], b[:3, :3])


def turn_between(a: np.ndarray, b: np.ndarray) -> float:
    """Angle [rad] of the turn from orientation `b` to orientation `a` (3x3 rotation matrices)."""
    return float(Rotation.from_matrix(a @ b.T).magnitude())
