"""From a contact path to in-hand manipulation primitives (paper section IV-C).

A path is a sequence of (contact point, finger angle) states in which each step either
moves the contact (translation) or turns the finger (rotation). Consecutive rotation steps
become one rotation; consecutive translation steps are merged into one straight
translation as long as every contact they pass lies within `tolerance` of the straight
line (so the merged motion stays on the supervoxels the search chose); zero rotations are
dropped.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class PrimitiveKind(IntEnum):
    ROTATION = 0      # same values as dmg_interfaces/msg/ManipulationPrimitive
    TRANSLATION = 1


@dataclass
class Primitive:
    kind: PrimitiveKind
    angle: float                 # signed rotation [rad] about the outward normal (ROTATION)
    translation: np.ndarray      # principal contact displacement [m] (TRANSLATION)
    contact_before: np.ndarray
    contact_after: np.ndarray
    angle_before: float          # principal finger angle [rad] in the contact's tangent frame
    angle_after: float
    secondary_before: np.ndarray
    secondary_after: np.ndarray
    gripper_after: np.ndarray | None = None   # 4x4 gripper pose in the object frame after it (set by the search)

    @property
    def opening_before(self) -> float:
        return float(np.linalg.norm(self.secondary_before - self.contact_before))

    @property
    def opening_after(self) -> float:
        return float(np.linalg.norm(self.secondary_after - self.contact_after))


def wrap_angle(angle: float) -> float:
    """Angle in (-pi, pi]."""
    return float(-np.mod(-angle + np.pi, 2 * np.pi) + np.pi)


def _straight_runs(points: np.ndarray, tolerance: float) -> list[int]:
    """Indices where the merged straight translations of a polyline start and end.

    From each start the farthest end whose chord keeps all points between within
    `tolerance` is taken (farthest first, so a path that zigzags around a straight line
    becomes that one line).
    """
    breaks = [0]
    start = 0
    while start < len(points) - 1:
        end = next(j for j in range(len(points) - 1, start, -1) if _within(points[start:j + 1], tolerance))
        breaks.append(end)
        start = end
    return breaks


def _within(points: np.ndarray, tolerance: float) -> bool:
    """Do the inner points lie within `tolerance` of the segment from the first to the last?"""
    a, b = points[0], points[-1]
    ab = b - a
    length2 = float(ab @ ab)
    if length2 == 0.0:
        return bool(np.all(np.linalg.norm(points - a, axis=1) <= tolerance))
    s = np.clip((points[1:-1] - a) @ ab / length2, 0.0, 1.0)
    distance = np.linalg.norm(points[1:-1] - (a + s[:, None] * ab), axis=1)
    return bool(np.all(distance <= tolerance))


def primitives_from_path(contacts: np.ndarray, secondaries: np.ndarray, angles: np.ndarray,
                         goal_angle: float, tolerance: float) -> list[Primitive]:
    """Primitives along a state path; the last rotation ends exactly at `goal_angle`.

    contacts/secondaries: (K, 3) per state; angles: (K,) principal finger angle per state.
    Between consecutive states either the contact or the angle changes (or nothing).
    """
    primitives: list[Primitive] = []
    index = 0
    count = len(contacts)
    while index < count - 1:
        moves = np.linalg.norm(contacts[index + 1] - contacts[index]) > 1e-12
        end = index + 1
        if moves:
            while end + 1 < count and np.linalg.norm(contacts[end + 1] - contacts[end]) > 1e-12:
                end += 1
            breaks = _straight_runs(contacts[index:end + 1], tolerance)
            for a, b in zip(breaks[:-1], breaks[1:]):
                i, j = index + a, index + b
                primitives.append(Primitive(PrimitiveKind.TRANSLATION, 0.0, contacts[j] - contacts[i],
                                            contacts[i], contacts[j], float(angles[i]), float(angles[j]),
                                            secondaries[i], secondaries[j]))
        else:
            while end + 1 < count and np.linalg.norm(contacts[end + 1] - contacts[end]) <= 1e-12:
                end += 1
            turn = sum(wrap_angle(angles[k + 1] - angles[k]) for k in range(index, end))
            _append_rotation(primitives, turn, contacts[index], float(angles[index]), secondaries[index])
        index = end
    final_angle = primitives[-1].angle_after if primitives else float(angles[0])
    _append_rotation(primitives, wrap_angle(goal_angle - final_angle), contacts[-1], final_angle, secondaries[-1])
    return primitives


def _append_rotation(primitives: list[Primitive], turn: float, contact: np.ndarray, angle: float,
                     secondary: np.ndarray) -> None:
    """Add a rotation (merged into a preceding rotation; dropped when it sums to zero)."""
    if primitives and primitives[-1].kind == PrimitiveKind.ROTATION:
        previous = primitives.pop()
        turn = previous.angle + turn
        angle = previous.angle_before
    if abs(turn) < 1e-9:
        return
    primitives.append(Primitive(PrimitiveKind.ROTATION, turn, np.zeros(3), contact, contact, angle,
                                float(np.mod(angle + turn, 2 * np.pi)), secondary, secondary))
