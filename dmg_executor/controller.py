"""Executing a repositioning plan with two grippers, closed loop on the perceived object pose.

Paper section V. Gripper 1 (the holder) holds the object, gripper 2 (the pusher) pushes it.
Every primitive is done in one or more pushes, each a sequence of states (dmg_executor/states/):

  FindContact   nothing moves; from the perceived pose, the push point on the object mesh
                (push_planning) and a collision-free route to it are computed.
  Approach      the pusher follows the route to `gap` in front of the push point.
  Execute       the holder's fingers loosen, the relative motion pushes the object, split between
                the arms by the ECTS coordination alpha; then the grip tightens (its phases: Phase).
  Leave         the pusher backs out along the push line.

Around them: Look (the held object unseen, or its pose too uncertain to judge the end by),
Homeward (a push given up), ClearForTurn/TurnHolder/HolderHome (the holder turns the object for a
push the pusher cannot reach, or goes back to where it started) and ReturnHome (the plan done).
The target of primitive k is the object pose in the holder's frame that puts the gripper at
the primitive's `gripper_after` (the planner's gripper pose in the object frame), so errors
left by one push are corrected by the next. Any fault stops both arms with the object held tight
and ends the run with an Outcome; `cancel` does the same on request.

Each tick `PlanExecutor.update` runs the monitors (object lost, slip, limits, time), updates the
belief of where the object is (held reference, dead reckoning of a push), then the current state.
"""
from __future__ import annotations

import traceback
from dataclasses import replace

import numpy as np

from dmg_common.transforms import apply, invert
from dmg_executor.contract import Command, GripCommand, Observation, Outcome, Progress, Result, Step
from dmg_executor.monitors import (
    SlipStreak,
    limit_violation,
    moved_in_grip,
    poses_agree,
    tilted_further_while_pressed,
    tilted_while_pushed,
)
from dmg_executor.motion import held_grip
from dmg_executor.push_points import ObjectSurface
from dmg_executor.pushed import judge_blind_push
from dmg_executor.run import Run
from dmg_executor.settings import ExecutorSettings
from dmg_executor.states.base import State, Transition
from dmg_executor.states.find_contact import FindContact
from dmg_executor.views import CameraModel, TagLayout
from dmg_planner.primitives import Primitive


class PlanExecutor:
    """The state machine of one plan; call `update` every control tick with a fresh Observation."""

    def __init__(self, settings: ExecutorSettings, surface: ObjectSurface, primitives: list[Primitive],
                 principal_finger: int, alpha: float, start_time: float, camera: CameraModel | None = None,
                 tags: TagLayout | None = None):
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"ECTS coordination alpha must be in [0, 1], got {alpha}")
        if principal_finger not in (0, 1):
            raise ValueError(f"principal_finger must be 0 or 1, got {principal_finger}")
        self.settings = settings
        self.run = Run(settings, surface, primitives, principal_finger, float(alpha), start_time, camera, tags)
        self.state: State = FindContact()
        self.slip_streak = SlipStreak()
        self.failure: str | None = None      # the traceback of an error of the executor's own that ended the run

    # --- public ------------------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return self.run.result is not None

    @property
    def result(self) -> Result | None:
        return self.run.result

    @property
    def primitives(self) -> list[Primitive]:
        """The plan's primitives, then the corrections and level press added after it."""
        return self.run.campaign.primitives

    @property
    def notes(self) -> list[str]:
        """What the result will report besides the errors: primitives left, looks, pushes stopped."""
        return self.run.campaign.notes

    @property
    def alpha(self) -> float:
        """The ECTS coordination the pushes are split by (1: the pusher moves alone)."""
        return self.run.alpha

    @property
    def step(self) -> Step:
        """What feedback publishes of the current state."""
        return self.state.step

    @property
    def state_name(self) -> str:
        """The current state in full (with its phase), for logs."""
        return self.state.name

    def progress(self) -> Progress:
        campaign = self.run.campaign
        primitives = campaign.primitives
        return Progress(min(campaign.index, len(primitives) - 1) if primitives else 0, len(primitives),
                        self.state.step, campaign.errors[0], campaign.errors[1], campaign.pushes,
                        campaign.principal_contact(self.run.last))

    def final_errors(self, obs: Observation) -> tuple[float, float]:
        """(principal contact vs the goal contact [m], gripper orientation vs the goal's [rad])."""
        return self.run.campaign.final_errors(obs)

    def update(self, observation: Observation) -> Command:
        """One control tick: the arms' twists and any gripper command."""
        run = self.run
        if self.done:
            return run.halt()
        run.last = observation
        try:
            if run.holder_start is None:
                run.begin(observation)
                command = self._tick(observation)
                command.pusher_grip = GripCommand(0.0, 0.0)     # pusher closed: its fingertips push together
                return command
            return self._tick(observation)
        except Exception as error:     # (a fault of its own must still stop the arms and keep the object held)
            self.failure = traceback.format_exc()
            failed = (f"the executor failed in {self.state_name} of primitive {run.campaign.index}: "
                      f"{type(error).__name__}: {error}; stopped, gripper 1 closed at the hold force")
            run.finish(Outcome.INTERNAL_ERROR, run.campaign.with_notes(failed))
            return run.halt()

    def cancel(self, reason: str = "cancelled on request") -> Command:
        return self.abort(Outcome.CANCELED, reason)

    def abort(self, outcome: Outcome, message: str) -> Command:
        """End the run from outside (cancel, a dead driver): stop, grip tight."""
        return self.run.abort(outcome, message)

    # --- one tick: monitors, belief, state ---------------------------------------------------------
    def _tick(self, obs: Observation) -> Command:
        run, s = self.run, self.settings
        campaign, step = run.campaign, self.state.step
        run.holder_turning = self.state.turns_holder
        if obs.opening < s.monitors.dropped_share * campaign.narrowest_grasp:
            return run.abort(Outcome.OBJECT_LOST, f"the object left gripper 1 during {step.name} of primitive "
                             f"{campaign.index}: its fingers closed to {obs.opening * 1000:.1f} mm (the plan's "
                             f"narrowest grasp is {campaign.narrowest_grasp * 1000:.1f} mm); stopped")
        # While the grip is closed and nothing pushes, the object cannot move: the camera may lose it
        # for a while (the pusher's hand turns and passes the object); the run ends only when the
        # held object stays unseen (on the way to a push: and is not found from vantage places). A
        # push goes on by dead reckoning (or, without blind pushes, stops at once with the grip
        # closed) and counts as seen until it ends; on the way to a push that starts where the camera
        # sees no tag (and loosening there), and while the holder turns the object or has turned it
        # away, the object is not expected to be seen: the count starts after.
        blind_push = step in (Step.APPROACH, Step.EXECUTE) and run.push is not None and run.push.blind
        if blind_push or run.holder_turning or run.holder_turns.far_side or run.search.searching:
            run.unseen_from = obs.time     # (a search is bounded by its vantage places)
        unseen = obs.time - max(obs.object_time, run.reckoned_time, run.unseen_from)
        if obs.object_in_holder is not None and unseen > s.monitors.stale_after_held and step == Step.APPROACH:
            # On the way to a push (or back from one given up) the held object has not moved: look for it
            # from vantage places round it, as after a push, before giving it up (sim: a box turned
            # 131 deg, the pusher stuck at a waypoint behind it, OBJECT_LOST on its way home).
            again = run.push is not None and run.memory.lost_again(run.push.direction, s)
            run.note(f"the object went unseen for {unseen:.1f} s on the way to a push of primitive "
                     f"{campaign.index}: looked for it" + ("; the second time this way: no push this way again"
                                                           if again else ""))
            run.search.searching = True
            return self._go(Transition(FindContact()), obs)
        if obs.object_in_holder is None or unseen > s.monitors.stale_after_held:
            age = "never seen" if obs.object_in_holder is None else f"last seen {unseen:.2f} s ago"
            return run.abort(Outcome.OBJECT_LOST, f"object pose lost ({age}; limit {s.monitors.stale_after_held:.2f} s) "
                             f"during {step.name} of primitive {campaign.index}: stopped, gripper 1 closed at the "
                             "hold force")
        # Poses from images taken while the holder turns are not trusted, nor those with the object
        # turned away unless they are certain (the object seen edge-on or from its back: measured
        # 7-10 mm off); the held pose is known.
        trusted, fresh = run.trusted(obs), run.fresh(obs)
        search = run.search
        search.searching = search.searching and not (fresh and (not search.seeking_certain or run.trust.certain(obs)))
        search.seeking_certain = search.seeking_certain and search.searching
        if self.state.pushing:     # the pusher's track and the last pose seen, with the pusher when its image was taken
            known = run.pushed.reckoning
            known.moved(obs.time, invert(obs.holder) @ obs.pusher)
            if fresh and obs.object_position_sigma <= s.tolerances.goal_position:
                # (a pose less certain than the goal's tolerance is no better than the reckoning: a lone tag
                # seen obliquely can be 10 mm off at 4 mm sigma)
                known.seen(obs.object_in_holder, obs.object_time)
        if self.state.pushing and s.push.blind:
            # The last pose moved on by the pusher's motion since its image: the image's latency made
            # up for, and the push goes on when the camera loses the object.
            if not fresh and not known.blind:
                known.blind = True
                run.note(f"a push of primitive {campaign.index} went on unseen, on dead reckoning")
            run.reckoned, run.reckoned_time = known.believed(invert(obs.holder) @ obs.pusher), obs.time
        elif not fresh and not s.push.blind and (stop := self.state.unseen_push(run, obs)) is not None:
            return stop
        elif run.reckoned is not None and fresh and obs.object_time >= run.reckoned_time:
            # Seen again after the push. Only a pose certain of its position judges it: an uncertain one
            # (a lone tag seen obliquely; sim: 11 mm off at 4 mm sigma) would have every later push that
            # way reach further for a miss that was not.
            if obs.object_position_sigma <= s.slip.position_sigma:
                judge_blind_push(run, obs)
            run.reckoned = None
        held = run.held
        if fresh and run.reckoned is None and (held.pending or held.outdone_by(obs)):
            held.take(obs)     # the first fresh pose since the grip closed, or a more certain one
        fault = self._limits(obs) or (self._slip(obs) if trusted else None)
        if fault and fault[0] == Outcome.SLIP and self._doubt_slip(fault[1]):
            # (the grip closed at the hold force again, the arms still: a real slip stops there)
            return self._go(Transition(FindContact(), Command(holder_grip=held_grip(s))), obs)
        if fault:
            return run.abort(*fault)
        if fresh and run.reckoned is None and not self.slip_streak.poses:
            held.fold_in(obs)
        if run.reckoned is not None:
            obs = replace(obs, object_in_holder=run.reckoned)    # pushed, not seen since: where it went
        else:
            obs = held.account(obs)                                   # held still since a certain pose
        if obs.time - run.step_started > s.limits.step_timeout:
            return run.abort(Outcome.STEP_TIMEOUT, f"{step.name} of primitive {campaign.index} did not finish in "
                             f"{s.limits.step_timeout:.1f} s (contact error {campaign.errors[0] * 1000:.1f} mm, angle error "
                             f"{np.rad2deg(campaign.errors[1]):.1f} deg)")
        campaign.measure(obs)
        command = self._go(self.state.tick(run, obs), obs)
        spread = self._spread_wanted(obs)
        if spread != run.pusher_spread:
            run.pusher_spread = spread
            command.pusher_grip = GripCommand(max(spread - 2 * s.gripper.tip_radius, 0.0), 0.0)
        return command

    def _go(self, outcome: Command | Transition, obs: Observation) -> Command:
        """Follow transitions to the state that answers this tick."""
        run = self.run
        while isinstance(outcome, Transition):
            self.state = outcome.to
            run.holder_turning = self.state.turns_holder
            if outcome.command is not None:
                run.start_step(obs)
            self.state.enter(run, obs)
            outcome = self.state.tick(run, obs) if outcome.command is None else outcome.command
        return outcome

    def _spread_wanted(self, obs: Observation) -> float:
        """How far apart [m] the pusher's fingertip centres should be: opened for a straddle push from where
        its last stretch begins until it has backed out of it, else closed (0) - never closing on gripper 1's
        fingers (the pusher still in the space kept free round them: stopped short backing out)."""
        run, step = self.run, self.state.step
        spread = run.push_spread
        if spread and (step in (Step.EXECUTE, Step.LEAVE)
                       or (step == Step.APPROACH and run.pilot.route.index >= len(run.pilot.route.waypoints) - 1)):
            return spread
        if run.pusher_spread and run.keep_out(obs).contains(apply(invert(obs.holder), obs.pusher[:3, 3]))[0]:
            return run.pusher_spread
        return 0.0

    # --- faults ----------------------------------------------------------------------------------
    def _limits(self, obs: Observation) -> tuple[Outcome, str] | None:
        why = limit_violation(obs, self.run.holder_start, self.settings)
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
        streak, held = self.slip_streak, self.run.held
        if streak.add(obs) < self.settings.slip.poses:
            return None
        if held.reference is not None and len(held.poses) == 1 and poses_agree(streak.poses, self.settings):
            self.run.note(f"the pose the grip's reference was taken from disagreed with the {len(streak.poses)} "
                          f"after it, which agree: a stray pose, the reference taken again ({fault[1]})")
            held.take(obs)
            streak.clear()
            return None
        return fault

    def _doubt_slip(self, why: str) -> bool:
        """A slip seen while the grip is closed and nothing touches the object (outside a push) is looked at
        again from other views, the grip closed at the hold force, before it ends the run, once until the
        next push: one view can mislead for many images (sim, a U: a lone tag seen head-on gave poses 3-8 mm and 3-8 deg
        off, 0.5-0.8 mm sure of themselves, for 0.4 s of the pusher's approach)."""
        run = self.run
        if self.state.step == Step.EXECUTE or run.search.slip_doubted:
            return False     # (in a push the grip is loosened: the object may well have moved)
        run.search.slip_doubted = run.search.searching = run.search.seeking_certain = True
        run.note(f"{why}, with nothing touching it: looked at again from other views")
        self.slip_streak.clear()
        return True

    def _slip_in(self, obs: Observation) -> tuple[Outcome, str] | None:
        """What the latest pose shows: the object moved in the closed grip (by a pose certain enough of
        its position), or tilted while pushed (by a pose certain enough of its tilt; a level press: further off the
        goal's grasp axis; once the grip has closed again, only the first kind counts: a pose a few mm off may
        still be sure of its tilt)."""
        run = self.run
        if run.held.reference is not None:
            why = moved_in_grip(obs, run.held, self.settings)
        elif run.pushed is not None and self.state.pushing and run.campaign.leveling:
            tilt = run.campaign.tilt_off_goal
            why = tilted_further_while_pressed(obs, float(np.linalg.norm(tilt(run.pushed.reference))),
                                               float(np.linalg.norm(tilt(obs.object_in_holder))), self.settings)
        elif run.pushed is not None and self.state.pushing:
            why = tilted_while_pushed(obs, run.pushed.reference, self.settings)
        else:
            why = None
        if why is None:
            return None
        return Outcome.SLIP, f"{why} during {self.state.step.name} of primitive {run.campaign.index}"
