"""What the states of one run share: the campaign, what is believed of the object, the pusher's route,
what the holder's turns did, and the run's end."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dmg_common.transforms import apply, invert
from dmg_executor.belief import HeldPose, PoseTrust
from dmg_executor.campaign import Campaign
from dmg_executor.contract import Command, Observation, Outcome, Result
from dmg_executor.motion import Pilot, Route, held_grip
from dmg_executor.push_points import ObjectSurface, PushPoint
from dmg_executor.reckoning import Reckoning
from dmg_executor.routes import KeepOut, keep_out, route
from dmg_executor.settings import ExecutorSettings
from dmg_executor.sight import Sight
from dmg_executor.views import CameraModel, TagLayout
from dmg_planner.primitives import Primitive


@dataclass
class Push:
    """One push: where it happens, in the base frame when it was planned, and its route there."""

    direction: np.ndarray         # the object's motion at the push point, base frame
    local_direction: np.ndarray   # the same in the holder's frame
    start: np.ndarray             # where the pusher's centre stops before the push
    route: Route                  # ending at `start`, the pusher's camera on the object on the way
    lever: float                  # m, pusher distance from the grasp axis (rotations)
    contact: PushPoint            # the push point on the object (object frame)
    other_views: list[np.ndarray] = field(default_factory=list)   # next best orientations at the push start
    blind: bool = False           # the camera sees no tag from its start: done on dead reckoning

    @property
    def spread(self) -> float:
        """The pusher's fingertip spread [m] for this push (0: closed; a straddle push opens them)."""
        return self.contact.spread

    @property
    def sideways(self) -> bool:
        """The pusher comes in along its own fingers and leaves the same way (a straddle push, a push between
        gripper 1's fingers): its tips are beside or between gripper 1's fingers all through the push."""
        return self.contact.sideways

    @property
    def carry(self) -> bool:
        """A carry: the tips meet the face along `direction`, then move back the way they came, the object
        following under its weight."""
        return self.contact.carry

    @property
    def sense(self) -> float:
        """+1: the object moves along `direction`; -1 (a carry): against it."""
        return -1.0 if self.carry else 1.0

    @property
    def motion(self) -> np.ndarray:
        """The way the object is moved (holder frame): along the push, or opposite to it for a carry."""
        return self.sense * self.local_direction


@dataclass
class Pushed:
    """A push from the moment the pusher began to move the object (holder frame)."""

    reference: np.ndarray      # the object pose it started from
    pusher: np.ndarray         # the pusher where it began
    along: np.ndarray          # the direction it pushed
    point: PushPoint           # where on the object (object frame)
    opening: float             # gripper 1's opening then
    reckoning: Reckoning       # the object's last known pose, moved on with the pusher


@dataclass
class PushMemory:
    """What earlier pushes of this run taught: where the pusher could not get, where the face was met
    further on than the pose said, and rotation pushes that turned the pusher without the object."""

    unreachable: list[np.ndarray] = field(default_factory=list)   # push directions (base frame) not reached
    shortfalls: list[tuple[np.ndarray, float]] = field(default_factory=list)   # (holder-frame direction, m)
    missed: list[PushPoint] = field(default_factory=list)
    lost_on_the_way: list[np.ndarray] = field(default_factory=list)   # push directions (base frame) whose way lost the object

    def lost_again(self, direction: np.ndarray, settings: ExecutorSettings) -> bool:
        """The object went unseen on the way to a push along `direction` (base frame): has a push this way
        lost it before? Then this way is taken as one the pusher cannot get to; else it is remembered."""
        cone = np.cos(settings.campaign.unreachable_cone)
        if any(float(past @ direction) >= cone for past in self.lost_on_the_way):
            self.unreachable.append(direction)
            return True
        self.lost_on_the_way.append(direction)
        return False

    def shortfall(self, direction: np.ndarray, settings: ExecutorSettings) -> float:
        """How much further on than its pose says the object has been met by blind pushes this way (0 to `gap`)."""
        cone = np.cos(settings.campaign.shortfall_cone)
        extra = sum(amount for past, amount in self.shortfalls if float(past @ direction) >= cone)
        return float(np.clip(extra, 0.0, settings.push.gap))

    def missed_before(self, push: PushPoint, settings: ExecutorSettings) -> bool:
        near, aligned = settings.push.missed_near_distance, np.cos(settings.push.missed_near)
        return any(np.linalg.norm(push.point - m.point) < near and float(push.direction @ m.direction) > aligned
                   for m in self.missed)


@dataclass
class HolderTurns:
    """What the holder's turns of the object about its fingers have done, and may still do."""

    turned_by: float = 0.0          # rad the holder turned the object about its fingers (to turn back by)
    far_side: bool = False          # the holder turned: the pusher faces the side it could not reach
    far_side_pushed: bool = False   # ... and has pushed there: turn back to look
    pressed_turned: bool = False    # a level press was seen made since the holder last turned
    may_turn: bool = True           # false once a turn stopped short (the wrist at a limit)
    may_return: bool = True         # false once the holder could not go back to where it started


@dataclass
class Search:
    """Why the held object is being looked for."""

    searching: bool = False         # it went unseen on the way to a push: look for it
    seeking_certain: bool = False   # ... or the plan's end is to be judged from an uncertain pose: look for a certain one
    sought_certain: bool = False    # a look for a certain pose was made since the last push
    slip_doubted: bool = False      # a slip seen with nothing touching the object was looked at again since the last push


class Run:
    """The shared context of one plan's execution; the states read and change it."""

    def __init__(self, settings: ExecutorSettings, surface: ObjectSurface, primitives: list[Primitive],
                 principal_finger: int, alpha: float, start_time: float, camera: CameraModel | None,
                 tags: TagLayout | None):
        self.settings, self.surface, self.alpha, self.started = settings, surface, alpha, start_time
        self.campaign = Campaign(settings, primitives, principal_finger)
        self.sight = Sight(settings, surface, camera, tags)
        self.pilot = Pilot(settings)
        self.trust = PoseTrust(settings.slip.position_sigma, settings.slip.tilt_sigma, settings.slip.reference_poses)
        self.held = HeldPose(self.trust)      # the object pose the closed grip must keep
        self.memory = PushMemory()
        self.push: Push | None = None         # the push planned last; None once the pusher is routed elsewhere
        self.pushed: Pushed | None = None     # the push under way or last made, from when it began to move the object
        self.holder_turns = HolderTurns()
        self.search = Search()
        self.holder_turning = False           # the holder is turning the object: images are not trusted
        self.reckoned: np.ndarray | None = None    # object pose believed while unseen since a push moved it (or a turn)
        self.reckoned_time = -math.inf
        self.fruitless: list[np.ndarray] = []   # places (holder frame) a look saw the object from none of the views at
        self.unseen_from = -math.inf    # being unseen counts from here (turns, blind pushes: expected)
        self.holder_start: np.ndarray | None = None
        self.pusher_home: np.ndarray | None = None
        self.pusher_spread = 0.0        # m between the pusher's fingertip centres as last commanded (0: closed)
        self.step_started = start_time
        self.last = Observation(start_time, np.eye(4), np.eye(4), None, -math.inf, 0.0)
        self.result: Result | None = None

    def begin(self, obs: Observation) -> None:
        """The first observation: where both grippers start."""
        self.holder_start, self.pusher_home = obs.holder.copy(), obs.pusher.copy()
        self.sight.neutral = self.pusher_home[:3, :3]

    @property
    def push_spread(self) -> float:
        """The planned push's fingertip spread [m] if it is a straddle push, else 0."""
        return 0.0 if self.push is None else self.push.spread

    # --- notes and the end -----------------------------------------------------------------------
    def note(self, text: str) -> None:
        self.campaign.notes.append(text)

    def halt(self) -> Command:
        return Command(holder_grip=held_grip(self.settings))

    def abort(self, outcome: Outcome, message: str) -> Command:
        """End the run: stop both arms, grip tight, report the errors as last perceived and what the run did
        before (its notes)."""
        last = self.last
        position, angle = self.campaign.final_errors(last) if last.object_in_holder is not None else (math.nan, math.nan)
        self.finish(outcome, self.campaign.with_notes(message), position, angle)
        return self.halt()

    def finish(self, outcome: Outcome, message: str, position: float = math.nan, angle: float = math.nan) -> None:
        if self.result is None:
            campaign = self.campaign
            completed = campaign.plan_length if outcome == Outcome.OK else min(campaign.index, campaign.plan_length)
            self.result = Result(outcome, message, completed, position, angle, self.last.time - self.started)

    # --- belief ----------------------------------------------------------------------------------
    def start_step(self, obs: Observation) -> None:
        """Start a step with the grip closed: from here the object must not move in it (from the
        next fresh pose on, if the last one is stale: the object moved while unseen)."""
        self.step_started = obs.time
        if self.held.reference is not None and self.reckoned is None:
            return      # held since its pose was seen, the grip closed all along: still where it was seen
        # (an object pushed unseen is where dead reckoning puts it, not seen there: no reference yet)
        if obs.time - obs.object_time > self.settings.monitors.stale_after or self.reckoned is not None:
            self.held.await_fresh()
        else:
            self.held.take(obs)

    def trusted(self, obs: Observation) -> bool:
        """Is this pose from an image worth trusting: not taken while the holder turns, nor of the object
        turned away unless certain?"""
        return not self.holder_turning and (not self.holder_turns.far_side or self.trust.certain(obs))

    def fresh(self, obs: Observation) -> bool:
        """A trusted pose no older than `stale_after`."""
        return self.trusted(obs) and obs.time - obs.object_time <= self.settings.monitors.stale_after

    def seen_since(self, since: float) -> bool:
        """Has a fresh pose from an image taken at or after `since` come?"""
        seen = self.last
        return seen.object_in_holder is not None and self.fresh(seen) and seen.object_time >= since

    # --- the space round the grasp and routes through it ---------------------------------------------
    def keep_out(self, obs: Observation) -> KeepOut:
        s = self.settings
        return keep_out(self.surface.vertices, obs.object_in_holder, obs.opening, s.gripper.tip_radius, 2 * s.gripper.tip_radius,
                        s.approach.clearance, s.approach.palm_reach)

    def plan_route(self, start: np.ndarray, goal: np.ndarray, box: KeepOut, prefer: np.ndarray | None = None
                   ) -> list[np.ndarray]:
        """Waypoints (holder frame) round the keep-out box, with this executor's route rules."""
        rules = self.settings.approach
        return route(start, goal, box, prefer, escape_depth=rules.escape_depth, far_side_cost=rules.far_side_cost)

    def home_in(self, holder: np.ndarray) -> np.ndarray:
        """Where the pusher started (its camera's vantage point), in the holder's frame."""
        return apply(invert(holder), self.pusher_home[:3, 3])

    def turn_radius(self, obs: Observation) -> float:
        """How far from the holder's finger axis the pusher's tip must be while the holder turns the object."""
        s = self.settings
        body = apply(obs.object_in_holder, self.surface.vertices)
        reach = max(float(np.hypot(body[:, 0], body[:, 1]).max()), obs.opening / 2 + 2.5 * s.gripper.tip_radius)
        return reach + 2 * s.gripper.tip_radius + s.approach.clearance

    def clear_of_turn(self, obs: Observation, place: np.ndarray) -> bool:
        """Is the pusher's tip at `place` (base frame) out of reach of the object turning about the holder's fingers?"""
        local = apply(invert(obs.holder), place)
        return float(np.hypot(local[0], local[1])) > self.turn_radius(obs)

    def route_to(self, obs: Observation, goal: np.ndarray, orientation: np.ndarray) -> None:
        """Route the pusher to `goal` (holder frame; a goal inside the space kept free moves just clear
        of it: a run that began next to the object ends there), turned to `orientation` there and
        its camera on the object on the way (RouteError if there is no route). A pusher inside that
        space on a push's line (its start in a hollow of the object, the pusher on its way in) first
        backs out the way it came: along the line (sim, a stepped block: stopped on that line, unseen,
        44 mm inside the space, no route out - the run ended LIMIT_VIOLATION), or for a sideways push
        along its own fingers (back along the line it would go through gripper 1's hand)."""
        box = self.keep_out(obs)
        start = apply(invert(obs.holder), obs.pusher[:3, 3])
        goal = box.nearest_outside(goal)
        back = []
        along = (np.zeros(3) if self.push is None else invert(obs.holder)[:3, :3] @ obs.pusher[:3, 2]
                 if self.push.sideways else self.push.local_direction)
        if box.contains(start)[0] and np.any(along):
            start = start - (box.exit_distance(start, -along) + self.settings.approach.exit_margin) * along
            back = [apply(obs.holder, start)]
        places = back + [apply(obs.holder, w) for w in self.plan_route(start, goal, box, goal)]
        orientations = [self.sight.views(obs, place)[0][0] for place in places[:-1]] + [orientation]
        self.push = None
        self.pilot.follow(Route(places, orientations))

    def head_home(self, obs: Observation, clear_of_turn: bool = False) -> None:
        """Route the pusher back to where it started (RouteError if there is none); before the holder
        turns the object, at least out of the turning object's reach (with gripper 1 moving in the
        pushes, at alpha < 1, the start may have come within it)."""
        goal = self.home_in(obs.holder)
        if clear_of_turn:
            radius, needed = float(np.hypot(*goal[:2])), self.turn_radius(obs) + self.settings.approach.clearance
            if radius < needed:
                outward = goal[:2] if radius > 1e-6 else apply(invert(obs.holder), obs.pusher[:3, 3])[:2]
                goal[:2] = outward / np.linalg.norm(outward) * needed
        self.route_to(obs, goal, self.pusher_home[:3, :3])
