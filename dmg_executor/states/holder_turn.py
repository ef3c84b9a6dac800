"""The holding gripper turning the object about its finger axis (to show the pusher the far side, or back
to where the camera sees the object's tags), or going back to where it started, once the pusher is clear."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import distance
from dmg_executor.contract import Command, Observation, Outcome, Step
from dmg_executor.motion import limited
from dmg_executor.routes import RouteError
from dmg_executor.run import Run
from dmg_executor.states import find_contact
from dmg_executor.states.base import State, Transition


@dataclass
class HolderMove:
    """What the holder is to do once the pusher is clear."""

    angle: float                      # rad to turn about the holder's z (its finger axis)
    back: bool                        # turning back to where the camera sees the object's tags
    home: np.ndarray | None = None    # instead of turning: back to this pose (where the holder started)


def start_holder_turn(run: Run, obs: Observation, back: bool, home: np.ndarray | None = None,
                      angle: float | None = None) -> Command | Transition:
    """The pusher back to where it started, then the holder turns the object: `holder_turn` to show
    the pusher the far side, or back after the push there; or, given `home`, the holder goes there."""
    turns, campaign = run.holder_turns, run.campaign
    if home is not None:
        angle = 0.0
    elif back:
        angle = -turns.turned_by
    else:
        angle = run.settings.holder.turn if angle is None else angle
        turns.turned_by = angle
    move = HolderMove(angle, back, None if home is None else home.copy())
    turns.far_side_pushed = turns.pressed_turned = False
    try:
        run.head_home(obs, clear_of_turn=True)
    except RouteError as error:
        if back:
            return run.abort(Outcome.LIMIT_VIOLATION, f"cannot clear the pusher from the object before the "
                             f"holding gripper turns it back: {error}")
        return forgo(run, move, f"no route takes the pusher out of its reach ({error})")
    if home is not None:
        offset, turned = distance(run.holder_start, obs.holder)
        run.note(f"primitive {campaign.index}: the holding gripper went back to where it started (it had "
                 f"moved {offset * 1000:.0f} mm and turned {np.rad2deg(turned):.0f} deg in the pushes) "
                 "for a push it could not be given where it was")
    elif not back:
        what = ("a level press" if campaign.leveling else "a push on its far side" if abs(angle) > np.pi / 2 + 0.1
                else "a push from its side")
        run.note(f"primitive {campaign.index}: the holding gripper turned the object "
                 f"{np.rad2deg(angle):.0f} deg about its fingers for {what}")
    return Transition(ClearForTurn(move))


def forgo(run: Run, move: HolderMove, why: str) -> Transition:
    """Nothing turned yet: the holder's turn (or its way back to where it started) is given up like a push
    the pusher cannot get to, and not tried again; the run goes on without it."""
    run.note(f"the holding gripper did not {'go back' if move.home is not None else 'turn the object'}: {why}")
    if move.home is not None:
        run.holder_turns.may_return = False
    else:
        run.holder_turns.may_turn = False
    return Transition(find_contact.FindContact())


class ClearForTurn(State):
    """The pusher on its way out of reach of the object the holder is about to move."""

    step = Step.FIND_CONTACT
    turns_holder = True

    def __init__(self, move: HolderMove):
        self.move = move

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        pilot = run.pilot
        stalled = pilot.stalled(obs)
        if not (pilot.arrived(obs) or stalled):
            return pilot.along(obs)
        if not stalled and pilot.route.on_the_way:
            pilot.route.index += 1
            return Command()
        if not run.clear_of_turn(obs, obs.pusher[:3, 3]):
            if self.move.back:
                return run.abort(Outcome.LIMIT_VIOLATION, "the pusher cannot get out of reach of the object "
                                 "the holding gripper must turn back")
            return forgo(run, self.move, "the pusher could not get out of its reach")
        # The grip is closed: the object stays where it was seen; the next reference is the first
        # image after the turn back.
        run.held.await_fresh()
        run.reckoned, run.reckoned_time = obs.object_in_holder.copy(), math.inf
        move = self.move
        return Transition.handover(HolderHome(move.home, obs) if move.home is not None
                                   else TurnHolder(move.angle, move.back, obs))


class TurnHolder(State):
    """Turn the holder about its finger axis at a P-controlled rate, keeping its grasp frame in place. A
    turn that stops gaining (the wrist at its limit) goes back."""

    step = Step.FIND_CONTACT
    turns_holder = True

    def __init__(self, angle: float, back: bool, obs: Observation):
        self.angle, self.back = angle, back
        self.turned = 0.0       # rad so far (summed tick by tick: a half turn has no unique rotation vector)
        self.last = obs.holder[:3, :3].copy()     # holder orientation at the previous tick
        self.place = obs.holder[:3, 3].copy()     # where the grasp frame stays while it turns
        self.progress = (0.0, obs.time)           # (turned, when) at the last headway

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        s = run.settings
        current = obs.holder[:3, :3]
        self.turned += float(Rotation.from_matrix(self.last.T @ current).as_rotvec()[2])
        self.last = current.copy()
        left = self.angle - self.turned
        if abs(left) < s.approach.waypoint_turn_tolerance:
            run.holder_turns.far_side, run.reckoned_time = not self.back, obs.time
            return Transition(find_contact.FindContact())
        if abs(self.turned - self.progress[0]) > s.approach.headway_turn:
            self.progress = (self.turned, obs.time)
        drift = float(np.linalg.norm(obs.holder[:3, 3] - self.place))
        if obs.time - self.progress[1] > s.approach.stall_time or drift > s.monitors.turn_drift:
            why = (f"moved {drift * 1000:.0f} mm" if drift > s.monitors.turn_drift
                   else f"stopped at {np.rad2deg(self.turned):.0f} deg")
            if self.back:
                return run.abort(Outcome.LIMIT_VIOLATION, f"the holding gripper could not turn the object back ({why})")
            run.note(f"the holding gripper could not turn the object ({why}): turned back, not turned again")
            run.holder_turns.may_turn = False
            self.angle, self.back, self.progress, self.place = 0.0, True, (self.turned, obs.time), obs.holder[:3, 3].copy()
            return Command()
        rate = float(np.clip(s.approach.gain * left, -s.limits.angular_speed, s.limits.angular_speed))
        return Command(holder=np.concatenate([s.approach.gain * (self.place - obs.holder[:3, 3]), rate * current[:, 2]]))


class HolderHome(State):
    """The holder (the grip closed, the pusher clear) back to where it started at a P-controlled speed; one
    that stops gaining (an arm at a limit) stays where it got to."""

    step = Step.FIND_CONTACT
    turns_holder = True

    def __init__(self, home: np.ndarray, obs: Observation):
        self.home = home
        self.progress = (math.inf, obs.time)      # (distance left, when) at the last headway

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        s = run.settings
        offset = self.home[:3, 3] - obs.holder[:3, 3]
        rotation = Rotation.from_matrix(self.home[:3, :3] @ obs.holder[:3, :3].T).as_rotvec()
        distance_left, angle_left = float(np.linalg.norm(offset)), float(np.linalg.norm(rotation))
        if distance_left < s.approach.waypoint_tolerance and angle_left < s.approach.waypoint_turn_tolerance:
            run.reckoned_time = obs.time
            return Transition(find_contact.FindContact())
        headway = s.approach
        left = distance_left + angle_left * headway.headway_distance / headway.headway_turn     # headway in either counts
        if left < self.progress[0] - headway.headway_distance:
            self.progress = (left, obs.time)
        if obs.time - self.progress[1] > s.approach.stall_time:
            run.note(f"the holding gripper stopped {distance_left * 1000:.0f} mm and "
                     f"{np.rad2deg(angle_left):.0f} deg short of where it started")
            run.holder_turns.may_return, run.reckoned_time = False, obs.time
            return Transition(find_contact.FindContact())
        return Command(holder=np.concatenate([limited(s.approach.gain * offset, s.approach.speed),
                                              limited(s.approach.gain * rotation, s.limits.angular_speed)]))

