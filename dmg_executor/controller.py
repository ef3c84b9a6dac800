"""Executing a repositioning plan with two grippers, closed loop on the perceived object pose.

Paper section V. Gripper 1 (the holder) holds the object, gripper 2 (the pusher) pushes it.
Every primitive is done in one or more pushes, each an explicit sequence of steps:

  FIND_CONTACT  nothing moves; from the perceived pose, the push point on the object mesh
                (push_points) and a collision-free route to it (routes) are computed.
  APPROACH      the pusher follows the route to `gap` in front of the push point.
  EXECUTE       the holder's fingers loosen (P control of the finger distance), the relative
                motion pushes the object - a translation v = -m t' with m from a P controller
                on the remaining contact displacement, or a rotation about the grasp axis at
                a P-controlled rate, the pusher following the object on its arc - split
                between the arms by the ECTS coordination alpha; then the grip tightens.
                While pushing, the object pose is the last seen one moved on by the
                pusher's motion since its image (reckoning): a push the camera cannot
                watch goes on blind and the next pose checks it.
  LEAVE         the pusher backs out along the push line (a straddle push's: off the face, then
                out along its fingers the way it came in, and closes them).

The target of primitive k is the object pose in the holder's frame that puts the gripper at
the primitive's `gripper_after` (the planner's gripper pose in the object frame), so errors
left by one push are corrected by the next. After the last primitive the pusher returns to
where it started. Any fault stops both arms with the object held tight and ends the run with
an Outcome; `cancel` does the same on request.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply, distance, from_rotation, invert, turn_between
from dmg_executor.belief import HeldPose, PoseTrust
from dmg_executor.contract import Command, GripCommand, Observation, Outcome, Progress, Result, Step
from dmg_executor.ects import arm_twists
from dmg_executor.fingertips import fingertip_shells, leading_tip, meeting_start, push_start, sweep_to_touch
from dmg_executor.grip import tilt_hold_force
from dmg_executor.monitors import (
    SlipStreak,
    limit_violation,
    moved_in_grip,
    poses_agree,
    tilt_since,
    tilted_while_pushed,
    turn_since,
)
from dmg_executor.push_points import (
    ObjectSurface,
    PushError,
    PushPoint,
    exit_normals,
    rotation_push,
    straddle_push,
    translation_push,
)
from dmg_executor.reckoning import Reckoning
from dmg_executor.routes import KeepOut, RouteError, keep_out, route
from dmg_executor.settings import ExecutorSettings
from dmg_executor.views import CameraModel, GripperShape, Occluders, TagLayout, overlap, placed, ranked_views, turns
from dmg_planner.primitives import Primitive, PrimitiveKind


@dataclass
class _Push:
    """One push: where it happens, in the base frame at FIND_CONTACT time, and its route."""

    direction: np.ndarray     # the object's motion at the push point, base frame
    local_direction: np.ndarray   # the same in the holder's frame
    start: np.ndarray         # where the pusher's centre stops before the push
    waypoints: list[np.ndarray]   # route ending at `start`
    orientations: list[np.ndarray]   # pusher orientation wanted at each waypoint (camera on the object)
    lever: float              # m, pusher distance from the grasp axis (rotations)
    contact: PushPoint | None = None   # the push point on the object (object frame)
    other_views: list[np.ndarray] = field(default_factory=list)   # next best orientations at the push start
    homeward: bool = False    # not a push: the way back to where the pusher started, to plan afresh from there
    blind: bool = False       # the camera sees no tag from its start: done on dead reckoning


@dataclass
class _Headway:
    """The closest the pusher has come to where it is going, and when it last came closer."""

    target: bytes          # where it is going (position and orientation)
    offset: float          # m
    turn: float            # rad
    since: float           # s


@dataclass
class _HolderTurn:
    """The holding gripper turning the object about its finger axis, once the pusher is clear."""

    angle: float                  # rad to turn about the holder's z (its finger axis)
    back: bool                    # turning back to where the camera sees the object's tags
    home: np.ndarray | None = None     # instead of turning: back to this pose (where the holder started)
    clearing: bool = True         # the pusher still on its way back to where it started
    turned: float = 0.0           # rad turned so far (summed tick by tick: a half turn has no unique rotation vector)
    last: np.ndarray | None = None     # holder orientation at the previous tick
    place: np.ndarray | None = None    # where the grasp frame stays while it turns
    progress: tuple[float, float] = (0.0, -math.inf)   # (turned, when) at the last headway


@dataclass
class _Look:
    """Looking for the held object: from one place, the pusher orientations left to try (best
    first), then on to the next vantage place."""

    place: np.ndarray
    views: list[np.ndarray]
    places: list[tuple[np.ndarray, np.ndarray]] | None = None   # vantage places left (base frame) and the view there
    gone_to: int = 0              # vantage places gone to
    since: float | None = None    # when the pusher settled in the current view
    travelling: bool = False      # on the way to `place`
    poses: list[tuple[np.ndarray, float]] = field(default_factory=list)   # (pose, m sigma) last seen from each view


def _rotation_about_axis(rotation: np.ndarray) -> float:
    """Angle [rad] of a rotation (holder frame) about the grasp axis x."""
    return float(Rotation.from_matrix(rotation).as_rotvec()[0])



def _torque_axis(middle: np.ndarray, push: PushPoint) -> np.ndarray:
    """Unit axis through `middle` that a push at `push` turns the object about (object frame)."""
    axis = np.cross(push.point - middle, push.direction)
    return axis / max(float(np.linalg.norm(axis)), 1e-12)


def _best_level_press(candidates: list[tuple[_Push, int]], middle: np.ndarray, axis: np.ndarray,
                      reach: np.ndarray) -> _Push:
    """Of level presses (with how many tags the camera sees from each start): seen first, then the one
    turning the object most nearly about the tilt's `axis` (object frame; sim, bracket: a press 30 deg off
    it, taken for the way it ran, turned 0.3-0.9 deg of 4.6), then the one running most nearly along
    `reach` (base frame: the way the pusher's fingers point)."""
    return max(candidates, key=lambda c: (c[1] > 0, round(float(_torque_axis(middle, c[0].contact) @ axis), 2),
                                          float(c[0].direction @ reach)))[0]


def _slid_since(reference: np.ndarray, now: np.ndarray) -> float:
    """How far [m] the grasp's middle moved on the object from pose `reference` to `now` (holder frame);
    a turn about the grasp axis moves it not at all."""
    return float(np.linalg.norm(invert(now)[:3, 3] - invert(reference)[:3, 3]))


def _on_grasp_axis(holder_in_object: np.ndarray, height: float) -> np.ndarray:
    """The point `height` [m] along the grasp axis from the grasp's middle (object frame)."""
    return holder_in_object[:3, 3] + height * holder_in_object[:3, 0]


def _turned_since(reference: np.ndarray, now: np.ndarray) -> float:
    """How far [rad] the object turned about the grasp axis from pose `reference` to `now` (holder frame)."""
    return _rotation_about_axis(now[:3, :3] @ reference[:3, :3].T)


def tilt_steering(tilt: np.ndarray, direction: np.ndarray, lever: float, grip_reach: float) -> float:
    """Which way [rad, signed] the pusher should slide along the grasp axis x (holder frame) to turn a
    pushed object's tilt `tilt` (rotation vector) back. Sliding drags the face along x by friction
    F_x at the contact `lever` from the grasp axis; the self-centring grip answers with unequal
    finger forces whose sliding friction adds (mu*h - L)*F_x about d x x in all, mu*h = `grip_reach`.
    While the object slides, nothing else resists a turn about that axis."""
    axis = np.cross(direction, [1.0, 0.0, 0.0])
    return -math.copysign(1.0, grip_reach - lever) * float(tilt @ axis)


def _distinct(orientations: np.ndarray, chosen: np.ndarray, count: int, apart: float) -> list[np.ndarray]:
    """Up to `count` of `orientations` (best first), each at least `apart` [rad] from `chosen` and the others taken."""
    taken = [chosen]
    for orientation in orientations:
        if len(taken) > count:
            break
        if all(turn_between(orientation, other) >= apart for other in taken):
            taken.append(orientation)
    return taken[1:]


def _limited(velocity: np.ndarray, limit: float, full: bool = False) -> np.ndarray:
    """`velocity` capped at `limit` in size, or (`full`) at exactly `limit` its way."""
    size = float(np.linalg.norm(velocity))
    return velocity * (limit / size) if size > limit or (full and size > 0.0) else velocity


def _shift(twist: np.ndarray, from_point: np.ndarray, to_point: np.ndarray) -> np.ndarray:
    """The same rigid motion as a twist at another point."""
    return np.concatenate([twist[:3] + np.cross(twist[3:], to_point - from_point), twist[3:]])


class PlanExecutor:
    """The state machine of one plan; call `update` every control tick with a fresh Observation."""

    def __init__(self, settings: ExecutorSettings, surface: ObjectSurface, primitives: list[Primitive],
                 principal_finger: int, alpha: float, start_time: float, camera: CameraModel | None = None,
                 tags: TagLayout | None = None):
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"ECTS coordination alpha must be in [0, 1], got {alpha}")
        if principal_finger not in (0, 1):
            raise ValueError(f"principal_finger must be 0 or 1, got {principal_finger}")
        missing = [k for k, p in enumerate(primitives) if p.gripper_after is None]
        if missing:
            raise ValueError(f"primitives {missing} carry no gripper_after pose: plan with this planner version")
        self.settings, self.surface, self.primitives = settings, surface, list(primitives)
        self.plan_length = len(primitives)
        # The narrowest the object is between gripper 1's fingers along the plan: closed much further, they hold nothing.
        self.narrowest_grasp = min((min(p.opening_before, p.opening_after) for p in primitives), default=0.0)
        self.widest_grasp = max((max(p.opening_before, p.opening_after) for p in primitives), default=0.0)
        self.notes: list[str] = []      # primitives that could not be finished, and why
        self.camera, self.tags = camera, tags
        self.turns = (turns(settings.tilt_limit, settings.roll_limit, settings.views.grid_step)
                      if camera is not None and tags is not None else None)
        self.shape = GripperShape(settings.finger_length, settings.tip_radius, settings.hand_start, settings.hand_end,
                                  settings.hand_radius)
        self.waiting_since: float | None = None     # at a push start, waiting for a fresh object pose
        self.principal_finger, self.alpha = principal_finger, float(alpha)
        self.started = start_time
        self.index, self.pushes, self.step = 0, 0, Step.FIND_CONTACT
        self.step_started = start_time
        self.result: Result | None = None
        self.push: _Push | None = None
        self.retreat: list[np.ndarray] = []    # where the pusher backs out to after a push (base frame), in order
        self.pusher_spread = 0.0        # m between the pusher's fingertip centres as last commanded (0: closed)
        self.opened_at = -math.inf      # when the pusher opened for a straddle push
        self.waypoint = 0
        self.trust = PoseTrust(settings.slip_position_sigma, settings.slip_tilt_sigma, settings.reference_poses)
        self.held = HeldPose(self.trust)      # the object pose the closed grip must keep
        self.pushed_reference: np.ndarray | None = None
        self.grip_until = -math.inf
        self.phase = ""
        self.looking: _Look | None = None
        self.searching = False          # the held object went unseen on the way to a push: look for it
        self.seeking_certain = False    # ... or the plan's end is to be judged from an uncertain pose: look for a certain one
        self.sought_certain = False     # a look for a certain pose was made since the last push
        self.error_before_push = math.inf   # the current primitive's error when its last push was planned
        self.settled = False            # near the goal, and pushes make no headway: no more of them
        self.headway: _Headway | None = None
        self.slip_streak = SlipStreak()
        self.unreachable: list[np.ndarray] = []   # push directions (base frame) whose start the pusher could not reach
        self.shortfalls: list[tuple[np.ndarray, float]] = []   # (push direction in the holder frame, m): see _judge_blind_push
        self.pushed_from = np.eye(4)      # pusher in the holder's frame where the current push began
        self.pushed_along = np.zeros(3)   # ... and the direction it pushed (holder frame)
        self.pushed_point: PushPoint | None = None   # ... and where on the object
        self.pushed_opening = 0.0            # ... and gripper 1's opening then
        self.missed: list[PushPoint] = []    # rotation pushes whose pusher turned without turning the object
        self.level_index: int | None = None   # the correction that presses the object level (see level_tilt)
        self.level_axis = np.zeros(3)         # holder frame: the axis the current level push turns the object about
        self.level_began = 0.0                # rad: the tilt off the goal's grasp axis when leveling began
        self.fruitless: list[np.ndarray] = []   # places (holder frame) a look saw the object from none of the views at
        self.turn_mark: tuple[float, float] | None = None   # (pusher, object) turned [rad] when the object last gained
        self.sweep_to_face = 0.0   # rad a rotation's pusher turns before its tips meet the face (as seen when it began)
        self.reckoning: Reckoning | None = None   # the current push's last known object pose
        self.reckoned: np.ndarray | None = None    # object pose believed while unseen since a push moved it (or the holder turned it)
        self.reckoned_time = -math.inf
        self.holder_turn: _HolderTurn | None = None
        self.turned_by = 0.0            # rad the holder turned the object about its fingers (to turn back by)
        self.far_side = False           # the holder turned: the pusher faces the side it could not reach
        self.far_side_pushed = False    # ... and has pushed there: turn back to look
        self.pressed_turned = False     # a level press was seen made since the holder last turned
        self.may_turn = True            # false once a turn stopped short (the wrist at a limit)
        self.may_return = True          # false once the holder could not go back to where it started
        self.unseen_from = -math.inf    # being unseen counts from here (turns, blind pushes: expected)
        self.holder_start: np.ndarray | None = None
        self.pusher_home: np.ndarray | None = None
        self.returning = False
        self.last = Observation(start_time, np.eye(4), np.eye(4), None, -math.inf, 0.0)
        self.errors = (math.nan, math.nan)

    # --- public ------------------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return self.result is not None

    def progress(self) -> Progress:
        return Progress(min(self.index, len(self.primitives) - 1) if self.primitives else 0, len(self.primitives),
                        self.step, self.errors[0], self.errors[1], self.pushes, self.principal_contact(self.last))

    def update(self, observation: Observation) -> Command:
        """One control tick: the arms' twists and any gripper command."""
        if self.done:
            return self._halt()
        self.last = observation
        if self.holder_start is None:
            self.holder_start, self.pusher_home = observation.holder.copy(), observation.pusher.copy()
            command = self._tick(observation)
            command.pusher_grip = GripCommand(0.0, 0.0)     # pusher closed: its fingertips push together
            return command
        return self._tick(observation)

    def cancel(self, reason: str = "cancelled on request") -> Command:
        return self.abort(Outcome.CANCELED, reason)

    def abort(self, outcome: Outcome, message: str) -> Command:
        """End the run from outside (cancel, a dead driver): stop, grip tight."""
        return self._abort(outcome, message)

    # --- the state machine ---------------------------------------------------------------------
    def _tick(self, obs: Observation) -> Command:
        s = self.settings
        if obs.opening < s.monitors.dropped_share * self.narrowest_grasp:
            return self._abort(Outcome.OBJECT_LOST, f"the object left gripper 1 during {self.step.name} of primitive "
                               f"{self.index}: its fingers closed to {obs.opening * 1000:.1f} mm (the plan's narrowest "
                               f"grasp is {self.narrowest_grasp * 1000:.1f} mm); stopped")
        # While the grip is closed and nothing pushes, the object cannot move: the camera may lose it
        # for a while (the pusher's hand turns and passes the object); the run ends only when the
        # held object stays unseen (on the way to a push: and is not found from vantage places). A
        # push goes on by dead reckoning (or, without blind pushes, stops at once with the grip
        # closed) and counts as seen until it ends; on the way to a push that starts where the camera
        # sees no tag (and loosening there), and while the holder turns the object or has turned it
        # away, the object is not expected to be seen: the count starts after.
        blind_push = self.step in (Step.APPROACH, Step.EXECUTE) and self.push is not None and self.push.blind
        if blind_push or self.holder_turn is not None or self.far_side or self.searching:
            self.unseen_from = obs.time     # (a search is bounded by its vantage places)
        unseen = obs.time - max(obs.object_time, self.reckoned_time, self.unseen_from)
        if obs.object_in_holder is not None and unseen > s.stale_after_held and self.step == Step.APPROACH:
            # On the way to a push (or back from one given up) the held object has not moved: look for it
            # from vantage places round it, as after a push, before giving it up (sim: a box turned
            # 131 deg, the pusher stuck at a waypoint behind it, OBJECT_LOST on its way home).
            self.notes.append(f"the object went unseen for {unseen:.1f} s on the way to a push of primitive "
                              f"{self.index}: looked for it")
            self.searching = True
            self._enter(Step.FIND_CONTACT, obs)
            return Command()
        if obs.object_in_holder is None or unseen > s.stale_after_held:
            age = "never seen" if obs.object_in_holder is None else f"last seen {unseen:.2f} s ago"
            return self._abort(Outcome.OBJECT_LOST, f"object pose lost ({age}; limit {s.stale_after_held:.2f} s) "
                               f"during {self.step.name} of primitive {self.index}: stopped, gripper 1 closed at the hold force")
        # Poses from images taken while the holder turns are not trusted, nor those with the object
        # turned away unless they are certain (the object seen edge-on or from its back: measured
        # 7-10 mm off); the held pose is known.
        trusted = self._trusted(obs)
        fresh = self._fresh(obs)
        self.searching = self.searching and not (fresh and (not self.seeking_certain or self.trust.certain(obs)))
        self.seeking_certain = self.seeking_certain and self.searching
        if self._pushing() and s.blind_pushes:
            # The last pose moved on by the pusher's motion since its image: the image's latency made
            # up for, and the push goes on when the camera loses the object.
            known = self.reckoning
            known.moved(obs.time, invert(obs.holder) @ obs.pusher)
            if fresh:
                known.seen(obs.object_in_holder, obs.object_time)
            elif not known.blind:
                known.blind = True
                self.notes.append(f"a push of primitive {self.index} went on unseen, on dead reckoning")
            self.reckoned, self.reckoned_time = known.believed(invert(obs.holder) @ obs.pusher), obs.time
        elif not fresh and not s.blind_pushes and self.step == Step.EXECUTE and self.phase != "tighten":
            self.notes.append(f"a push of primitive {self.index} stopped: object unseen for "
                              f"{obs.time - obs.object_time:.2f} s")
            return self._tighten(obs)
        elif self.reckoned is not None and fresh and obs.object_time >= self.reckoned_time:
            # Seen again after the push. Only a pose certain of its position judges it: an uncertain one
            # (a lone tag seen obliquely; sim: 11 mm off at 4 mm sigma) would have every later push that
            # way reach further for a miss that was not.
            if obs.object_position_sigma <= s.slip_position_sigma:
                self._judge_blind_push(obs)
            self.reckoned = None
        if fresh and self.reckoned is None and (self.held.pending or self.held.outdone_by(obs)):
            self.held.take(obs)     # the first fresh pose since the grip closed, or a more certain one
        fault = self._limits(obs) or (self._slip(obs) if trusted else None)
        if fault:
            return self._abort(*fault)
        if fresh and self.reckoned is None and not self.slip_streak.poses:
            self.held.fold_in(obs)
        if self.reckoned is not None:
            obs = replace(obs, object_in_holder=self.reckoned)    # pushed, not seen since: where it went
        elif self.held.better_than(obs):
            obs = replace(obs, object_in_holder=self.held.reference)   # held still since a certain pose
        if obs.time - self.step_started > s.step_timeout:
            return self._abort(Outcome.STEP_TIMEOUT, f"{self.step.name} of primitive {self.index} did not finish in "
                               f"{s.step_timeout:.1f} s (contact error {self.errors[0] * 1000:.1f} mm, angle error "
                               f"{np.rad2deg(self.errors[1]):.1f} deg)")
        self._measure(obs)
        handler = self._finish_plan if self.returning else {
            Step.FIND_CONTACT: self._find_contact, Step.APPROACH: self._approach, Step.EXECUTE: self._execute,
            Step.LEAVE: self._leave}[self.step]
        command = handler(obs)
        spread = self._spread_wanted(obs)
        if spread != self.pusher_spread:
            self.pusher_spread = spread
            command.pusher_grip = GripCommand(max(spread - 2 * s.tip_radius, 0.0), 0.0)
        return command

    def _spread_wanted(self, obs: Observation) -> float:
        """How far apart [m] the pusher's fingertip centres should be: opened for a straddle push from where
        its last stretch begins until it has backed out of it, else closed (0) - never closing on gripper 1's
        fingers (the pusher still in the space kept free round them: stopped short backing out)."""
        if self._push_spread and (self.step in (Step.EXECUTE, Step.LEAVE)
                                  or (self.step == Step.APPROACH and self.waypoint >= len(self.push.waypoints) - 1)):
            return self._push_spread
        if self.pusher_spread and self._keep_out(obs).contains(apply(invert(obs.holder), obs.pusher[:3, 3]))[0]:
            return self.pusher_spread
        return 0.0

    @property
    def _push_spread(self) -> float:
        """The current push's fingertip spread [m] if it is a straddle push, else 0."""
        push = self.push
        return 0.0 if push is None or push.contact is None else push.contact.spread

    def _enter(self, step: Step, obs: Observation) -> None:
        """Start a step with the grip closed: from here the object must not move in it (from the
        next fresh pose on, if the last one is stale: the object moved while unseen)."""
        self.step, self.step_started = step, obs.time
        if self.held.reference is not None and self.reckoned is None:
            return      # held since its pose was seen, the grip closed all along: still where it was seen
        # (an object pushed unseen is where dead reckoning puts it, not seen there: no reference yet)
        if obs.time - obs.object_time > self.settings.stale_after or self.reckoned is not None:
            self.held.await_fresh()
        else:
            self.held.take(obs)

    def _pushing(self) -> bool:
        return self.step == Step.EXECUTE and self.phase in ("touch", "push")

    def _end_uncertain(self) -> bool:
        """Is the plan's last primitive (or correction) about to be judged from a held pose too uncertain of its
        position to tell, with no look for a better one since the last push? (sim, plug: a lone tag seen
        obliquely at the end, 1.2-3.6 mm sigma, put a grasp 2.5 mm from its goal 2.4-8.1 mm from it.)"""
        return not self.sought_certain and self.held.uncertain

    def _push_reference(self, obs: Observation) -> np.ndarray:
        """The pose a push starts from: the latest seen, if fresh and certain - the push's own poses are
        single poses from this view, while the held reference may average poses from the views on the way
        (sim, bracket: 4.2 deg of tilt averaged over an approach, 2.9 deg seen at the push start, 2.7 true;
        a level press took the difference for the object turning back and stopped closing its gap) - else
        the held reference (a blind push)."""
        seen = self.last
        if seen.object_in_holder is not None and self._fresh(seen) and self.trust.certain(seen):
            return seen.object_in_holder.copy()
        return obs.object_in_holder.copy()

    def _trusted(self, obs: Observation) -> bool:
        """Is this pose from an image worth trusting: not taken while the holder turns, nor of the object
        turned away unless certain?"""
        return self.holder_turn is None and (not self.far_side or self.trust.certain(obs))

    def _fresh(self, obs: Observation) -> bool:
        """A trusted pose no older than `stale_after`."""
        return self._trusted(obs) and obs.time - obs.object_time <= self.settings.stale_after

    def _find_contact(self, obs: Observation) -> Command:
        if self.holder_turn is not None:
            return self._turn_holder(obs)
        if self.far_side_pushed:
            return self._start_holder_turn(obs, back=True)     # to see what the push did
        if (self.held.pending or self.searching) and not self.far_side:
            return self._look_around(obs)     # plan the next push from a fresh pose
        self.looking = None
        while self.index < len(self.primitives) and self._primitive_finished(obs):
            if self._leveling and self.far_side:    # presses seen from the turned holder: judged once turned back
                self.far_side_pushed = True
                return Command()
            if self.index == len(self.primitives) - 1 and self._end_uncertain():
                self.sought_certain = self.seeking_certain = self.searching = True
                return self._look_around(obs)
            self.index, self.pushes = self.index + 1, 0
            if self.index == len(self.primitives):
                self._add_correction(obs)
            self._measure(obs)
        if self.index >= len(self.primitives):
            return self._start_holder_turn(obs, back=True) if self.far_side else self._finish_plan(obs)
        primitive = self.primitives[self.index]
        try:
            self.push = self._plan_push(primitive, obs)
            self.error_before_push = self._error_and_tolerance(obs)[0]
        except (PushError, RouteError) as error:
            if self._leveling and self.pressed_turned:   # the next press another way: turn back, plan from there
                self.far_side_pushed = True
                return Command()
            turn = self._quarter_turn(obs) if self._leveling else None
            if turn is not None:
                return self._start_holder_turn(obs, back=False, angle=turn)
            if self._push_when_returned(primitive, obs):
                return self._start_holder_turn(obs, back=False, home=self.holder_start)
            if self._push_when_turned(primitive, obs):
                return self._start_holder_turn(obs, back=False)
            turn = self._quarter_turn(obs) if primitive.kind == PrimitiveKind.TRANSLATION and not self._leveling else None
            if turn is not None:
                return self._start_holder_turn(obs, back=False, angle=turn)
            self.far_side_pushed = self.far_side     # (turned, and still no push: turn back)
            # No push can do (the rest of) it: the next primitive aims at its own target from here,
            # and the result says what was left and why.
            failed = None if self._leveling else primitive.kind
            self.notes.append(f"primitive {self.index} ({failed.name.lower() if failed else 'level press'}) left at "
                              f"{self.errors[0] * 1000:.1f} mm, {np.rad2deg(self.errors[1]):.1f} deg: no safe push: {error}")
            self.index, self.pushes = self.index + 1, 0
            if self.index == len(self.primitives):
                self._add_correction(obs, failed=failed)
            return Command()
        outside = [p for p in self.push.waypoints + [self.push.start]
                   if np.any(p < self.settings.workspace_min) or np.any(p > self.settings.workspace_max)]
        if outside:
            return self._abort(Outcome.LIMIT_VIOLATION, f"primitive {self.index}: the push needs the pusher at "
                               f"{np.round(outside[0], 3).tolist()} m, outside the workspace")
        self.waypoint, self.sought_certain = 0, False
        self._enter(Step.APPROACH, obs)
        return Command()

    def _push_when_turned(self, primitive: Primitive, obs: Observation) -> bool:
        """Would the pusher, back where it started, find a push for `primitive` with the holder turned
        `holder_turn` about its fingers (the object's far side towards it)? Such a push is done on dead
        reckoning, so only with blind pushes."""
        s = self.settings
        if (s.holder_turn == 0.0 or not s.blind_pushes or self.far_side or not self.may_turn
                or not self._clear_of_turn(obs, self.pusher_home[:3, 3])):
            return False
        holder = obs.holder.copy()
        holder[:3, :3] = obs.holder[:3, :3] @ Rotation.from_rotvec([0.0, 0.0, s.holder_turn]).as_matrix()
        try:
            self._plan_push(primitive, replace(obs, holder=holder, pusher=self.pusher_home.copy()))
        except (PushError, RouteError):
            return False
        return True

    def _quarter_turn(self, obs: Observation) -> float | None:
        """Where no push is found: the turn of the holder about its fingers (+-90 deg) after which the pusher,
        back where it started, finds one - a level press or a straddle push, each with the pusher's fingers
        pointing along the grasp axis, which Baxter's right arm does only about the way they point at home.
        (Not for other pushes a quarter turn would allow: sim, a T probe, a push along its bar so found
        knocked it out of the grip at every alpha.)"""
        if self.far_side or not self.may_turn:
            return None
        for angle in (np.pi / 2, -np.pi / 2):
            holder = obs.holder.copy()
            holder[:3, :3] = obs.holder[:3, :3] @ Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix()
            try:
                push = self._plan_push(self.primitives[self.index],
                                       replace(obs, holder=holder, pusher=self.pusher_home.copy()))
            except (PushError, RouteError):
                continue
            if self._leveling or push.contact.spread:
                return angle
        return None

    def _push_when_returned(self, primitive: Primitive, obs: Observation) -> bool:
        """At alpha < 1 the holder moves in the pushes (at 0 it does all of a rotation: turned 45 deg
        about its grasp axis, its hand is where the pusher has to go). Would the pusher, back where it
        started, find a push for `primitive` with the holder back where it started, holding the object
        as it does now (or with the holder then turning the object's far side towards it)?"""
        offset, turned = distance(self.holder_start, obs.holder)
        moved = self.settings.holder
        if not self.may_return or self.far_side or (offset < moved.moved_distance and turned < moved.moved_turn):
            return False
        returned = replace(obs, holder=self.holder_start.copy(), pusher=self.pusher_home.copy())
        try:
            self._plan_push(primitive, returned)
        except (PushError, RouteError):
            return self._push_when_turned(primitive, returned)
        return True

    def _turn_radius(self, obs: Observation) -> float:
        """How far from the holder's finger axis the pusher's tip must be while the holder turns the object."""
        s = self.settings
        body = apply(obs.object_in_holder, self.surface.vertices)
        reach = max(float(np.hypot(body[:, 0], body[:, 1]).max()), obs.opening / 2 + 2.5 * s.tip_radius)
        return reach + 2 * s.tip_radius + s.clearance

    def _clear_of_turn(self, obs: Observation, place: np.ndarray) -> bool:
        """Is the pusher's tip at `place` (base frame) out of reach of the object turning about the holder's fingers?"""
        local = apply(invert(obs.holder), place)
        return float(np.hypot(local[0], local[1])) > self._turn_radius(obs)

    def _start_holder_turn(self, obs: Observation, back: bool, home: np.ndarray | None = None,
                           angle: float | None = None) -> Command:
        """The pusher back to where it started, then the holder turns the object: `holder_turn` to show
        the pusher the far side, or back after the push there; or, given `home`, the holder goes there."""
        if home is not None:
            angle = 0.0
        elif back:
            angle = -self.turned_by
        else:
            angle = self.settings.holder_turn if angle is None else angle
            self.turned_by = angle
        self.holder_turn = _HolderTurn(angle, back, None if home is None else home.copy())
        self.far_side_pushed = self.pressed_turned = False
        try:
            self._head_home(obs, clear_of_turn=True)
        except RouteError as error:
            if back:
                return self._abort(Outcome.LIMIT_VIOLATION, f"cannot clear the pusher from the object before the "
                                   f"holding gripper turns it back: {error}")
            return self._forgo_turn(obs, f"no route takes the pusher out of its reach ({error})")
        if home is not None:
            offset, turned = distance(self.holder_start, obs.holder)
            self.notes.append(f"primitive {self.index}: the holding gripper went back to where it started (it had "
                              f"moved {offset * 1000:.0f} mm and turned {np.rad2deg(turned):.0f} deg in the pushes) "
                              "for a push it could not be given where it was")
        elif not back:
            what = ("a level press" if self._leveling else "a push on its far side" if abs(angle) > np.pi / 2 + 0.1
                    else "a push from its side")
            self.notes.append(f"primitive {self.index}: the holding gripper turned the object "
                              f"{np.rad2deg(angle):.0f} deg about its fingers for {what}")
        self._enter(Step.FIND_CONTACT, obs)
        return Command()

    def _forgo_turn(self, obs: Observation, why: str) -> Command:
        """Nothing turned yet: the holder's turn (or its way back to where it started) is given up like a push
        the pusher cannot get to, and not tried again; the run goes on without it."""
        turn = self.holder_turn
        self.notes.append(f"the holding gripper did not {'go back' if turn.home is not None else 'turn the object'}: {why}")
        self.holder_turn = None
        if turn.home is not None:
            self.may_return = False
        else:
            self.may_turn = False
        self._enter(Step.FIND_CONTACT, obs)
        return Command()

    def _turn_holder(self, obs: Observation) -> Command:
        """Clear the pusher, then turn the holder about its finger axis at a P-controlled rate, keeping
        its grasp frame in place. A turn that stops gaining (the wrist at its limit) goes back."""
        s, turn = self.settings, self.holder_turn
        if turn.clearing:
            stalled = self._stalled(obs)
            if not (self._arrived(obs) or stalled):
                return self._along_route(obs)
            if not stalled and self._on_the_way:
                self.waypoint += 1
                return Command()
            if not self._clear_of_turn(obs, obs.pusher[:3, 3]):
                if turn.back:
                    return self._abort(Outcome.LIMIT_VIOLATION, "the pusher cannot get out of reach of the object "
                                       "the holding gripper must turn back")
                return self._forgo_turn(obs, "the pusher could not get out of its reach")
            turn.clearing, turn.place, turn.last = False, obs.holder[:3, 3].copy(), obs.holder[:3, :3].copy()
            turn.progress = (math.inf if turn.home is not None else 0.0, obs.time)   # (turned or left, when)
            # The grip is closed: the object stays where it was seen; the next reference is the first
            # image after the turn back.
            self.held.await_fresh()
            self.reckoned, self.reckoned_time = obs.object_in_holder.copy(), math.inf
        if turn.home is not None:
            return self._holder_home(obs)
        current = obs.holder[:3, :3]
        turn.turned += float(Rotation.from_matrix(turn.last.T @ current).as_rotvec()[2])
        turn.last = current.copy()
        left = turn.angle - turn.turned
        if abs(left) < self.settings.approach.waypoint_turn_tolerance:
            self.holder_turn, self.far_side, self.reckoned_time = None, not turn.back, obs.time
            self._enter(Step.FIND_CONTACT, obs)
            return Command()
        if abs(turn.turned - turn.progress[0]) > self.settings.approach.headway_turn:
            turn.progress = (turn.turned, obs.time)
        drift = float(np.linalg.norm(obs.holder[:3, 3] - turn.place))
        if obs.time - turn.progress[1] > s.stall_time or drift > self.settings.monitors.turn_drift:
            why = (f"moved {drift * 1000:.0f} mm" if drift > self.settings.monitors.turn_drift
                   else f"stopped at {np.rad2deg(turn.turned):.0f} deg")
            if turn.back:
                return self._abort(Outcome.LIMIT_VIOLATION, f"the holding gripper could not turn the object back ({why})")
            self.notes.append(f"the holding gripper could not turn the object ({why}): turned back, not turned again")
            self.may_turn = False
            turn.angle, turn.back, turn.progress, turn.place = 0.0, True, (turn.turned, obs.time), obs.holder[:3, 3].copy()
            return Command()
        rate = float(np.clip(s.approach_gain * left, -s.max_angular_speed, s.max_angular_speed))
        return Command(holder=np.concatenate([s.approach_gain * (turn.place - obs.holder[:3, 3]), rate * current[:, 2]]))

    def _holder_home(self, obs: Observation) -> Command:
        """The holder (the grip closed, the pusher clear) back to where it started at a P-controlled
        speed; one that stops gaining (an arm at a limit) stays where it got to."""
        s, turn = self.settings, self.holder_turn
        offset = turn.home[:3, 3] - obs.holder[:3, 3]
        rotation = Rotation.from_matrix(turn.home[:3, :3] @ obs.holder[:3, :3].T).as_rotvec()
        distance_left, angle_left = float(np.linalg.norm(offset)), float(np.linalg.norm(rotation))
        if distance_left < s.waypoint_tolerance and angle_left < self.settings.approach.waypoint_turn_tolerance:
            self.holder_turn, self.reckoned_time = None, obs.time
            self._enter(Step.FIND_CONTACT, obs)
            return Command()
        headway = self.settings.approach
        left = distance_left + angle_left * headway.headway_distance / headway.headway_turn     # headway in either counts
        if left < turn.progress[0] - self.settings.approach.headway_distance:
            turn.progress = (left, obs.time)
        if obs.time - turn.progress[1] > s.stall_time:
            self.notes.append(f"the holding gripper stopped {distance_left * 1000:.0f} mm and "
                              f"{np.rad2deg(angle_left):.0f} deg short of where it started")
            self.holder_turn, self.may_return, self.reckoned_time = None, False, obs.time
            self._enter(Step.FIND_CONTACT, obs)
            return Command()
        return Command(holder=np.concatenate([_limited(s.approach_gain * offset, s.approach_speed),
                                              _limited(s.approach_gain * rotation, s.max_angular_speed)]))

    def _add_correction(self, obs: Observation, failed: PrimitiveKind | None = None) -> None:
        """The plan is done but the grasp is not where it should be (a rotation also slides the object,
        a push also turns it): one more translation or rotation to the goal grasp, the larger error
        first (not the kind that just found no push), up to `campaign.max_corrections` besides a level press (see
        `level_tilt`) comes first where the tilt is more than the turn about the grasp axis left (the
        holder's turns for it shift the object, which the corrections after it take back), else last."""
        s = self.settings
        self.index -= 1
        self._measure(obs)
        self.index += 1
        shares = {PrimitiveKind.TRANSLATION: self.errors[0] / s.position_tolerance,
                  PrimitiveKind.ROTATION: abs(self.errors[1]) / s.angle_tolerance}
        shares.pop(failed, None)
        kind = max(shares, key=shares.get)
        corrections = len(self.primitives) - self.plan_length - (self.level_index is not None)
        corrected = self.settled or shares[kind] <= s.campaign.retry_factor or corrections >= s.campaign.max_corrections
        tilt = float(np.linalg.norm(self._tilt_off_goal(obs.object_in_holder))) if self._needs_leveling(obs) else 0.0
        if tilt and (corrected or tilt > abs(self.errors[1])):
            self.level_index, self.level_began = len(self.primitives), tilt
            self.primitives.append(replace(self.primitives[-1]))
            self.notes.append(f"the grasp axis was {np.rad2deg(self.level_began):.1f} deg off the goal's: "
                              f"primitive {self.level_index} presses the object level")
        elif not corrected:
            self.primitives.append(replace(self.primitives[-1], kind=kind))

    def _primitive_finished(self, obs: Observation) -> bool:
        """Within tolerance, or close enough after a push, or out of pushes, or settled near the goal (a level
        press: level, or out of presses, or the last gained nothing)."""
        error, tolerance = self._error_and_tolerance(obs)
        if self._leveling:
            gained = self.level_began - error
            level, settled = self.settings.level, self.settings.campaign.settled_share * self.settings.goal_angle_tolerance
            return (error <= tolerance or self.pushes >= level.pushes + 1 or (self.pushes > 0 and gained < level.done)
                    or (self.pushes >= level.pushes and error <= settled))
        return (error <= tolerance or (self.pushes > 0 and error <= self.settings.campaign.retry_factor * tolerance)
                or self.pushes >= self.settings.campaign.max_pushes_per_primitive
                or self._settled(obs, error, tolerance))

    def _error_and_tolerance(self, obs: Observation) -> tuple[float, float]:
        """The current primitive's remaining error and its tolerance (m for a translation, rad for a rotation
        and for the tilt a level push presses back), judged from the pose the tick goes by (not the latest
        image's: one taken while the holder turns is not trusted - sim, bracket: 7.5 deg seen mid-turn, 4.0
        true, ended a level press as having gained nothing)."""
        if self._leveling:
            return float(np.linalg.norm(self._tilt_off_goal(obs.object_in_holder))), self.settings.level_tilt
        if self.primitives[self.index].kind == PrimitiveKind.TRANSLATION:
            return self.errors[0], self.settings.position_tolerance
        return abs(self.errors[1]), self.settings.angle_tolerance

    def _settled(self, obs: Observation, error: float, tolerance: float) -> bool:
        """Did the last push of a primitive that ends at the goal grasp make no headway (`campaign.no_headway`),
        with the grasp already within `campaign.settled_share` of the goal's tolerances? Then more pushes like it
        would spend the time, not improve the grasp (sim, box: eight 13 s translation pushes from
        1.9-2.8 mm off moved it 0.0-0.6 mm each, until the run's time was nearly up); no correction
        follows."""
        headway = self.error_before_push - error
        if (self.pushes == 0 or self.index < self.plan_length - 1
                or headway >= self.settings.campaign.no_headway * tolerance):
            return False
        s = self.settings
        position, angle = self.final_errors(obs)
        self.settled = (position <= s.campaign.settled_share * s.goal_position_tolerance
                        and angle <= s.campaign.settled_share * s.goal_angle_tolerance)
        if self.settled:
            self.notes.append(f"primitive {self.index} settled {position * 1000:.1f} mm and {np.rad2deg(angle):.1f} deg "
                              f"from the goal: its last push made no headway")
        return self.settled

    def _plan_push(self, primitive: Primitive, obs: Observation) -> _Push:
        """The push for what remains of `primitive`: the best-seen of the possible push points,
        with its route and the pusher's orientations along it."""
        s = self.settings
        holder_in_object = invert(obs.object_in_holder)
        occluders = Occluders.of(self.shape, obs.holder, obs.opening)
        if self._leveling:
            return self._plan_level_push(obs, occluders)
        if primitive.kind == PrimitiveKind.TRANSLATION:
            # Square onto a face round the grasp axis, along the normal line through the grasp's middle
            # (the contact force is along the face's normal: off that line it would turn the object),
            # up to `push.detour_limit` off the remaining motion (holder frame): such a push goes as far as the
            # motion's share along it, the next one takes the rest. Where no face is square to any
            # such line (a curved object), along the motion itself.
            motion = self._remaining_motion(obs)
            directions = self._square_pushes(obs, motion, holder_in_object) or [motion]
            middle = holder_in_object[:3, 3]                 # the grasp's middle on the object (object frame)
            pushes, problems = [], []
            for direction in directions:
                try:   # the contact moves over the object opposite to the object's motion
                    pushes.append(translation_push(self.surface, middle, -(holder_in_object[:3, :3] @ direction),
                                                   self.settings.push.translation_slant))
                except PushError as error:
                    problems.append(str(error))
            if motion[2] > s.position_tolerance and s.straddle_opening > 0.0:
                try:
                    pushes.append(self._straddle_push(holder_in_object))
                except PushError as error:
                    problems.append(str(error))
            if not pushes:
                raise PushError("; ".join(problems))
            candidates = self._watched(obs, pushes, occluders)
            # The most progress: the full motion when the camera can watch it.
            return max(candidates, key=lambda c: float(motion @ (invert(obs.holder)[:3, :3] @ c[0].direction)))[0]
        limited = float(np.clip(self.errors[1], -s.max_push_angle, s.max_push_angle))
        # The object must turn by `limited` about x: a finger rotation of -limited about +x. The push
        # goes across the fingers (beyond their tips, or between them towards the palm where that
        # fits) or along them towards the palm beside them, as the paper's; where none of those can be
        # pushed and watched (an object held across an edge: each meets a face slanted 45 deg near its
        # edge), square onto another face round the grasp. (Left to the corrections after the plan
        # instead, the plug's set did worse: a translation first slid it where the rotation then pushed
        # it back towards the palm.)
        paper = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
        problems = []
        for height in (0.0, *s.push.off_middle_shares * obs.opening / 2):
            if height and not self.surface.inside(_on_grasp_axis(holder_in_object, height)[None])[0]:
                continue     # (the axis crosses a hollow there)
            faces = self._face_pushes(obs, holder_in_object, height)
            faces = faces[np.abs(faces @ paper.T).max(axis=1) < np.cos(s.push.same_push)]
            for directions in (paper, faces):
                pushes = self._rotation_pushes(obs, directions, limited, problems, height)
                try:
                    candidates = self._watched(obs, pushes, occluders) if pushes else []
                except (PushError, RouteError) as error:
                    problems.append(str(error))
                    continue
                if candidates:   # first of the best seen: the longest lever beyond the tips
                    return max(candidates, key=lambda candidate: candidate[1])[0]
        raise PushError("; ".join(problems))

    def _straddle_push(self, holder_in_object: np.ndarray) -> PushPoint:
        """The push that moves the object out along gripper 1's fingers: on its palm side, the pusher's tips
        open either side of those fingers (`straddle_push`), on a face the pusher's fingers reach beside them
        without meeting gripper 1's palm."""
        s = self.settings
        middle, rotation = holder_in_object[:3, 3], holder_in_object[:3, :3]
        halves = 2 * s.tip_radius + s.straddle.margins
        halves = halves[2 * halves - 2 * s.tip_radius <= s.straddle_opening + 1e-9]
        if not len(halves):
            widest = 2 * (s.tip_radius + s.straddle.margins[0])
            raise PushError(f"a straddle push needs the pusher open {widest * 1000:.0f} mm "
                            f"(straddle_opening {s.straddle_opening * 1000:.0f} mm)")
        push = straddle_push(self.surface, middle, rotation[:, 2], rotation[:, 1], halves, s.straddle.twist,
                             s.push.translation_slant)
        depth = -float((push.point - middle) @ rotation[:, 2])     # towards the palm from the grasp's middle
        room = s.finger_length - 2 * s.tip_radius - s.gap - s.clearance   # (its finger beside the tip, radius tip_radius)
        if depth > room:
            raise PushError(f"the straddle push's face is {depth * 1000:.0f} mm towards gripper 1's palm (the pusher's "
                            f"fingers fit up to {room * 1000:.0f} mm)")
        return push

    def _plan_level_push(self, obs: Observation, occluders: Occluders) -> _Push:
        """A push along the grasp axis on a face beside the grasp's middle that turns the object about the
        axis across it the tilt needs (`rotation_push` about that axis), beyond the fingertips or beside
        the fingers, never between them towards the palm; one the camera sees from its start."""
        s = self.settings
        tilt = self._tilt_off_goal(obs.object_in_holder)
        angle = float(np.linalg.norm(tilt))
        self.level_axis = tilt / angle
        holder_in_object = invert(obs.object_in_holder)
        middle, rotation = holder_in_object[:3, 3], holder_in_object[:3, :3]
        pushes, problems = [], []
        for depth, off, along in itertools.product(s.level.levers, s.level.off_axis, (1.0, -1.0)):
            # (an axis turned `off` about the grasp axis: most of the turn, a little across it, the next push's)
            axis = Rotation.from_rotvec([off, 0.0, 0.0]).apply(self.level_axis)
            try:
                push = rotation_push(self.surface, middle, rotation @ axis, rotation @ np.array([along, 0.0, 0.0]),
                                     -angle, depth, 0.0, s.push.slant_limit, s.edge_margin)
            except PushError as error:
                problems.append(str(error))
                continue
            lever = rotation.T @ (push.point - middle)      # holder frame
            if lever[2] < 0.0 and abs(lever[1]) < 2 * s.tip_radius:
                problems.append(f"the level push at {np.round(lever * 1000, 1).tolist()} mm is between the fingers")
                continue
            pushes.append(push)
        if not pushes:
            raise PushError("no level push: " + "; ".join(problems))
        candidates = self._watched(obs, pushes, occluders)
        if not s.blind_pushes:
            candidates = [c for c in candidates if c[1] > 0]
        if not candidates:
            raise PushError("the wrist camera would see none of the object's tags from where a level push starts")
        # The pusher's fingers point along the press: only a press the way they point at its start is reachable.
        reach = self.pusher_home[:3, 2]
        candidates = [c for c in candidates if float(c[0].direction @ reach) > np.cos(s.level.reach_cone)]
        if not candidates:
            raise PushError("no level push runs the way the pusher's fingers point where it started")
        return _best_level_press(candidates, middle, rotation @ self.level_axis, reach)

    def _rotation_pushes(self, obs: Observation, directions: np.ndarray, angle: float, problems: list[str],
                         height: float = 0.0) -> list[PushPoint]:
        """Push points turning the object by `angle` about x, pushed along `directions` (holder frame)
        on lines `height` [m] along the grasp axis from the grasp's middle, each at the full lever or
        shorter ones where the object is small, in order of preference; why others were not taken
        goes to `problems`."""
        s = self.settings
        holder_in_object = invert(obs.object_in_holder)
        middle = _on_grasp_axis(holder_in_object, height)   # (the torque about the axis is the same at any height)
        palm = -holder_in_object[:3, 2]
        palm_room = s.finger_length - 2 * s.tip_radius - s.clearance
        ranked = []
        for along_fingers, direction in zip(directions[:, 2] < -np.cos(np.pi / 4), directions @ holder_in_object[:3, :3].T):
            for depth in s.push_depth * s.push.lever_shares:
                try:
                    push = rotation_push(self.surface, middle, holder_in_object[:3, 0], direction, -angle,
                                         depth, 0.0, s.push.slant_limit, s.edge_margin)
                except PushError as error:
                    problems.append(str(error))
                    continue
                if self._missed_before(push):
                    problems.append(f"the push at {np.round(push.point * 1000, 1).tolist()} mm (object frame) "
                                    "turned the pusher without the object before")
                    continue
                towards_palm = float((push.point - middle) @ palm)
                if towards_palm >= palm_room:
                    problems.append(f"the push at {np.round(push.point * 1000, 1).tolist()} mm is too far "
                                    "between the fingers towards the palm")
                    continue
                # Preferred in this order: beyond the tips, along the fingers, towards the palm; long levers first.
                ranked.append(((1 if along_fingers else 0 if towards_palm < 0 else 2, -depth), push))
        return [push for _, push in sorted(ranked, key=lambda entry: entry[0])]

    def _square_pushes(self, obs: Observation, motion: np.ndarray, holder_in_object: np.ndarray) -> list[np.ndarray]:
        """Directions (holder frame) square onto the faces round the grasp within `push.detour_limit` of `motion`
        and moving the object more than the tolerance along it: pushing along one slides the object
        without turning it."""
        pushes = self._face_pushes(obs, holder_in_object)
        # ... and one that would move the object less than the tolerance along the motion is no push.
        share = pushes @ motion
        wanted = ((share >= np.cos(self.settings.push.detour_limit) * float(np.linalg.norm(motion)))
                  & (share > self.settings.position_tolerance))
        return list(pushes[wanted])

    def _face_pushes(self, obs: Observation, holder_in_object: np.ndarray, height: float = 0.0) -> np.ndarray:
        """(k, 3) unit directions (holder frame, across the grasp axis) square onto the object's faces
        round the grasp axis `height` [m] along it from the grasp's middle, one per face."""
        count = self.settings.push.face_rays
        angles = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
        rays = np.column_stack([np.zeros(count), np.cos(angles), np.sin(angles)])     # holder frame
        normals = exit_normals(self.surface, _on_grasp_axis(holder_in_object, height), rays @ holder_in_object[:3, :3].T)
        pushes = -(normals[np.isfinite(normals).all(axis=1)] @ obs.object_in_holder[:3, :3].T)
        pushes[:, 0] = 0.0     # the face's tilt towards the grasp axis the fingers take
        lengths = np.linalg.norm(pushes, axis=1)
        pushes = pushes[lengths > 0.5] / lengths[lengths > 0.5, None]
        return pushes[np.unique(np.round(pushes, 2), axis=0, return_index=True)[1]]

    def _watched(self, obs: Observation, pushes: list, occluders: Occluders) -> list[tuple[_Push, int]]:
        """Routes for the push points that can be reached and that the camera sees from the push start."""
        if self.unreachable:
            directions = np.array([(obs.holder @ obs.object_in_holder)[:3, :3] @ push.direction for push in pushes])
            cone = np.cos(self.settings.campaign.unreachable_cone)
            near = (directions @ np.array(self.unreachable).T >= cone).any(axis=1)
            if near.all():
                raise PushError("the pusher could not get to where any push that would do it starts")
            pushes = [push for push, excluded in zip(pushes, near) if not excluded]
        candidates, problems = [], []
        for push in pushes:
            try:
                candidates.append(self._push_from(obs, push, occluders))
            except RouteError as error:
                problems.append(str(error))
        if not candidates:
            raise RouteError("; ".join(problems))
        if self.turns is None:
            return candidates
        watched = [c for c in candidates if c[1] > 0]
        # A translation is pushed on dead reckoning and looked at after; a rotation is not: unseen, nothing
        # tells that its pusher slid off, shoves the object across the fingers or turns in the air (sim:
        # the plug's blind far-side rotations dropped it in 4 of 6 runs).
        # (A level press unseen turns no further than the tilt it began with and the give, `level.press_give`.)
        if not watched and self.settings.blind_pushes and (self._primitive.kind == PrimitiveKind.TRANSLATION
                                                           or self._leveling):
            return candidates
        if not watched:
            raise PushError("the wrist camera would see none of the object's tags from where the push starts "
                            "(it would need the pusher behind the object)")
        return watched

    def _push_from(self, obs: Observation, push, occluders: Occluders) -> tuple[_Push, int]:
        """Route and orientations for a push point (object frame); how many tags the camera sees from its start."""
        s = self.settings
        holder = obs.holder
        object_pose = holder @ obs.object_in_holder
        point = apply(object_pose, push.point)
        direction = object_pose[:3, :3] @ push.direction
        box = self._keep_out(obs)
        to_holder = invert(holder)
        point_h = apply(to_holder, point)
        direction_h = to_holder[:3, :3] @ direction
        # Where the last stretch begins: a push comes in along its line; a straddle push along the pusher's
        # fingers, known once its orientation is (below).
        outside_h = (None if push.spread
                     else point_h - (box.exit_distance(point_h, -direction_h) + s.approach.exit_margin) * direction_h)
        if outside_h is not None and outside_h[2] < box.low[2]:
            # The line leaves the kept-free space through its palm end: the pusher would come up along
            # gripper 1's hand and arm (sim: 300 mm, 12 s with the object unseen, then OBJECT_LOST).
            raise RouteError(f"the push at {np.round(point_h * 1000, 1).tolist()} mm (holder frame) comes along "
                             "the holding gripper's hand from its palm side")
        provisional = point - (1.5 * s.tip_radius + s.gap) * direction     # the reach depends on the orientation
        if push.spread:
            views, seen = self._straddling_views(obs, provisional, direction, occluders)
        else:   # where the push starts, the tips must not be spread along the grasp axis
            views, seen = self._views(obs, provisional, level=holder[:3, 0], occluders=occluders, in_line=direction)
        # The best view whose hand keeps clear of the holding gripper (usually the first) and whose
        # fingertips start clear of the object: set back by the face's plane, a tip beside the face can be
        # inside another part of it (sim, a stepped block: a tip in the step where a push along a slanted
        # line started, met 13 mm before the start at 23 N on the way in, SLIP; the plug: a level press's
        # approach met a prong 7 mm early), and its way in goes through that part.
        normal, to_object = object_pose[:3, :3] @ push.normal, invert(object_pose)
        # A rotation's pusher, touching the push point, turns about the grasp axis: its tips must sweep into the
        # face there, not along it (sim, stepped block: tips beside the axis slid up the face past its edge,
        # eight pushes taken to have missed).
        sweeping = self._primitive.kind == PrimitiveKind.ROTATION and not self._leveling
        clashes = sweeps = 0
        for first, view in enumerate(views):
            start = push_start(point, normal, direction, view, s.tip_radius, s.gap, s.fingertips, s.push.slant_limit,
                               push.spread)
            clash = self._hands_clash(start, view, occluders)
            clashes += clash
            shells = fingertip_shells(view, s.tip_radius, s.fingertips.tip_clearance, push.spread)
            if clash or self.surface.inside(apply(to_object, start + shells)).any():
                continue
            near = from_rotation(view, start + (s.gap - s.fingertips.sweep_back) * direction)
            if sweeping and not np.isfinite(sweep_to_touch(self.surface, object_pose, near, holder, direction,
                                                           s.tip_radius, s.fingertips.sweep_limit, s.fingertips)):
                sweeps += 1
                continue
            break
        else:
            others = len(views) - sweeps
            what = ("the pusher's hand into the holding gripper" if clashes == others else
                    "a fingertip into the object" if clashes == 0 else
                    "the pusher's hand into the holding gripper or a fingertip into the object")
            sweep = ("sweep its tips along the face rather than into it as it turns about the grasp axis"
                     if sweeps else "")
            what = f"put {what}" + (f" or {sweep}" if sweep else "") if others else sweep
            raise RouteError(f"the push at {np.round(point_h * 1000, 1).tolist()} mm (holder frame) would {what} "
                             "however it is turned")
        views, seen = views[first:], seen[first:]
        start = meeting_start(start, views[0], direction, object_pose, self.surface, s.tip_radius, s.gap, s.fingertips,
                              push.spread)
        if push.spread:
            outside_h = self._straddle_entry(apply(to_holder, start), to_holder[:3, :3] @ views[0], push.spread, box,
                                             invert(obs.object_in_holder))
        pusher_h = apply(to_holder, obs.pusher[:3, 3])
        waypoints = [apply(holder, w) for w in self._route(pusher_h, outside_h, box, self._home_in(holder))]
        lever = float(np.linalg.norm(np.cross(point + s.tip_radius * normal - holder[:3, 3], holder[:3, 0])))
        orientations = [self._views(obs, place)[0][0] for place in waypoints[:-1]] + [views[0]] * 2
        return _Push(direction, direction_h, start, waypoints + [start], orientations, lever, push,
                     _distinct(views[1:][seen[1:] > 0], views[0], s.approach.other_views,
                                   s.approach.distinct_view), blind=self.turns is not None and seen[0] == 0), int(seen[0])

    def _straddling_views(self, obs: Observation, place: np.ndarray, direction: np.ndarray,
                          occluders: Occluders) -> tuple[np.ndarray, np.ndarray]:
        """The pusher orientations (best view first) at `place` (base frame) whose fingertips, opened, straddle
        gripper 1's fingers for a push along `direction` (base frame): the fingers along the grasp axis (either
        way), the tips spread across it and the push - rolled about the fingers from the nearest views the arm
        can take (`straddle.twist` at most) onto exactly that line."""
        views, seen = self._views(obs, place, occluders=occluders)
        grasp_axis = obs.holder[:3, 0]
        spread = np.cross(direction, grasp_axis)
        spread /= np.linalg.norm(spread)
        keep = ((np.abs(views[:, :, 0] @ spread) > np.cos(self.settings.straddle.twist))
                & (np.abs(views[:, :, 2] @ grasp_axis) > np.cos(self.settings.straddle.fingers)))
        if not keep.any():
            raise RouteError("no pusher orientation its arm can take puts its fingers along gripper 1's grasp axis "
                             "with the tips either side of gripper 1's fingers")
        views, seen = views[keep], seen[keep]
        fingers = views[:, :, 2]
        tips = spread - (fingers @ spread)[:, None] * fingers
        tips *= np.sign(views[:, :, 0] @ spread)[:, None] / np.linalg.norm(tips, axis=1, keepdims=True)
        return np.stack([tips, np.cross(fingers, tips), fingers], axis=2), seen

    def _straddle_entry(self, start_h: np.ndarray, orientation_h: np.ndarray, spread: float, box: KeepOut,
                        object_in_holder_inverse: np.ndarray) -> np.ndarray:
        """Where (holder frame) a straddle push's last stretch begins: out of the kept-free space along the
        pusher's fingers from its start, so that the open tips come in either side of gripper 1's fingers,
        clear of the object all the way (RouteError if not)."""
        s = self.settings
        fingers = orientation_h[:, 2]
        length = box.exit_distance(start_h, -fingers) + s.approach.exit_margin
        shells = fingertip_shells(orientation_h, s.tip_radius, s.fingertips.tip_clearance, spread)
        along = start_h - np.linspace(0.0, length, 12)[:, None] * fingers
        if self.surface.inside(apply(object_in_holder_inverse, (along[:, None, :] + shells[None]).reshape(-1, 3))).any():
            raise RouteError(f"the straddle push's open fingertips would meet the object on their way in to "
                             f"{np.round(start_h * 1000, 1).tolist()} mm (holder frame)")
        return start_h - length * fingers

    def _hands_clash(self, place: np.ndarray, orientation: np.ndarray, occluders: Occluders) -> bool:
        """Would the pusher with its tips at `place`, turned `orientation`, have its hand in the holding
        gripper or its fingers in that gripper's hand? (The arms do not collide in the simulation;
        they would on the robot.) Fingers near fingers are the keep-out box's business."""
        pusher = np.eye(4)
        pusher[:3, :3], pusher[:3, 3] = orientation, place
        return (overlap(placed(self.shape.hand(), pusher), occluders.fixed)
                or overlap(placed(occluders.riding, pusher), occluders.hand))

    def _views(self, obs: Observation, place: np.ndarray, level: np.ndarray | None = None,
               occluders: Occluders | None = None, in_line: np.ndarray | None = None,
               neutral: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Pusher orientations at `place` (turned from `neutral`, by default the orientation it
        started in), best view of the object's tags first, and how many tags each sees (without a
        camera model: only `neutral`, seeing none). `occluders` also checks what hides tags (10x the
        time): for push starts, where a push waits for a fresh pose; on the way there the held
        object may go unseen a while."""
        neutral = self.pusher_home[:3, :3] if neutral is None else neutral
        if self.turns is None:
            return neutral[None], np.zeros(1, int)
        scene = self.surface.scene if occluders is not None else None
        return ranked_views(self.camera, self.tags, obs.holder @ obs.object_in_holder, place, neutral, self.turns,
                            self.settings.views, level, occluders, scene, in_line)

    def _home_in(self, holder: np.ndarray) -> np.ndarray:
        """Where the pusher started (its camera's vantage point), in the holder's frame."""
        return apply(invert(holder), self.pusher_home[:3, 3])

    def _reach(self, direction: np.ndarray, orientation: np.ndarray) -> float:
        """How far the closed fingertips reach from the pusher's grasp frame along `direction`."""
        across = abs(float(direction @ orientation[:, 0]))   # the two tips sit side by side along its x
        return self.settings.tip_radius * (1.0 + across)

    def _approach(self, obs: Observation) -> Command:
        if obs.time < self.opened_at + self.settings.grip_settle:
            return Command()      # the pusher opening for a straddle push, where its last stretch begins
        command = self._along_route(obs)
        arrived = self._arrived(obs)
        if not arrived and self._stalled(obs):
            if not self._there_but_turned(obs):
                return self._give_up_push(obs)
            arrived = True
        if arrived:
            if self.push.homeward and not self._on_the_way:
                self._enter(Step.FIND_CONTACT, obs)
                return Command()
            if not self._on_the_way and obs.time - obs.object_time > self.settings.stale_after:
                waiting = self._look_again(obs)     # at the push start: a fresh pose first, if any view gives one
                if waiting is not None:
                    return waiting
            self.waiting_since = None
            self.waypoint += 1
            if self._push_spread and self.waypoint == len(self.push.waypoints) - 1:
                self.opened_at = obs.time
                return Command()
            if self.waypoint == len(self.push.waypoints):
                self._enter(Step.EXECUTE, obs)
                self.phase, self.pushed_reference = "loosen", None
                self.grip_until = obs.time + self.settings.grip_settle
                return Command(holder_grip=self._loosened(obs))
        return command

    def _next_start_view(self) -> None:
        """Turn the pusher at the push start to the next best view."""
        self.push.orientations[-1] = self.push.other_views.pop(0)

    def _give_up_push(self, obs: Observation) -> Command:
        """The arm cannot get where the push starts (a joint at its limit): at the push start, turn the
        camera another way; else give the push up, take the pusher back to where it started (its arm
        untangled) and plan another push from there, never again one this way."""
        if self.push.homeward:
            self._enter(Step.FIND_CONTACT, obs)      # not home, but as close as it gets: plan from here
            return Command()
        if not self._on_the_way and self.push.other_views:
            self._next_start_view()
            return Command()
        self.unreachable.append(self.push.direction)
        self.notes.append(f"a push of primitive {self.index} given up: the pusher came no closer to waypoint "
                          f"{self.waypoint + 1} of {len(self.push.waypoints)} in {self.settings.stall_time:.1f} s")
        try:
            self._head_home(obs)
        except RouteError:
            self._enter(Step.FIND_CONTACT, obs)
            return Command()
        self.push.homeward = True
        self._enter(Step.APPROACH, obs)
        return Command()

    def _look_around(self, obs: Observation) -> Command:
        """Look for the held object (it has not moved since it was last seen): turn the pusher where
        it stands through its best view and the others that see a tag, each for `stale_after` (seeking a
        certain pose: until a pose seen from it arrives); then
        go to the vantage places round the grasp axis the most tags are seen from
        (`_vantage_places`), up to `look.places`, and do the same at each. A view the arm stops more
        than `approach.view_short` short of drops the place's views further than that from where it got to.
        Seen from none, the run ends OBJECT_LOST with the grip closed. The search is bounded by its
        places and views (each given up when the arm stops turning towards it), not by how long the
        object goes unseen; the step's time limit counts afresh at each view and each place (it
        catches a look that makes no headway)."""
        if self.looking is None:
            place = obs.pusher[:3, 3].copy()
            views = [] if self._fruitless(obs, place) else self._look_views(obs, place, self.pusher_home[:3, :3])
            self.looking = _Look(place, views)
        look = self.looking
        self.unseen_from = obs.time
        if look.travelling:
            if self._arrived(obs) and self._on_the_way:
                self.waypoint += 1
            elif self._arrived(obs) or self._stalled(obs):     # (an arm at a limit: looks from where it got to)
                look.travelling, look.place = False, obs.pusher[:3, 3].copy()
                look.views = self._look_views(obs, look.place, self.push.orientations[-1])
            if look.travelling:
                return self._along_route(obs)
        if not look.views:
            return self._next_look_place(obs)
        command = self._go_to(obs, look.place, look.views[0])
        short = turn_between(look.views[0], obs.pusher[:3, :3])
        # (as far as the arm turns)
        if short < self.settings.approach.waypoint_turn_tolerance or self._stalled(obs, look.place, look.views[0]):
            if look.since is None:
                look.since = obs.time
            elif obs.time - look.since > self.settings.stale_after or (self.seeking_certain and self._seen_since(look.since)):
                # (seeking a certain pose, the first pose from a view is all it adds: the object is held still)
                if self.seeking_certain and self._certain_from_views(look):
                    return command
                look.views.pop(0)
                look.since, self.step_started = None, obs.time
                if short > self.settings.approach.view_short:
                    # The wrist is at a limit here: only views near where it got to are tried.
                    look.views = [view for view in look.views
                                  if turn_between(view, obs.pusher[:3, :3]) <= self.settings.approach.view_short]
        return command

    def _seen_since(self, since: float) -> bool:
        """Has a fresh pose from an image taken at or after `since` come?"""
        seen = self.last
        return seen.object_in_holder is not None and self._fresh(seen) and seen.object_time >= since

    def _certain_from_views(self, look: _Look) -> bool:
        """Looking for a certain pose: take the pose seen from this view since the pusher got there; once the
        mean of those from the last `look.view_poses` views is certain of its position (independent errors:
        sigma / sqrt(n)), hold it and end the look (sim, plug: every view of 15 at three places gave
        1.0-1.3 mm against a 1 mm limit, 38 s of looking for nothing better)."""
        seen = self.last
        if not self._seen_since(look.since):
            return False
        look.poses.append((seen.object_in_holder.copy(), seen.object_position_sigma))
        # (views from one place see much alike: no more than a few count)
        taken = look.poses[-self.settings.look.view_poses:]
        poses = np.array([pose for pose, _ in taken])
        sigma = float(np.linalg.norm([sigma for _, sigma in taken])) / len(poses)
        if len(poses) < 2 or sigma > self.settings.slip_position_sigma:
            return False
        self.held.take_mean(poses, sigma, seen.object_time)
        self.searching = self.seeking_certain = False
        self.notes.append(f"primitive {self.index} judged from the mean of {len(poses)} poses seen from as many "
                          f"views ({sigma * 1000:.1f} mm)")
        return True

    def _look_views(self, obs: Observation, place: np.ndarray, neutral: np.ndarray) -> list[np.ndarray]:
        """The best pusher orientation at `place` (turned from `neutral`) and the distinct others a tag is
        seen from, best first (the best is tried even if the model sees no tag from it)."""
        views, seen = self._views(obs, place, occluders=Occluders.of(self.shape, obs.holder, obs.opening),
                                  neutral=neutral)
        return [views[0]] + _distinct(views[1:][seen[1:] > 0], views[0], self.settings.approach.other_views,
                                   self.settings.approach.distinct_view)

    def _next_look_place(self, obs: Observation) -> Command:
        """On to the next vantage place the pusher can be routed to; after the last, OBJECT_LOST (or, looking
        for a certain pose of an object seen, on with the uncertain one)."""
        look = self.looking
        if not self._fruitless(obs, look.place):
            self.fruitless.append(apply(invert(obs.holder), look.place))
        if look.places is None:
            look.places = self._vantage_places(obs)
        while look.places and look.gone_to < self.settings.look.places:
            place, orientation = look.places.pop(0)
            try:
                self._route_to(obs, apply(invert(obs.holder), place), orientation)
            except RouteError:
                continue
            look.gone_to += 1
            look.travelling, look.place, look.since = True, place, None
            self.step_started = obs.time
            return self._along_route(obs)
        if self.seeking_certain:     # seen, if not for certain: judged from what was seen
            self.searching = self.seeking_certain = False
            self.notes.append(f"primitive {self.index} judged from a pose uncertain by {self.held.sigma * 1000:.1f} mm: "
                              f"none of {look.gone_to} vantage place(s) gave a certain one")
            return Command()
        return self._abort(Outcome.OBJECT_LOST, f"object pose lost (last seen {obs.time - obs.object_time:.1f} s ago): "
                           f"not seen from where the pusher stood nor from {look.gone_to} vantage place(s) round "
                           f"it, during {self.step.name} of primitive {self.index}: stopped, gripper 1 closed at "
                           "the hold force")

    def _vantage_places(self, obs: Observation) -> list[tuple[np.ndarray, np.ndarray]]:
        """Where the pusher started, turned `look.turns` round the holder's grasp axis (its x, through the
        grasp's middle: what a rotation turns the object about) with the pusher's orientation turned
        alike, each moved just clear of the space kept free if inside it (as the object turned in the
        grip, that space grew): those within the workspace's limits that the view model sees a tag
        from, with their best view, most tags first, then nearest; where it started (the camera saw
        the object from there first) always, last if the model sees no tag from there."""
        s = self.settings
        box = self._keep_out(obs)
        occluders = Occluders.of(self.shape, obs.holder, obs.opening)
        home, axes = self._home_in(obs.holder), obs.holder[:3, :3]
        found, taken = [], [obs.pusher[:3, 3]]     # (places this close to one taken are that one)
        for angle in s.look.turns:
            turn = Rotation.from_rotvec([angle, 0.0, 0.0]).as_matrix()
            place = apply(obs.holder, box.nearest_outside(turn @ home))
            if (np.linalg.norm(np.array(taken) - place, axis=1).min() < s.look.same_place
                    or np.any(place < s.workspace_min) or np.any(place > s.workspace_max)):
                continue
            away = float(np.linalg.norm(place - obs.pusher[:3, 3]))
            views, seen = self._views(obs, place, occluders=occluders,
                                      neutral=axes @ turn @ axes.T @ self.pusher_home[:3, :3])
            if seen[0] > 0 or angle == 0.0:
                found.append((self._fruitless(obs, place), -int(seen[0]), away, place, views[0]))
                taken.append(place)
        found.sort(key=lambda item: item[:3])
        return [(place, view) for *_, place, view in found]

    def _tilt_off_goal(self, object_in_holder: np.ndarray) -> np.ndarray:
        """Rotation vector (holder frame, across the grasp axis) that would turn the object from
        `object_in_holder` so that the grasp axis lies on it as the goal grasp's does."""
        turn = Rotation.from_matrix(self._target()[:3, :3] @ object_in_holder[:3, :3].T).as_rotvec()
        turn[0] = 0.0
        return turn

    def _needs_leveling(self, obs: Observation) -> bool:
        """After the plan (once a run): is the grasp outside the goal's tolerances (as the run's end judges
        it; the principal contact's error takes in the tilt times the contact's distance from the grasp's
        middle) with its axis certainly tilted more than `level_tilt` off the goal's? Only then: each turn
        of the holder a press needs shifts the object ~1 mm in the grip (sim: box, plug)."""
        s = self.settings
        position, angle = self.final_errors(obs)
        return (self.level_index is None and s.level_tilt > 0.0 and obs.object_tilt_sigma <= s.slip_tilt_sigma
                and (position > s.goal_position_tolerance or angle > s.goal_angle_tolerance)
                and np.linalg.norm(self._tilt_off_goal(obs.object_in_holder)) > s.level_tilt)

    @property
    def _leveling(self) -> bool:
        return self.level_index is not None and self.index == self.level_index

    def _fruitless(self, obs: Observation, place: np.ndarray) -> bool:
        """Has a look at `place` (base frame) seen nothing before, in this run? Places are kept in the
        holder's frame, so they move with the grasp; the small pushes between looks leave what a
        place sees much as it was (sim, bracket: four looks of one run each began at the same two
        blind places, 13 s each, before the third place saw a tag)."""
        here = apply(invert(obs.holder), place)
        return any(np.linalg.norm(here - old) < self.settings.look.fruitless_near for old in self.fruitless)

    def _look_again(self, obs: Observation) -> Command | None:
        """Wait at the push start for a fresh pose; when none comes within `stale_after`, turn the
        pusher to the next best view (the view model missed something that hides the tags). After
        the last view, None: push blind from the last pose (held since it was seen), if allowed."""
        if self.waiting_since is None:
            self.waiting_since = obs.time
        elif obs.time - self.waiting_since > self.settings.stale_after:
            if self.push.other_views:
                self._next_start_view()
                self.waiting_since = None
            elif self.settings.blind_pushes:
                self.push.blind = True
                return None
        return Command()

    def _execute(self, obs: Observation) -> Command:
        s = self.settings
        primitive = self.primitives[self.index]
        if self.phase == "loosen":
            if obs.time < self.grip_until:
                return Command(holder_grip=self._held() if self._leveling else self._loosened(obs))
            self.phase = "push"
            self.held.reference = None
            # A level press the camera sees needs no turn back to be judged: the next is planned as the holder stands.
            self.pressed_turned = self.far_side and self._leveling and not self.push.blind
            self.far_side_pushed = self.far_side and not self.pressed_turned
            self.pushed_reference = self._push_reference(obs)
            self.pushed_opening = obs.opening
            pusher = invert(obs.holder) @ obs.pusher
            self.pushed_from, self.pushed_along, self.turn_mark = pusher.copy(), self.push.local_direction.copy(), None
            self.pushed_point = self.push.contact
            # The pusher's tip stands `gap` short of the push point; it meets the face there (or further
            # on, where blind pushes this way fell short).
            along = self.push.local_direction
            face = apply(obs.object_in_holder, self.push.contact.point)
            self.reckoning = Reckoning(self.pushed_reference.copy(), pusher, apply(invert(pusher), face - s.gap * along),
                                       face + self._shortfall(along) * along,
                                       np.zeros(3) if self._leveling else along.copy(),   # (a level push: believed unmoved)
                                       turning=primitive.kind == PrimitiveKind.ROTATION)
            self.reckoning.moved(obs.time, pusher)
            # Close the gap along the push line first, at push speed: turning from `gap` away, a rotation's
            # pusher would mostly slide past the face (its arc is tangent to the face, not into it); a
            # translation's P control would take seconds over it. A translation stops `touch_margin`
            # short of where the face is believed to be: the P-controlled push meets it. Either stops
            # where the camera sees the object move: the face was nearer than believed (a rotation's
            # pusher went on to shove the box 5 mm across the fingers and, turning, out of them).
            self.phase = "touch"
        if self.phase == "touch":
            closed = float((apply(invert(obs.holder), obs.pusher[:3, 3]) - self.pushed_from[:3, 3]) @ self.push.local_direction)
            short = s.touch_margin if primitive.kind == PrimitiveKind.TRANSLATION and not self._leveling else 0.0
            seen = self.reckoning.pose
            met = _slid_since(self.pushed_reference, seen) > s.push.touched
            if self._leveling:     # or pressed back about the level axis (pose noise reaches 0.5 deg; the turn about
                # the grasp axis, 1.4 deg between two poses of a still bracket, is none of the press's business)
                met = met or self._level_left(self.pushed_reference) - self._level_left(seen) > s.push.turn_gain
            else:
                met = met or abs(_turned_since(self.pushed_reference, seen)) > s.push.turn_gain
            if closed < s.gap - short and not met:
                command = self._coordinated(obs, np.concatenate([s.push_speed * self.push.direction, np.zeros(3)]))
                command.holder_grip = self._held() if self._leveling else self._loosened(obs)
                return command
            self.phase = "push"
            if primitive.kind == PrimitiveKind.ROTATION and not self._leveling:
                sweep = sweep_to_touch(self.surface, obs.holder @ seen, obs.pusher, obs.holder,
                                       obs.holder[:3, :3] @ self.push.local_direction, s.tip_radius, 2 * s.push.missed_turn,
                                       s.fingertips)
                self.sweep_to_face = sweep if np.isfinite(sweep) else 0.0
        if self.phase == "tighten":
            if obs.time < self.grip_until:
                return Command()
            self.pushes += 1
            self._enter(Step.LEAVE, obs)
            return Command()
        holder = obs.holder
        if self._leveling:
            return self._press_level(obs)
        forced = obs.opening - max(self.pushed_opening, self.widest_grasp)
        if forced > s.monitors.forced_open:
            return self._stop_push(obs, f"the object forced gripper 1's fingers {forced * 1000:.1f} mm wider than its "
                                        "grasp (turning over in the grip)")
        tilted = tilt_since(self.pushed_reference, obs.object_in_holder) if self._fresh(obs) else 0.0
        if (s.monitors.push_tilt_stop * s.slip_angle < tilted <= s.slip_angle
                and obs.object_tilt_sigma <= s.slip_tilt_sigma):
            return self._stop_push(obs, f"the object tilted {np.rad2deg(tilted):.1f} deg off the grasp axis")
        if primitive.kind == PrimitiveKind.TRANSLATION:
            along = float(self._remaining_motion(obs) @ (holder[:3, :3].T @ self.push.direction))
            if along <= s.position_tolerance:
                return self._tighten(obs)
            speed = float(np.clip(s.linear_gain * along, s.min_push_speed, s.push_speed))
            # Keep the push line through the grasp axis: an offset across it would turn the object.
            across = np.cross(self.push.direction, holder[:3, 0])
            touching = obs.pusher[:3, 3] + leading_tip(self.push.direction, obs.pusher[:3, :3], s.tip_radius,
                                                       s.fingertips.leading_tip)
            offset = float((touching - holder[:3, 3]) @ across)
            relative = np.concatenate([speed * self.push.direction - s.approach_gain * offset * across
                                       + self._tilt_slide(obs) * holder[:3, 0], np.zeros(3)])
        else:
            turn = self.errors[1]
            turned = _turned_since(self.pushed_reference, obs.object_in_holder)
            budget = float(np.clip(turn + turned, -s.max_push_angle, s.max_push_angle))   # this push's share
            left = budget - turned
            if abs(turn) <= s.angle_tolerance or left * np.sign(budget) <= s.angle_tolerance / 2:
                return self._tighten(obs)
            pusher_turned = abs(_turned_since(self.pushed_from, invert(obs.holder) @ obs.pusher))
            stalled = self._turn_stalled(pusher_turned, turned)
            missed = self.turn_mark is None and pusher_turned > self.sweep_to_face + s.push.missed_turn
            if (stalled and abs(turned) < s.push.turn_gain) or missed:
                # No turn to show for it (a stall after a noise 'gain', or none at all): turning in the air.
                self._mark_missed(f"a rotation push of primitive {self.index} missed the object (it turned "
                                  f"{np.rad2deg(turned):.1f} deg): not tried there again")
                return self._tighten(obs)
            if stalled:
                self.notes.append(f"a rotation push of primitive {self.index} stopped after {np.rad2deg(turned):.1f} deg: "
                                  f"the object stopped turning with the pusher")
                return self._tighten(obs)
            slid = _slid_since(self.pushed_reference, obs.object_in_holder)
            if slid > s.rotation_slide:
                self.notes.append(f"a rotation push of primitive {self.index} stopped after {np.rad2deg(turned):.1f} deg: "
                                  f"the object slid {slid * 1000:.1f} mm in the grip")
                return self._tighten(obs)
            lever = max(self.push.lever, 1e-3)
            rate = float(np.clip(s.angular_gain * abs(left), s.min_push_speed / lever,
                                 min(s.max_angular_speed, s.push_speed / lever)))
            relative = np.concatenate([np.zeros(3), np.sign(left) * rate * holder[:3, 0]])   # about the grasp axis
        command = self._coordinated(obs, relative)
        command.holder_grip = self._loosened(obs)
        return command

    def _press_level(self, obs: Observation) -> Command:
        """Turn the object about `level_axis` through the grasp's middle, the grip held, under P control on
        the tilt left along that axis; stop when it is under `level.done`, or once the pusher has turned the
        tilt the press began with and the slack its tip may meet the face late by (seen: `level.slack`, the
        seen tilt stops it first; unseen: only the give before the object moves, `level.press_give`)."""
        s = self.settings
        left, began = self._level_left(obs.object_in_holder), self._level_left(self.pushed_reference)
        pusher_turned = turn_between((invert(obs.holder) @ obs.pusher)[:3, :3], self.pushed_from[:3, :3])
        lever = max(self.push.lever, 1e-3)
        slack = (s.level.press_give if self.reckoning.blind else s.level.slack) / lever
        if left <= s.level.done or pusher_turned > began + slack:
            return self._tighten(obs)
        slid = _slid_since(self.pushed_reference, obs.object_in_holder)
        if slid > s.level.slide:
            self.notes.append(f"a level press of primitive {self.index} stopped: the grasp slid {slid * 1000:.1f} mm "
                              "on the object (shoved across the fingers, not rolled on them)")
            return self._tighten(obs)
        rate = float(np.clip(s.angular_gain * left, s.min_push_speed / lever, min(s.max_angular_speed, s.push_speed / lever)))
        command = self._coordinated(obs, np.concatenate([np.zeros(3), rate * (obs.holder[:3, :3] @ self.level_axis)]))
        command.holder_grip = self._held()
        return command

    def _level_left(self, object_in_holder: np.ndarray) -> float:
        """rad of tilt off the goal's grasp axis that a press has still to turn back: along the way the object
        is seen turning once it has turned `push.turn_gain` since the press began (about the way it should), before
        that along `level_axis`.
        A press turns the object about an axis of its own (sim, bracket: pushed to turn it about an axis 30
        deg off the tilt's, it turned about one 43 deg off, and pressed on until the tilt along the tilt's
        axis was gone, it ended as tilted as it began); along the way it turns, the tilt is least where
        none is left."""
        tilt = self._tilt_off_goal(object_in_holder)
        turned = self._tilt_off_goal(self.pushed_reference) - tilt
        way = float(np.linalg.norm(turned))
        seen_way = way > self.settings.push.turn_gain and float(turned @ self.level_axis) > 0.0
        return float(tilt @ (turned / way if seen_way else self.level_axis))

    def _turn_stalled(self, pusher_turned: float, turned: float) -> bool:
        """Has the pusher turned `turn_stall` on since the object last gained `push.turn_gain` with it? Then it
        no longer turns the object but shoves it out of the grip (sim: bracket and plug stuck at 31 deg
        - the pusher slid along the face into a corner - then 8-38 deg of tilt within 0.5 s). Counted
        from the object's first gain: the pusher takes up the contact's slack first. Both in rad, absolute."""
        mark = self.turn_mark
        if abs(turned) >= (self.settings.push.turn_gain if mark is None else mark[1] + self.settings.push.turn_gain):
            self.turn_mark = (pusher_turned, abs(turned))
            return False
        return mark is not None and pusher_turned - mark[0] > self.settings.turn_stall

    def _mark_missed(self, note: str) -> None:
        """The pusher turned without turning the object: that push is not planned again."""
        if self.pushed_point is not None:
            self.missed.append(self.pushed_point)
        self.notes.append(note)

    def _missed_before(self, push: PushPoint) -> bool:
        near, aligned = (self.settings.push.missed_near_distance, np.cos(self.settings.push.missed_near))
        return any(np.linalg.norm(push.point - m.point) < near and float(push.direction @ m.direction) > aligned
                   for m in self.missed)

    def _tilt_slide(self, obs: Observation) -> float:
        """Pusher speed [m/s] along the grasp axis that steers a translated object's tilt back
        (`tilt_steering`), from fresh poses certain of their tilt only."""
        s = self.settings
        if (s.tilt_gain == 0.0 or self.reckoning.blind or obs.object_tilt_sigma > s.slip_tilt_sigma
                or obs.time - obs.object_time > s.stale_after or self._push_spread):
            return 0.0      # (a straddle push's tips slid along the grasp axis would leave the face beside the fingers)
        tilt = turn_since(self.pushed_reference, obs.object_in_holder)
        pusher = invert(obs.holder) @ obs.pusher
        local = self.push.local_direction
        lever = -float(pusher[:3, 3] @ local) - self._reach(local, pusher[:3, :3])
        steer = tilt_steering(tilt, local, lever, s.grip_friction * obs.opening / 2)
        return float(np.clip(s.tilt_gain * steer, -s.tilt_speed, s.tilt_speed))

    def _stop_push(self, obs: Observation, why: str) -> Command:
        """End the push early, saying why in the result; the rest is planned from where the object is."""
        self.notes.append(f"a push of primitive {self.index} stopped: {why}")
        return self._tighten(obs)

    def _tighten(self, obs: Observation) -> Command:
        self.phase = "tighten"
        self.grip_until = obs.time + self.settings.grip_settle
        return Command(holder_grip=self._held())

    def _coordinated(self, obs: Observation, relative: np.ndarray) -> Command:
        """ECTS: the relative motion as a twist at the grasp axis, split by alpha, each arm's share
        expressed at its own grasp frame."""
        origin = obs.holder[:3, 3]
        holder_twist, pusher_twist = arm_twists(np.zeros(6), relative, self.alpha)
        return Command(holder=_shift(holder_twist, origin, origin), pusher=_shift(pusher_twist, origin, obs.pusher[:3, 3]))

    def _leave(self, obs: Observation) -> Command:
        if not self.retreat:
            # Back out along the push line as the object now lies (a rotation turned it with the pusher); a
            # straddle push's pusher backs off the face by `gap`, then out along its fingers the way it came in.
            turned = 0.0 if self.pushed_reference is None else _turned_since(self.pushed_reference, obs.object_in_holder)
            local = Rotation.from_rotvec([turned, 0.0, 0.0]).apply(self.push.local_direction)
            box = self._keep_out(obs)
            to_holder = invert(obs.holder)
            pusher = apply(to_holder, obs.pusher[:3, 3])
            if self._push_spread:
                backed = pusher - self.settings.gap * local
                fingers = to_holder[:3, :3] @ obs.pusher[:3, 2]
                out = box.exit_distance(backed, -fingers) + self.settings.approach.exit_margin
                path = [backed, backed - out * fingers]
            else:
                path = [pusher - (box.exit_distance(pusher, -local) + self.settings.approach.exit_margin) * local]
            self.retreat = [apply(obs.holder, point) for point in path]
        short = float(np.linalg.norm(self.retreat[0] - obs.pusher[:3, 3]))
        if short < self.settings.waypoint_tolerance or self._stalled(obs, self.retreat[0]):
            # Stuck on the way out (sim: 25 s in LEAVE after the last push, the grasp within tolerance),
            # the next route starts from here.
            if short >= self.settings.waypoint_tolerance:
                self.notes.append(f"after a push of primitive {self.index} the pusher stopped backing out "
                                  f"{short * 1000:.0f} mm short")
            self.retreat = self.retreat[1:]
            if not self.retreat:
                self._enter(Step.FIND_CONTACT, obs)
            return Command()
        return self._go_to(obs, self.retreat[0], through=True)

    def _keep_out(self, obs: Observation) -> KeepOut:
        s = self.settings
        return keep_out(self.surface.vertices, obs.object_in_holder, obs.opening, s.tip_radius, 2 * s.tip_radius,
                        s.clearance, s.approach.palm_reach)

    def _route(self, start: np.ndarray, goal: np.ndarray, box: KeepOut, prefer: np.ndarray | None = None
               ) -> list[np.ndarray]:
        """Waypoints (holder frame) round the keep-out box, with this executor's route rules."""
        rules = self.settings.approach
        return route(start, goal, box, prefer, escape_depth=rules.escape_depth, far_side_cost=rules.far_side_cost)

    def _head_home(self, obs: Observation, clear_of_turn: bool = False) -> None:
        """Route the pusher back to where it started (RouteError if there is none); before the holder
        turns the object, at least out of the turning object's reach (with gripper 1 moving in the
        pushes, at alpha < 1, the start may have come within it)."""
        goal = self._home_in(obs.holder)
        if clear_of_turn:
            radius, needed = float(np.hypot(*goal[:2])), self._turn_radius(obs) + self.settings.clearance
            if radius < needed:
                outward = goal[:2] if radius > 1e-6 else apply(invert(obs.holder), obs.pusher[:3, 3])[:2]
                goal[:2] = outward / np.linalg.norm(outward) * needed
        self._route_to(obs, goal, self.pusher_home[:3, :3])

    def _route_to(self, obs: Observation, goal: np.ndarray, orientation: np.ndarray) -> None:
        """Route the pusher to `goal` (holder frame; a goal inside the space kept free moves just clear
        of it: a run that began next to the object ends there), turned to `orientation` there and
        its camera on the object on the way (RouteError if there is no route). A pusher inside that
        space on a push's line (its start in a hollow of the object, the pusher on its way in) first
        backs out along the line, the way it came (sim, a stepped block: stopped on that line, unseen,
        44 mm inside the space, no route out - the run ended LIMIT_VIOLATION)."""
        box = self._keep_out(obs)
        start = apply(invert(obs.holder), obs.pusher[:3, 3])
        goal = box.nearest_outside(goal)
        back = []
        along = self.push.local_direction if self.push is not None else np.zeros(3)
        if box.contains(start)[0] and np.any(along):
            start = start - (box.exit_distance(start, -along) + self.settings.approach.exit_margin) * along
            back = [apply(obs.holder, start)]
        places = back + [apply(obs.holder, w) for w in self._route(start, goal, box, goal)]
        orientations = [self._views(obs, place)[0][0] for place in places[:-1]] + [orientation]
        self.push = _Push(np.zeros(3), np.zeros(3), places[-1], places, orientations, 0.0)
        self.waypoint = 0

    def _finish_plan(self, obs: Observation) -> Command:
        """All primitives done: the pusher goes back to where it started, then the result."""
        if not self.returning:
            self.returning = True
            self.step, self.step_started = Step.LEAVE, obs.time
            if self.held.reference is None:
                self.held.take(obs)
            try:
                self._head_home(obs)
            except RouteError as error:
                return self._abort(Outcome.LIMIT_VIOLATION, f"cannot return the pusher: {error}")
        stalled = self._stalled(obs)
        if self._arrived(obs) or stalled:
            if stalled:     # its arm at a limit (sim: 25 s at the last waypoint, then STEP_TIMEOUT): done here
                short = np.linalg.norm(self.push.waypoints[-1] - obs.pusher[:3, 3])
                self.notes.append(f"the pusher stopped {short * 1000:.0f} mm short of where it started")
                self.waypoint = len(self.push.waypoints) - 1
            self.waypoint += 1
            if self.waypoint == len(self.push.waypoints):
                position, angle = self.final_errors(obs)
                corrections = len(self.primitives) - self.plan_length
                s = self.settings
                within = position <= s.goal_position_tolerance and angle <= s.goal_angle_tolerance
                summary = (f"{self.plan_length} primitives and {corrections} corrections done: contact "
                           f"{position * 1000:.1f} mm and {np.rad2deg(angle):.1f} deg from the goal")
                if not within:
                    summary += (f", outside the tolerance of {s.goal_position_tolerance * 1000:.1f} mm and "
                                f"{np.rad2deg(s.goal_angle_tolerance):.1f} deg")
                self._finish(Outcome.OK if within else Outcome.OUT_OF_TOLERANCE,
                             "; ".join([summary] + self.notes), position, angle)
                return self._halt()
        return self._along_route(obs)

    # --- motion helpers
    def _stalled(self, obs: Observation, target: np.ndarray | None = None,
                 orientation: np.ndarray | None = None) -> bool:
        """Has the pusher come no closer to `target` (turned to `orientation`, if given; by default the
        current waypoint, turned as wanted there) for `stall_time`?"""
        if target is None:
            target, orientation = self.push.waypoints[self.waypoint], self.push.orientations[self.waypoint]
        offset = float(np.linalg.norm(target - obs.pusher[:3, 3]))
        turn = 0.0 if orientation is None else turn_between(orientation, obs.pusher[:3, :3])
        key = target.tobytes() + (b"" if orientation is None else orientation.tobytes())
        headway = self.headway
        gain = self.settings.approach
        if (headway is None or headway.target != key or offset < headway.offset - gain.headway_distance
                or turn < headway.turn - self.settings.approach.headway_turn):
            self.headway = _Headway(key, offset, turn, obs.time)
            return False
        return obs.time - headway.since > self.settings.stall_time

    def _arrived(self, obs: Observation) -> bool:
        """The pusher is at the current waypoint, turned as wanted there."""
        offset = np.linalg.norm(self.push.waypoints[self.waypoint] - obs.pusher[:3, 3])
        turn = turn_between(self.push.orientations[self.waypoint], obs.pusher[:3, :3])
        # (where a push starts: on its line, precisely)
        tolerance = self.settings.waypoint_tolerance if self._on_the_way else self.settings.position_tolerance
        return offset < tolerance and turn < self.settings.approach.waypoint_turn_tolerance

    @property
    def _on_the_way(self) -> bool:
        """Is the pusher's current waypoint one on the way (not the last of its route)?"""
        return self.waypoint < len(self.push.waypoints) - 1

    def _there_but_turned(self, obs: Observation) -> bool:
        """Is the pusher at a waypoint on the way, only not turned as wanted there? That turn is a view
        of the object on the way, not needed to go on (sim, bracket: two wrist joints 1 deg from their
        limits 1 mm from the waypoint; the push was given up after `stall_time`, and gripper 1 sent back
        and turned half round for another)."""
        return self._on_the_way and float(np.linalg.norm(self.push.waypoints[self.waypoint] - obs.pusher[:3, 3])) < \
            self.settings.waypoint_tolerance

    def _along_route(self, obs: Observation) -> Command:
        """Towards the current waypoint of the pusher's route: through the ones on the way, onto the last."""
        return self._go_to(obs, self.push.waypoints[self.waypoint], self.push.orientations[self.waypoint],
                           self._on_the_way)

    def _go_to(self, obs: Observation, target: np.ndarray, orientation: np.ndarray | None = None,
               through: bool = False) -> Command:
        """P control of the pusher towards a position (and orientation), speeds limited. Going `through`
        (a waypoint on the way), at full speed until within its tolerance: P control's slow tail at
        each waypoint took about a second."""
        s = self.settings
        offset = target - obs.pusher[:3, 3]
        velocity = _limited(s.approach_gain * offset, s.approach_speed,
                            through and np.linalg.norm(offset) > s.waypoint_tolerance)
        angular = np.zeros(3)
        if orientation is not None:
            turn = Rotation.from_matrix(orientation @ obs.pusher[:3, :3].T).as_rotvec()
            angular = _limited(s.approach_gain * turn, s.max_angular_speed,
                               through and np.linalg.norm(turn) > s.approach.waypoint_turn_tolerance)
        return Command(pusher=np.concatenate([velocity, angular]))

    def _loosened(self, obs: Observation) -> GripCommand:
        """P control of the finger distance towards just inside the object's width, at the slide force,
        or at what keeps the object's weight from tilting it off the grasp axis if that is more."""
        s = self.settings
        wanted = max(obs.opening - s.slide_squeeze, 0.0)
        opening = obs.opening + s.finger_gain * (wanted - obs.opening)
        tilt_hold = s.tilt_hold_margin * tilt_hold_force(obs.object_in_holder, obs.holder[:3, :3],
                                                         self.surface.centre_of_mass, self.surface.mass,
                                                         obs.opening, s.grip_friction)
        return GripCommand(max(opening, 0.0), float(np.clip(tilt_hold, s.slide_force, s.hold_force)))

    def _held(self) -> GripCommand:
        return GripCommand(0.0, self.settings.hold_force)

    def _halt(self) -> Command:
        return Command(holder_grip=self._held())

    # --- measurements and safety -----------------------------------------------------------------------
    def _target(self) -> np.ndarray:
        """Object pose in the holder's frame that completes the current primitive."""
        return invert(self._primitive.gripper_after)

    @property
    def _primitive(self) -> Primitive:
        """The primitive being done (the last one once all are: corrections aim at its goal)."""
        return self.primitives[min(self.index, len(self.primitives) - 1)]

    def _judge_blind_push(self, obs: Observation) -> None:
        """The first pose seen after a blind push. A translation that dead reckoning had moving the object
        further than the tolerance: if the pose shows it moved more than half the tolerance less (or
        more) along the push, and not turned with it, the pusher met the face that much further on
        (or nearer) than believed - the pose it was placed by lay short along the push, and the
        pusher goes ~0.9 mm past a face before the object gives way (a small correction would
        repeat the same miss). Pushes this way from now on count the object as met that much
        further on. A rotation that did not turn the object at all
        while dead reckoning had it turned missed the face (sim: the plug's far side, the same push
        planned five times): it is not planned again."""
        if self.reckoning is None or not self.reckoning.blind or self.pushed_reference is None or self._leveling:
            return
        if self._primitive.kind == PrimitiveKind.ROTATION:
            believed = _turned_since(self.pushed_reference, self.reckoned)
            seen = _turned_since(self.pushed_reference, obs.object_in_holder)
            if abs(believed) > 2 * self.settings.push.turn_gain and abs(seen) < self.settings.push.turn_gain:
                self._mark_missed(f"a blind rotation push of primitive {self.index} did not turn the object (turned "
                                  f"{np.rad2deg(seen):.1f} deg, believed {np.rad2deg(believed):.1f} deg): not tried there again")
            return
        direction = self.pushed_along
        believed = float((self.reckoned[:3, 3] - self.pushed_reference[:3, 3]) @ direction)
        seen = float((obs.object_in_holder[:3, 3] - self.pushed_reference[:3, 3]) @ direction)
        tolerance = self.settings.position_tolerance
        reached = seen >= tolerance / 2
        turned = abs(_turned_since(self.pushed_reference, obs.object_in_holder))
        if reached and turned > self.settings.campaign.partial_miss_turn:
            return     # the push turned the object too: what it lost along the push is not where it met the face
        if believed > tolerance and abs(believed - seen) > tolerance / 2:
            self.shortfalls.append((direction.copy(), min(believed - seen, self.settings.gap)))
            what = ("moved the object further than believed" if seen > believed else
                    "moved the object less than believed" if reached else "did not reach the object")
            self.notes.append(f"a blind push of primitive {self.index} {what} (moved {seen * 1000:.1f} mm, believed "
                              f"{believed * 1000:.1f} mm): pushes that way now reach "
                              f"{self._shortfall(direction) * 1000:.1f} mm further")

    def _shortfall(self, direction: np.ndarray) -> float:
        """How much further on than its pose says the object has been met by blind pushes this way (0 to `gap`)."""
        cone = np.cos(self.settings.campaign.shortfall_cone)
        extra = sum(amount for past, amount in self.shortfalls if float(past @ direction) >= cone)
        return float(np.clip(extra, 0.0, self.settings.gap))

    def _remaining_motion(self, obs: Observation) -> np.ndarray:
        """Object displacement (holder frame) still needed, across the grasp axis only."""
        goal_middle = self._primitive.gripper_after[:3, 3]
        where = apply(obs.object_in_holder, goal_middle)
        motion = -where
        motion[0] = 0.0       # along the grasp axis the fingers centre the object
        return motion


    def _measure(self, obs: Observation) -> None:
        if not self.primitives:
            self.errors = (0.0, 0.0)
            return
        target = self._target()
        self.errors = (float(np.linalg.norm(self._remaining_motion(obs))),
                       _rotation_about_axis(target[:3, :3] @ obs.object_in_holder[:3, :3].T))

    def principal_contact(self, obs: Observation) -> np.ndarray:
        """Where the principal finger touches the object, in the object frame, as perceived."""
        if obs.object_in_holder is None:
            return np.full(3, math.nan)
        side = -1.0 if self.principal_finger == 0 else 1.0
        return apply(invert(obs.object_in_holder), [side * obs.opening / 2, 0.0, 0.0])

    def final_errors(self, obs: Observation) -> tuple[float, float]:
        """(principal contact vs the goal contact [m], gripper orientation vs the goal's [rad])."""
        if not self.primitives or obs.object_in_holder is None:
            return (0.0, 0.0) if not self.primitives else (math.nan, math.nan)
        last = self.primitives[-1]
        return (float(np.linalg.norm(self.principal_contact(obs) - last.contact_after)),
                distance(invert(obs.object_in_holder), last.gripper_after)[1])

    def _limits(self, obs: Observation) -> tuple[Outcome, str] | None:
        why = limit_violation(obs, self.holder_start, self.settings)
        return None if why is None else (Outcome.LIMIT_VIOLATION, why)

    def _slip(self, obs: Observation) -> tuple[Outcome, str] | None:
        """A slip once `slip_poses` poses in a row show one: a single stray estimate is none. Nor is a held
        reference that rests on one pose, where the poses in a row agree with each other: that pose was the
        stray one, and the grip's reference is taken again (sim, box: the first pose after a blind push 5.3 mm
        and 5.0 deg off, 0.75 mm sure of itself, then good poses 0.3-0.5 mm off read as a slip)."""
        fault = self._slip_in(obs)
        if fault is None:
            self.slip_streak.clear()
            return None
        streak = self.slip_streak
        if streak.add(obs) < self.settings.slip_poses:
            return None
        if self.held.reference is not None and len(self.held.poses) == 1 and poses_agree(streak.poses, self.settings):
            self.notes.append(f"the pose the grip's reference was taken from disagreed with the {len(streak.poses)} "
                              f"after it, which agree: a stray pose, the reference taken again ({fault[1]})")
            self.held.take(obs)
            streak.clear()
            return None
        return fault

    def _slip_in(self, obs: Observation) -> tuple[Outcome, str] | None:
        """What the latest pose shows: the object moved in the closed grip (by a pose certain enough of
        its position), or tilted while pushed (by a pose certain enough of its tilt; once the grip has
        closed again, only the first kind counts: a pose a few mm off may still be sure of its tilt)."""
        if self.held.reference is not None:
            why = moved_in_grip(obs, self.held, self.settings)
        elif self.pushed_reference is not None and self._pushing():
            why = tilted_while_pushed(obs, self.pushed_reference, self.settings)
        else:
            why = None
        return None if why is None else (Outcome.SLIP, f"{why} during {self.step.name} of primitive {self.index}")

    def _abort(self, outcome: Outcome, message: str) -> Command:
        position, angle = self.final_errors(self.last) if self.last.object_in_holder is not None else (math.nan, math.nan)
        self._finish(outcome, message, position, angle)
        return self._halt()

    def _finish(self, outcome: Outcome, message: str, position: float = math.nan, angle: float = math.nan) -> None:
        if self.result is None:
            completed = self.plan_length if outcome == Outcome.OK else min(self.index, self.plan_length)
            self.result = Result(outcome, message, completed, position, angle, self.last.time - self.started)
