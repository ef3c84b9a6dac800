"""Moving the arms: the pusher along a route of waypoints under P control, stalls, and the ECTS split
of a push's relative motion between the two arms."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import turn_between
from dmg_executor.contract import Command, GripCommand, Observation
from dmg_executor.ects import arm_twists
from dmg_executor.grip import GRAVITY, tilt_hold_force, turn_hold_force
from dmg_executor.push_points import ObjectSurface
from dmg_executor.settings import ExecutorSettings


@dataclass
class Route:
    """Where the pusher goes (base frame): waypoints on the way, then its goal, each with the orientation
    wanted there (the camera on the object on the way)."""

    waypoints: list[np.ndarray]
    orientations: list[np.ndarray]
    index: int = 0              # the waypoint the pusher is heading for

    @property
    def on_the_way(self) -> bool:
        """Is the current waypoint one on the way (not the last of the route)?"""
        return self.index < len(self.waypoints) - 1

    @property
    def finished(self) -> bool:
        return self.index == len(self.waypoints)


@dataclass
class _Headway:
    """The closest the pusher has come to where it is going, and when it last came closer."""

    target: bytes          # where it is going (position and orientation)
    offset: float          # m
    turn: float            # rad
    since: float           # s


def limited(velocity: np.ndarray, limit: float, full: bool = False) -> np.ndarray:
    """`velocity` capped at `limit` in size, or (`full`) at exactly `limit` its way."""
    size = float(np.linalg.norm(velocity))
    return velocity * (limit / size) if size > limit or (full and size > 0.0) else velocity


def shift(twist: np.ndarray, from_point: np.ndarray, to_point: np.ndarray) -> np.ndarray:
    """The same rigid motion as a twist at another point."""
    return np.concatenate([twist[:3] + np.cross(twist[3:], to_point - from_point), twist[3:]])


def coordinated(obs: Observation, relative: np.ndarray, alpha: float) -> Command:
    """ECTS: the relative motion as a twist at the grasp axis, split by alpha, each arm's share
    expressed at its own grasp frame."""
    origin = obs.holder[:3, 3]
    holder_twist, pusher_twist = arm_twists(np.zeros(6), relative, alpha)
    return Command(holder=shift(holder_twist, origin, origin), pusher=shift(pusher_twist, origin, obs.pusher[:3, 3]))


def held_grip(settings: ExecutorSettings) -> GripCommand:
    """The holder's fingers closed at the hold force."""
    return GripCommand(0.0, settings.grip.hold_force)


def loosened_grip(settings: ExecutorSettings, surface: ObjectSurface, obs: Observation) -> GripCommand:
    """P control of the finger distance towards just inside the object's width, at the slide force,
    or at what keeps the object's weight from tilting it off the grasp axis or swinging it round the
    axis if that is more."""
    s, pose, rotation = settings, obs.object_in_holder, obs.holder[:3, :3]
    tilt_hold = s.grip.tilt_hold_margin * tilt_hold_force(pose, rotation, surface.centre_of_mass, surface.mass,
                                                          obs.opening, s.grip.friction)
    turn_hold = s.grip.turn_hold_margin * turn_hold_force(pose, rotation, surface.centre_of_mass, surface.mass,
                                                          s.grip.torsional_friction)
    return GripCommand(_loosened_opening(s, obs),
                       float(np.clip(max(tilt_hold, turn_hold), s.grip.slide_force, s.grip.hold_force)))


def _loosened_opening(settings: ExecutorSettings, obs: Observation) -> float:
    """One P step of the finger distance towards `grip.slide_squeeze` inside the object's width."""
    wanted = max(obs.opening - settings.grip.slide_squeeze, 0.0)
    return max(obs.opening + settings.grip.finger_gain * (wanted - obs.opening), 0.0)


def carrying_grip(settings: ExecutorSettings, surface: ObjectSurface, obs: Observation, way: np.ndarray) -> GripCommand:
    """The loosened grip of a carry along `way` (holder frame, unit): finger distance as `loosened_grip`, at
    the force whose friction holds `carry.weight_share` of the object's weight along `way`, the rest left on
    the pusher's tips below it."""
    s = settings
    weight = surface.mass * float(np.clip((obs.holder[:3, :3].T @ GRAVITY) @ way, 0.0, None))
    force = s.carry.weight_share * weight / (2.0 * s.grip.friction)
    return GripCommand(_loosened_opening(s, obs), float(min(force, s.grip.hold_force)))


class Pilot:
    """Takes the pusher along its current route and tells when it has arrived or stalled."""

    def __init__(self, settings: ExecutorSettings):
        self.settings = settings
        self.route: Route | None = None
        self._headway: _Headway | None = None

    def follow(self, route: Route) -> None:
        self.route = route

    def go_to(self, obs: Observation, target: np.ndarray, orientation: np.ndarray | None = None,
              through: bool = False) -> Command:
        """P control of the pusher towards a position (and orientation), speeds limited. Going `through`
        (a waypoint on the way), at full speed until within its tolerance: P control's slow tail at
        each waypoint took about a second."""
        s = self.settings
        offset = target - obs.pusher[:3, 3]
        velocity = limited(s.approach.gain * offset, s.approach.speed,
                           through and np.linalg.norm(offset) > s.approach.waypoint_tolerance)
        angular = np.zeros(3)
        if orientation is not None:
            turn = Rotation.from_matrix(orientation @ obs.pusher[:3, :3].T).as_rotvec()
            angular = limited(s.approach.gain * turn, s.limits.angular_speed,
                              through and np.linalg.norm(turn) > s.approach.waypoint_turn_tolerance)
        return Command(pusher=np.concatenate([velocity, angular]))

    def along(self, obs: Observation) -> Command:
        """Towards the current waypoint of the route: through the ones on the way, onto the last."""
        route = self.route
        return self.go_to(obs, route.waypoints[route.index], route.orientations[route.index], route.on_the_way)

    def arrived(self, obs: Observation) -> bool:
        """The pusher is at the current waypoint, turned as wanted there."""
        route = self.route
        offset = np.linalg.norm(route.waypoints[route.index] - obs.pusher[:3, 3])
        turn = turn_between(route.orientations[route.index], obs.pusher[:3, :3])
        # (where a push starts: on its line, precisely)
        tolerance = self.settings.approach.waypoint_tolerance if route.on_the_way else self.settings.tolerances.position
        return offset < tolerance and turn < self.settings.approach.waypoint_turn_tolerance

    def there_but_turned(self, obs: Observation, seen: bool = False) -> bool:
        """Is the pusher at a waypoint, only not turned as wanted there? On the way that turn is a view of
        the object, not needed to go on (sim, bracket: two wrist joints 1 deg from their limits 1 mm from
        the waypoint; the push was given up after `stall_time`, and gripper 1 sent back and turned half
        round for another). At the push start it is the camera's view for the push: with the pusher on
        the push line and the object `seen` from where it is, it has it (sim, a plus: 0.4 mm from the
        start, its wrist 3.8 deg short of the turn wanted, the push given up view after view)."""
        route = self.route
        offset = float(np.linalg.norm(route.waypoints[route.index] - obs.pusher[:3, 3]))
        if route.on_the_way:
            return offset < self.settings.approach.waypoint_tolerance
        return seen and offset < self.settings.tolerances.position

    def stalled(self, obs: Observation, target: np.ndarray | None = None,
                orientation: np.ndarray | None = None) -> bool:
        """Has the pusher come no closer to `target` (turned to `orientation`, if given; by default the
        current waypoint, turned as wanted there) for `stall_time`, by `headway_distance` or `headway_turn` or,
        far from it, by `headway_share` of what was left?"""
        if target is None:
            target, orientation = self.route.waypoints[self.route.index], self.route.orientations[self.route.index]
        offset = float(np.linalg.norm(target - obs.pusher[:3, 3]))
        turn = 0.0 if orientation is None else turn_between(orientation, obs.pusher[:3, :3])
        key = target.tobytes() + (b"" if orientation is None else orientation.tobytes())
        headway, rules = self._headway, self.settings.approach
        if (headway is None or headway.target != key
                or offset < headway.offset - max(rules.headway_distance, rules.headway_share * headway.offset)
                or turn < headway.turn - max(rules.headway_turn, rules.headway_share * headway.turn)):
            self._headway = _Headway(key, offset, turn, obs.time)
            return False
        return obs.time - headway.since > self.settings.approach.stall_time
