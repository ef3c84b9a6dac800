"""The plan as a campaign of pushes: which primitive is being done, how far it is from its target, when it
is finished, and the corrections and level press added after the plan."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply, distance, invert
from dmg_executor.contract import Observation
from dmg_executor.settings import ExecutorSettings
from dmg_planner.primitives import Primitive, PrimitiveKind


def rotation_about_axis(rotation: np.ndarray) -> float:
    """Angle [rad] of a rotation (holder frame) about the grasp axis x."""
    return float(Rotation.from_matrix(rotation).as_rotvec()[0])


def turned_since(reference: np.ndarray, now: np.ndarray) -> float:
    """How far [rad] the object turned about the grasp axis from pose `reference` to `now` (holder frame)."""
    return rotation_about_axis(now[:3, :3] @ reference[:3, :3].T)


def slid_since(reference: np.ndarray, now: np.ndarray) -> float:
    """How far [m] the grasp's middle moved on the object from pose `reference` to `now` (holder frame);
    a turn about the grasp axis moves it not at all."""
    return float(np.linalg.norm(invert(now)[:3, 3] - invert(reference)[:3, 3]))


class Campaign:
    """The primitives to do (the plan's, then corrections), the one being done and its error."""

    def __init__(self, settings: ExecutorSettings, primitives: list[Primitive], principal_finger: int):
        missing = [k for k, p in enumerate(primitives) if p.gripper_after is None]
        if missing:
            raise ValueError(f"primitives {missing} carry no gripper_after pose: plan with this planner version")
        self.settings, self.primitives, self.principal_finger = settings, list(primitives), principal_finger
        self.plan_length = len(primitives)
        # The narrowest the object is between gripper 1's fingers along the plan: closed much further, they hold nothing.
        self.narrowest_grasp = min((min(p.opening_before, p.opening_after) for p in primitives), default=0.0)
        self.widest_grasp = max((max(p.opening_before, p.opening_after) for p in primitives), default=0.0)
        self.notes: list[str] = []      # what the result reports besides the errors: primitives left, looks, stops
        self.index, self.pushes = 0, 0
        self.errors = (math.nan, math.nan)      # (contact displacement [m], turn about the grasp axis [rad]) left
        self.error_before_push = math.inf   # the current primitive's error when its last push was planned
        self.settled = False            # near the goal, and pushes make no headway: no more of them
        self.level_index: int | None = None   # the correction that presses the object level (see level_tilt)
        self.level_axis = np.zeros(3)         # holder frame: the axis the current level push turns the object about
        self.level_began = 0.0                # rad: the tilt off the goal's grasp axis when leveling began

    @property
    def primitive(self) -> Primitive:
        """The primitive being done (the last one once all are: corrections aim at its goal)."""
        return self.primitives[min(self.index, len(self.primitives) - 1)]

    @property
    def over(self) -> bool:
        return self.index >= len(self.primitives)

    @property
    def leveling(self) -> bool:
        """Is the primitive being done the level press?"""
        return self.level_index is not None and self.index == self.level_index

    def target(self) -> np.ndarray:
        """Object pose in the holder's frame that completes the current primitive."""
        return invert(self.primitive.gripper_after)

    def next_primitive(self) -> None:
        self.index, self.pushes = self.index + 1, 0

    def remaining_motion(self, obs: Observation) -> np.ndarray:
        """Object displacement (holder frame) still needed, across the grasp axis only."""
        where = apply(obs.object_in_holder, self.primitive.gripper_after[:3, 3])
        motion = -where
        motion[0] = 0.0       # along the grasp axis the fingers centre the object
        return motion

    def measure(self, obs: Observation) -> None:
        if not self.primitives:
            self.errors = (0.0, 0.0)
            return
        self.errors = (float(np.linalg.norm(self.remaining_motion(obs))),
                       rotation_about_axis(self.target()[:3, :3] @ obs.object_in_holder[:3, :3].T))

    def tilt_off_goal(self, object_in_holder: np.ndarray) -> np.ndarray:
        """Rotation vector (holder frame, across the grasp axis) that would turn the object from
        `object_in_holder` so that the grasp axis lies on it as the goal grasp's does."""
        turn = Rotation.from_matrix(self.target()[:3, :3] @ object_in_holder[:3, :3].T).as_rotvec()
        turn[0] = 0.0
        return turn

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

    def error_and_tolerance(self, obs: Observation) -> tuple[float, float]:
        """The current primitive's remaining error and its tolerance (m for a translation, rad for a rotation
        and for the tilt a level push presses back), judged from the pose the tick goes by (not the latest
        image's: one taken while the holder turns is not trusted - sim, bracket: 7.5 deg seen mid-turn, 4.0
        true, ended a level press as having gained nothing)."""
        if self.leveling:
            return float(np.linalg.norm(self.tilt_off_goal(obs.object_in_holder))), self.settings.level.tilt
        if self.primitives[self.index].kind == PrimitiveKind.TRANSLATION:
            return self.errors[0], self.settings.tolerances.position
        return abs(self.errors[1]), self.settings.tolerances.angle

    def finished(self, obs: Observation) -> bool:
        """Within tolerance, or close enough after a push, or out of pushes, or settled near the goal (a level
        press: level, or out of presses, or the last gained nothing)."""
        error, tolerance = self.error_and_tolerance(obs)
        if self.leveling:
            gained = self.level_began - error
            level, settled = self.settings.level, self.settings.campaign.settled_share * self.settings.tolerances.goal_angle
            return (error <= tolerance or self.pushes >= level.pushes + 1 or (self.pushes > 0 and gained < level.done)
                    or (self.pushes >= level.pushes and error <= settled))
        return (error <= tolerance or (self.pushes > 0 and error <= self.settings.campaign.retry_factor * tolerance)
                or self.pushes >= self.settings.campaign.max_pushes_per_primitive
                or self._settles(obs, error, tolerance))

    def _settles(self, obs: Observation, error: float, tolerance: float) -> bool:
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
        self.settled = (position <= s.campaign.settled_share * s.tolerances.goal_position
                        and angle <= s.campaign.settled_share * s.tolerances.goal_angle)
        if self.settled:
            self.notes.append(f"primitive {self.index} settled {position * 1000:.1f} mm and {np.rad2deg(angle):.1f} deg "
                              f"from the goal: its last push made no headway")
        return self.settled

    def needs_leveling(self, obs: Observation) -> bool:
        """After the plan (once a run): is the grasp outside the goal's tolerances (as the run's end judges
        it; the principal contact's error takes in the tilt times the contact's distance from the grasp's
        middle) with its axis certainly tilted more than `level_tilt` off the goal's? Only then: each turn
        of the holder a press needs shifts the object ~1 mm in the grip (sim: box, plug)."""
        s = self.settings
        position, angle = self.final_errors(obs)
        return (self.level_index is None and s.level.tilt > 0.0 and obs.object_tilt_sigma <= s.slip.tilt_sigma
                and (position > s.tolerances.goal_position or angle > s.tolerances.goal_angle)
                and np.linalg.norm(self.tilt_off_goal(obs.object_in_holder)) > s.level.tilt)

    def add_correction(self, obs: Observation, failed: PrimitiveKind | None = None) -> None:
        """The plan is done but the grasp is not where it should be (a rotation also slides the object,
        a push also turns it): one more translation or rotation to the goal grasp, the larger error
        first (not the kind that just found no push), up to `campaign.max_corrections` besides a level press (see
        `level_tilt`) comes first where the tilt is more than the turn about the grasp axis left or a turn
        found no push (the holder's turns for it shift the object, which the corrections after it take back),
        else last."""
        s = self.settings
        self.index -= 1
        self.measure(obs)
        self.index += 1
        shares = {PrimitiveKind.TRANSLATION: self.errors[0] / s.tolerances.position,
                  PrimitiveKind.ROTATION: abs(self.errors[1]) / s.tolerances.angle}
        shares.pop(failed, None)
        kind = max(shares, key=shares.get)
        corrections = len(self.primitives) - self.plan_length - (self.level_index is not None)
        corrected = self.settled or shares[kind] <= s.campaign.retry_factor or corrections >= s.campaign.max_corrections
        tilt = float(np.linalg.norm(self.tilt_off_goal(obs.object_in_holder))) if self.needs_leveling(obs) else 0.0
        # (a turn that just found no push waits for it: the tilt can be what keeps the grasp off its faces)
        turn_left = 0.0 if failed == PrimitiveKind.ROTATION else abs(self.errors[1])
        if tilt and (corrected or tilt > turn_left):
            self.level_index, self.level_began = len(self.primitives), tilt
            self.primitives.append(replace(self.primitives[-1]))
            self.notes.append(f"the grasp axis was {np.rad2deg(self.level_began):.1f} deg off the goal's: "
                              f"primitive {self.level_index} presses the object level")
        elif not corrected:
            self.primitives.append(replace(self.primitives[-1], kind=kind))

    def summary(self, position: float, angle: float) -> tuple[bool, str]:
        """At the plan's end, its final errors (`final_errors`): within the goal's tolerances?, and what to report."""
        s = self.settings
        corrections = len(self.primitives) - self.plan_length
        within = position <= s.tolerances.goal_position and angle <= s.tolerances.goal_angle
        summary = (f"{self.plan_length} primitives and {corrections} corrections done: contact "
                   f"{position * 1000:.1f} mm and {np.rad2deg(angle):.1f} deg from the goal")
        if not within:
            summary += (f", outside the tolerance of {s.tolerances.goal_position * 1000:.1f} mm and "
                        f"{np.rad2deg(s.tolerances.goal_angle):.1f} deg")
        return within, self.with_notes(summary)

    def with_notes(self, message: str) -> str:
        """A run's closing message followed by what it did (its notes)."""
        return "; ".join([message] + self.notes)
