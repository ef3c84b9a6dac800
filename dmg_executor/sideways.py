"""Pushes the pusher comes in to along its own fingers, across the push, and leaves the same way: a
straddle push (its tips opened either side of gripper 1's fingers) and a push between gripper 1's
fingers (its closed tips in the room between them), both on the object's palm side to move it out of
the grip towards gripper 1's fingertips."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from dmg_common.transforms import apply
from dmg_executor.contract import Observation
from dmg_executor.fingertips import fingertip_shells
from dmg_executor.push_points import PushError, PushPoint, straddle_push
from dmg_executor.routes import KeepOut, RouteError
from dmg_executor.run import Run
from dmg_planner.primitives import PrimitiveKind


def straddle_point(run: Run, holder_in_object: np.ndarray) -> PushPoint:
    """The push that moves the object out along gripper 1's fingers: on its palm side, the pusher's tips
    open either side of those fingers (`straddle_push`), on a face the pusher's fingers reach beside them
    without meeting gripper 1's palm."""
    s = run.settings
    middle, rotation = holder_in_object[:3, 3], holder_in_object[:3, :3]
    halves = 2 * s.gripper.tip_radius + s.straddle.margins
    halves = halves[2 * halves - 2 * s.gripper.tip_radius <= s.straddle.opening + 1e-9]
    if not len(halves):
        widest = 2 * (s.gripper.tip_radius + s.straddle.margins[0])
        raise PushError(f"a straddle push needs the pusher open {widest * 1000:.0f} mm "
                        f"(straddle_opening {s.straddle.opening * 1000:.0f} mm)")
    push = straddle_push(run.surface, middle, rotation[:, 2], rotation[:, 1], halves, s.straddle.twist,
                         s.push.translation_slant)
    depth = -float((push.point - middle) @ rotation[:, 2])     # towards the palm from the grasp's middle
    room = s.gripper.finger_length - 2 * s.gripper.tip_radius - s.push.gap - s.approach.clearance   # (its finger beside the tip, radius tip_radius)
    if depth > room:
        raise PushError(f"the straddle push's face is {depth * 1000:.0f} mm towards gripper 1's palm (the pusher's "
                        f"fingers fit up to {room * 1000:.0f} mm)")
    return push


def between_fingers(run: Run, obs: Observation, push: PushPoint, point_h: np.ndarray) -> tuple[PushPoint, bool]:
    """A push whose line meets the object from gripper 1's palm side, made between gripper 1's fingers: the
    pusher's closed tips come in across those fingers along its own (`point_h`: the push point, holder
    frame), side by side along the grasp axis where both fit between the fingers, else one behind the other
    along the push (then they need a tip's width more room towards the palm). Translations only: the pusher
    neither turns about the grasp axis nor slides along it there. The push, and whether its tips lie along
    it. RouteError where `between.enabled` is off or the tips fit neither between the fingers nor short of
    the palm."""
    s = run.settings
    refusal = (f"the push at {np.round(point_h * 1000, 1).tolist()} mm (holder frame) comes along the holding "
               "gripper's hand from its palm side")
    if (not s.between.enabled or run.campaign.leveling
            or run.campaign.primitive.kind != PrimitiveKind.TRANSLATION):
        raise RouteError(refusal)
    tip = s.gripper.tip_radius
    free = obs.opening / 2 - abs(float(point_h[0])) - s.fingertips.tip_clearance   # from the push line to a finger
    if free < tip:
        raise RouteError(f"{refusal}, and a fingertip of the pusher ({2 * tip * 1000:.0f} mm) does not fit between "
                         f"its fingers ({obs.opening * 1000:.0f} mm apart)")
    in_line = free < 2 * tip
    room = s.gripper.finger_length - 2 * tip * (1 + in_line) - s.push.gap - s.approach.clearance
    if -float(point_h[2]) > room:
        raise RouteError(f"{refusal}, {-point_h[2] * 1000:.0f} mm towards its palm (the pusher's tips fit "
                         f"between its fingers up to {room * 1000:.0f} mm)")
    return replace(push, sideways=True), bool(in_line)


def sideways_entry(run: Run, start_h: np.ndarray, orientation_h: np.ndarray, spread: float, box: KeepOut,
                    object_in_holder_inverse: np.ndarray) -> np.ndarray:
    """Where (holder frame) a sideways push's last stretch begins: out of the kept-free space along the
    pusher's fingers from its start, so that its tips (`spread` apart, 0 closed) come in either side of or
    between gripper 1's fingers, clear of the object all the way (RouteError if not)."""
    s = run.settings
    fingers = orientation_h[:, 2]
    length = box.exit_distance(start_h, -fingers) + s.approach.exit_margin
    shells = fingertip_shells(orientation_h, s.gripper.tip_radius, s.fingertips.tip_clearance, spread)
    along = start_h - np.linspace(0.0, length, 12)[:, None] * fingers
    if run.surface.inside(apply(object_in_holder_inverse, (along[:, None, :] + shells[None]).reshape(-1, 3))).any():
        raise RouteError(f"the pusher's fingertips would meet the object on their way in along its fingers to "
                         f"{np.round(start_h * 1000, 1).tolist()} mm (holder frame)")
    return start_h - length * fingers
