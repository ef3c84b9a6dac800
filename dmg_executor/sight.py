"""What the pusher's wrist camera can see: the pusher orientations at a place ranked by the object's tags
they show, and whether the pusher's hand would be in the holding gripper there."""
from __future__ import annotations

import numpy as np

from dmg_common.transforms import turn_between
from dmg_executor.contract import Observation
from dmg_executor.push_points import ObjectSurface
from dmg_executor.routes import RouteError
from dmg_executor.settings import ExecutorSettings
from dmg_executor.views import CameraModel, GripperShape, Occluders, TagLayout, overlap, placed, ranked_views, turns


def distinct(orientations: np.ndarray, chosen: np.ndarray, count: int, apart: float) -> list[np.ndarray]:
    """Up to `count` of `orientations` (best first), each at least `apart` [rad] from `chosen` and the others taken."""
    taken = [chosen]
    for orientation in orientations:
        if len(taken) > count:
            break
        if all(turn_between(orientation, other) >= apart for other in taken):
            taken.append(orientation)
    return taken[1:]


class Sight:
    """The view model of one run: the camera and the object's tags (without them, no view is ranked)."""

    def __init__(self, settings: ExecutorSettings, surface: ObjectSurface, camera: CameraModel | None,
                 tags: TagLayout | None):
        self.settings, self.surface, self.camera, self.tags = settings, surface, camera, tags
        self.turns = (turns(settings.views.tilt_limit, settings.views.roll_limit, settings.views.grid_step)
                      if camera is not None and tags is not None else None)
        self.shape = GripperShape(settings.gripper.finger_length, settings.gripper.tip_radius, settings.gripper.hand_start, settings.gripper.hand_end,
                                  settings.gripper.hand_radius)
        self.neutral = np.eye(3)      # the pusher's orientation where it started, once known

    @property
    def modelled(self) -> bool:
        """Can views be told apart by the tags they see?"""
        return self.turns is not None

    def occluders(self, obs: Observation) -> Occluders:
        return Occluders.of(self.shape, obs.holder, obs.opening)

    def views(self, obs: Observation, place: np.ndarray, level: np.ndarray | None = None,
              occluders: Occluders | None = None, in_line: np.ndarray | None = None,
              neutral: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Pusher orientations at `place` (turned from `neutral`, by default the orientation it
        started in), best view of the object's tags first, and how many tags each sees (without a
        camera model: only `neutral`, seeing none). `occluders` also checks what hides tags (10x the
        time): for push starts, where a push waits for a fresh pose; on the way there the held
        object may go unseen a while."""
        neutral = self.neutral if neutral is None else neutral
        if self.turns is None:
            return neutral[None], np.zeros(1, int)
        scene = self.surface.scene if occluders is not None else None
        return ranked_views(self.camera, self.tags, obs.holder @ obs.object_in_holder, place, neutral, self.turns,
                            self.settings.views, level, occluders, scene, in_line)

    def look_views(self, obs: Observation, place: np.ndarray, neutral: np.ndarray) -> list[np.ndarray]:
        """The best pusher orientation at `place` (turned from `neutral`) and the distinct others a tag is
        seen from, best first (the best is tried even if the model sees no tag from it)."""
        views, seen = self.views(obs, place, occluders=self.occluders(obs), neutral=neutral)
        rules = self.settings.approach
        return [views[0]] + distinct(views[1:][seen[1:] > 0], views[0], rules.other_views, rules.distinct_view)

    def hands_clash(self, place: np.ndarray, orientation: np.ndarray, occluders: Occluders,
                    between_fingers: bool = False) -> bool:
        """Would the pusher with its tips at `place`, turned `orientation`, have its hand in the holding
        gripper or its fingers in that gripper's hand? (The arms do not collide in the simulation;
        they would on the robot.) Fingers near fingers are the keep-out box's business, and so are
        fingers `between_fingers` of the holding gripper, kept short of its palm where that push is
        planned (the hand's spheres, round where the hand is flat, reach in front of the palm on its axis)."""
        pusher = np.eye(4)
        pusher[:3, :3], pusher[:3, 3] = orientation, place
        return (overlap(placed(self.shape.hand(), pusher), occluders.fixed)
                or (not between_fingers and overlap(placed(occluders.riding, pusher), occluders.hand)))

    def sideways_views(self, obs: Observation, place: np.ndarray, fingers_along: np.ndarray, tips_along: np.ndarray,
                       fingers_limit: float, twist_limit: float, occluders: Occluders,
                       refusal: str) -> tuple[np.ndarray, np.ndarray]:
        """The pusher orientations (best view first) at `place` (base frame) for a push it comes in to along its
        own fingers: those along `fingers_along` (either way, within `fingers_limit` [rad]), the tips side by
        side along `tips_along` - rolled about the fingers from the nearest views the arm can take
        (`twist_limit` [rad] at most) onto exactly that line (RouteError saying `refusal` if none)."""
        views, seen = self.views(obs, place, occluders=occluders)
        keep = ((np.abs(views[:, :, 0] @ tips_along) > np.cos(twist_limit))
                & (np.abs(views[:, :, 2] @ fingers_along) > np.cos(fingers_limit)))
        if not keep.any():
            raise RouteError(f"no pusher orientation its arm can take {refusal}")
        views, seen = views[keep], seen[keep]
        fingers = views[:, :, 2]
        tips = tips_along - (fingers @ tips_along)[:, None] * fingers
        tips *= np.sign(views[:, :, 0] @ tips_along)[:, None] / np.linalg.norm(tips, axis=1, keepdims=True)
        return np.stack([tips, np.cross(fingers, tips), fingers], axis=2), seen

    def straddling_views(self, obs: Observation, place: np.ndarray, direction: np.ndarray,
                         occluders: Occluders) -> tuple[np.ndarray, np.ndarray]:
        """Orientations whose fingertips, opened, straddle gripper 1's fingers for a push along `direction`
        (base frame): the fingers along the grasp axis, the tips spread across it and the push."""
        grasp_axis = obs.holder[:3, 0]
        spread = np.cross(direction, grasp_axis)
        rules = self.settings.straddle
        return self.sideways_views(obs, place, grasp_axis, spread / np.linalg.norm(spread), rules.fingers, rules.twist,
                                   occluders, "puts its fingers along gripper 1's grasp axis with the tips either "
                                   "side of gripper 1's fingers")

    def between_views(self, obs: Observation, place: np.ndarray, direction: np.ndarray, tips_in_line: bool,
                      occluders: Occluders) -> tuple[np.ndarray, np.ndarray]:
        """Orientations whose closed fingertips come in between gripper 1's fingers for a push along
        `direction` (base frame): the fingers across both the grasp axis and the push, the tips side by
        side along the grasp axis, or one behind the other along the push (`tips_in_line`)."""
        grasp_axis = obs.holder[:3, 0]
        across = np.cross(direction, grasp_axis)
        rules = self.settings.between
        return self.sideways_views(obs, place, across / np.linalg.norm(across), direction if tips_in_line else grasp_axis,
                                   rules.fingers, rules.twist, occluders, "puts its fingers across gripper 1's grasp "
                                   "axis with the closed tips between gripper 1's fingers")
