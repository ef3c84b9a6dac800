"""Where the pusher's two round fingertips are, and where they meet the object (pure geometry).

The pusher's grasp frame sits between its fingertip centres; its x runs from one tip to the other.
A push is planned for the tip that meets the face first, so these functions place the grasp frame
such that that tip, not the frame's centre, is on the push line and `gap` from the face.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply, invert
from dmg_executor.push_points import ObjectSurface
from dmg_executor.settings import FingertipSettings

_AROUND = np.array([d for d in itertools.product((-1.0, 0.0, 1.0), repeat=3) if any(d)])
SHELL_DIRECTIONS = _AROUND / np.linalg.norm(_AROUND, axis=1, keepdims=True)   # 26 ways out of a fingertip's centre


def tip_ahead(facing: np.ndarray, orientation: np.ndarray, tip_radius: float, leading: float) -> np.ndarray:
    """The closed pusher's fingertip centre [m, from its grasp frame turned `orientation`] that is
    clearly ahead along `facing` (their axis within arccos(`leading`) of it); zero for tips side by
    side, where which one touches first is down to the arm's tracking."""
    ahead = float(facing @ orientation[:, 0])
    if abs(ahead) < leading:
        return np.zeros(3)
    return math.copysign(tip_radius, ahead) * orientation[:, 0]


def leading_tip(direction: np.ndarray, orientation: np.ndarray, tip_radius: float, leading: float) -> np.ndarray:
    """Where [m, across `direction`] the closed pusher's fingertip that meets a face square to the push
    first sits from its grasp frame (turned `orientation`): the tip ahead along `direction`, or zero
    (tip_ahead). A contact off the push line turns the sliding object (sim, bracket: a tip 1.8 mm
    off along the grasp axis, 2.3 deg of tilt over an 8 mm blind push; box: a tip 6.6 mm off across
    it, 26 deg about the grasp axis over a 3 mm push)."""
    tip = tip_ahead(direction, orientation, tip_radius, leading)
    return tip - (tip @ direction) * direction


def push_start(point: np.ndarray, normal: np.ndarray, direction: np.ndarray, orientation: np.ndarray,
               tip_radius: float, gap: float, tips: FingertipSettings, slant_limit: float,
               spread: float = 0.0) -> np.ndarray:
    """Where the pusher's grasp frame (turned `orientation`) starts a push along `direction` on `point`
    of a face with outward `normal`: the fingertip nearer the face, when clearly so (tip_ahead), on
    the line along `direction` on which it meets the face at `point`, and neither tip nearer than
    `gap` along that line to the face's plane. Set back from the push line alone, tips side by side
    on a face slanted to the push are not equally far from it (sim, box face slanted 41 deg: the
    other tip started 3 mm inside it, pressed 21 N into it against the closed grip, and the box
    jumped 2.3 mm / 2.1 deg the wrong way when the grip loosened). `spread`: the tips opened that far
    apart (a straddle push: side by side across it, the point half way between them). A face slanted more
    than `slant_limit` [rad] to the push is taken as slanted that much."""
    ahead = np.zeros(3) if spread else tip_ahead(-normal, orientation, tip_radius, tips.leading_tip)
    met = point + tip_radius * normal - ahead   # that tip touching `point`
    centres = met + tip_centres(orientation, tip_radius, spread)
    # How far each tip travels along `direction` before it touches the face's plane.
    slant = max(-float(direction @ normal), np.cos(slant_limit))
    travel = ((centres - point) @ normal - tip_radius) / slant
    return met - (gap - min(float(travel.min()), 0.0)) * direction


def fingertip_fronts(direction: np.ndarray, orientation: np.ndarray, tip_radius: float, tips: FingertipSettings,
                     spread: float = 0.0) -> np.ndarray:
    """Points (n, 3; from the pusher's grasp frame turned `orientation`, its tips `spread` apart or closed) on
    both fingertips' spheres facing the push `direction`: the front and rims `tips.rims` off it, every `tips.rim_turn_step` round.
    The first of them to meet the object along the push is where a tip meets it."""
    side = np.cross(direction, orientation[:, 0] if abs(float(direction @ orientation[:, 0])) < 0.9 else orientation[:, 1])
    side /= np.linalg.norm(side)
    other = np.cross(direction, side)
    tilt, turn = np.meshgrid(tips.rims, np.arange(0.0, 2 * np.pi, tips.rim_turn_step))
    facing = (np.cos(tilt).reshape(-1, 1) * direction
              + np.sin(tilt).reshape(-1, 1) * (np.cos(turn).reshape(-1, 1) * side + np.sin(turn).reshape(-1, 1) * other))
    return (tip_centres(orientation, tip_radius, spread)[:, None, :] + tip_radius * facing[None]).reshape(-1, 3)


def fingertip_shells(orientation: np.ndarray, tip_radius: float, clearance: float, spread: float = 0.0) -> np.ndarray:
    """Points (n, 3; from the pusher's grasp frame turned `orientation`, its tips `spread` apart or closed)
    `clearance` out from both fingertips' spheres, all round them: where a push starts, none may be
    inside the object."""
    out = (tip_radius + clearance) * SHELL_DIRECTIONS
    return (tip_centres(orientation, tip_radius, spread)[:, None, :] + out[None]).reshape(-1, 3)


def sweep_to_touch(surface: ObjectSurface, object_pose: np.ndarray, pusher: np.ndarray, holder: np.ndarray,
                   direction: np.ndarray, tip_radius: float, limit: float, tips: FingertipSettings) -> float:
    """How far [rad] the closed pusher (pose `pusher`, base frame) turns about the grasp axis (x of `holder`)
    the way that moves it along the push `direction` (in steps of `tips.sweep_step`) before a fingertip comes
    within `tips.sweep_reach` of the
    object at `object_pose`; inf if not within `limit`. A rotation's pusher sweeps: where its tips lie
    beside the grasp axis rather than across the push line from it, the sweep runs along the face more
    than into it."""
    axis, origin = holder[:3, 0], holder[:3, 3]
    centres = pusher[:3, 3] + tip_centres(pusher[:3, :3], tip_radius)
    sense = 1.0 if float(np.cross(axis, centres.mean(axis=0) - origin) @ direction) >= 0.0 else -1.0
    angles = np.arange(0.0, limit + tips.sweep_step / 2, tips.sweep_step)
    turns = Rotation.from_rotvec(sense * angles[:, None] * axis).as_matrix()          # (k, 3, 3)
    swept = np.einsum("kij,nj->kni", turns, centres - origin) + origin                    # (k, 2, 3)
    near = surface.distance(apply(invert(object_pose), swept.reshape(-1, 3))).reshape(len(angles), -1).min(axis=1)
    touching = np.flatnonzero(near <= tip_radius + tips.sweep_reach)
    return float(angles[touching[0]]) if len(touching) else float("inf")


def tip_centres(orientation: np.ndarray, tip_radius: float, spread: float = 0.0) -> np.ndarray:
    """The pusher's two fingertip centres (2, 3; from its grasp frame turned `orientation`): side by side
    along its x, `spread` apart, or touching (closed)."""
    return max(tip_radius, spread / 2) * np.outer([1.0, -1.0], orientation[:, 0])


def meeting_start(start: np.ndarray, orientation: np.ndarray, direction: np.ndarray, object_pose: np.ndarray,
                  surface: ObjectSurface, tip_radius: float, gap: float, tips: FingertipSettings,
                  spread: float = 0.0) -> np.ndarray:
    """`start` (base frame) moved along the push `direction` until the fingertip that meets the
    object (at `object_pose`) first - rays from the tips' fronts onto its mesh - is `gap` from it.
    `push_start` sets back by the face's plane: a tip whose line passes beside the face never meets
    it (sim, plug: the push line 4-6 mm above a face's edge, tips side by side across it - the other
    tip started 12-14 mm away, and blind pushes counted from `gap` ended 6-8 mm short, three in a row)."""
    inverse = invert(object_pose)
    meet = surface.travel(apply(inverse, start + fingertip_fronts(direction, orientation, tip_radius, tips, spread)),
                          inverse[:3, :3] @ direction)
    return start if not np.isfinite(meet) else start + (meet - gap) * direction
