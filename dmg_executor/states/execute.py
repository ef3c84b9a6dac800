"""EXECUTE: one push, in phases - the holder's grip loosens, the pusher's tip closes its gap to the face,
the push (a translation, a rotation about the grasp axis, or a level press), the grip tightens."""
from __future__ import annotations

from enum import Enum

import numpy as np

from dmg_common.transforms import apply, invert, turn_between
from dmg_executor.campaign import slid_since, turned_since
from dmg_executor.contract import Command, GripCommand, Observation, Step
from dmg_executor.fingertips import leading_tip, sweep_to_touch
from dmg_executor.grip import balanced_line, tilt_steering, weight_torque
from dmg_executor.monitors import tilt_since, turn_since
from dmg_executor.motion import carrying_grip, coordinated, held_grip, loosened_grip
from dmg_executor.push_points import face_room, room_step
from dmg_executor.pushed import mark_missed
from dmg_executor.reckoning import Reckoning
from dmg_executor.run import Pushed, Run
from dmg_executor.states import leave
from dmg_executor.states.base import State, Transition
from dmg_planner.primitives import PrimitiveKind


class Phase(Enum):
    LOOSEN = "loosen"       # the holder's fingers opening to the slide force (held tight for a level press;
                            # for a carry, after the touch, to the force that leaves the object on the tips)
    TOUCH = "touch"         # the pusher closing its gap to the face along the push line (first, for a carry)
    PUSH = "push"           # moving the object under P control on what is left
    TIGHTEN = "tighten"     # the grip closing again before the pusher leaves


class Execute(State):
    """The relative motion pushes the object - a translation v = -m t' with m from a P controller on the
    remaining contact displacement, or a rotation about the grasp axis at a P-controlled rate, the pusher
    following the object on its arc, or a level press - split between the arms by the ECTS coordination
    alpha. While pushing, the object pose is the last seen one moved on by the pusher's motion since its
    image (reckoning): a push the camera cannot watch goes on blind and the next pose checks it. A carry
    (a translation down along gripper 1's fingers) touches the face below the object first, with the grip
    held, then loosens it so that the object rests partly on the tips, and lets it down with them."""

    step = Step.EXECUTE

    def __init__(self):
        self.phase = Phase.LOOSEN
        self.grip_until = 0.0
        self.turn_mark: tuple[float, float] | None = None   # (tip swept, object turned) [rad] when the object was
        #                                                     last seen to gain
        self.sweep_to_face = 0.0   # rad a rotation's pusher turns before its tips meet the face (as seen when it began)
        self.carried_from: tuple[np.ndarray, np.ndarray] | None = None   # (pusher, object) positions, holder frame,
        #                                                          when a carry began to let the object down
        self.line_offset = 0.0     # m across the push line from the grasp axis where the touching tip is kept
        self.turn_seen = 0.0       # rad the object was last seen turned about the grasp axis since the push began
        self.line_range: tuple[float, float] | None = None   # m a translation's line may move either way across

    def enter(self, run: Run, obs: Observation) -> None:
        run.pushed = None
        run.search.slip_doubted = False     # (the push touches the object: a slip after it is a new question)
        if run.push.carry:     # the tips go under the face with the grip held, then it loosens
            push = run.push
            self.line_offset = float(apply(obs.object_in_holder, push.contact.point)
                                     @ np.cross(push.local_direction, [1.0, 0.0, 0.0]))
            self._begin(run, obs)
        else:
            self.grip_until = obs.time + run.settings.grip.settle

    @property
    def pushing(self) -> bool:
        return self.phase in (Phase.TOUCH, Phase.PUSH)

    @property
    def name(self) -> str:
        return f"Execute.{self.phase.name}"

    def unseen_push(self, run: Run, obs: Observation) -> Command | None:
        if self.phase == Phase.TIGHTEN:
            return None
        run.note(f"a push of primitive {run.campaign.index} stopped: object unseen for "
                 f"{obs.time - obs.object_time:.2f} s")
        return self._tighten(run, obs)

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        leveling, carry = run.campaign.leveling, run.push.carry
        if self.phase == Phase.LOOSEN:
            if obs.time < self.grip_until:
                return Command(holder_grip=self._pushing_grip(run, obs))
            if carry:
                self.phase = Phase.PUSH
                self.carried_from = (apply(invert(obs.holder), obs.pusher[:3, 3]), obs.object_in_holder[:3, 3].copy())
            else:
                self._begin(run, obs)
        if self.phase == Phase.TOUCH:
            command = self._touch(run, obs)
            if command is not None:
                return command
            if carry:      # the tips are under the face: the loosened grip lets the object down onto them
                self.phase, self.grip_until = Phase.LOOSEN, obs.time + run.settings.grip.settle
                return Command(holder_grip=self._pushing_grip(run, obs))
        if self.phase == Phase.TIGHTEN:
            if obs.time < self.grip_until:
                return Command()
            run.campaign.pushes += 1
            return Transition(leave.Leave())
        if leveling:
            return self._press_level(run, obs)
        return self._push(run, obs)

    # --- the phases ------------------------------------------------------------------------------
    def _begin(self, run: Run, obs: Observation) -> None:
        """The grip is loose: the push begins from the pose it starts from, with dead reckoning from there."""
        s, push, campaign, turns = run.settings, run.push, run.campaign, run.holder_turns
        run.held.reference = None
        # A level press the camera sees needs no turn back to be judged: the next is planned as the holder stands.
        turns.pressed_turned = turns.far_side and campaign.leveling and not push.blind
        turns.far_side_pushed = turns.far_side and not turns.pressed_turned
        reference = self._push_reference(run, obs)
        pusher = invert(obs.holder) @ obs.pusher
        # The pusher's tip stands `gap` short of the push point; it meets the face there (or further
        # on, where blind pushes this way fell short).
        along = push.local_direction
        face = apply(obs.object_in_holder, push.contact.point)
        reckoning = Reckoning(reference.copy(), pusher, apply(invert(pusher), face - s.push.gap * along),
                              face + run.memory.shortfall(along, s) * along,
                              # (a level press or a carry: believed unmoved; a carry is never blind)
                              np.zeros(3) if campaign.leveling or push.carry else along.copy(),
                              turning=campaign.primitive.kind == PrimitiveKind.ROTATION)
        reckoning.moved(obs.time, pusher)
        run.pushed = Pushed(reference, pusher.copy(), along.copy(), push.contact, obs.opening, reckoning)
        self.turn_mark, self.turn_seen, self.line_range = None, 0.0, None
        # Close the gap along the push line first, at push speed: turning from `gap` away, a rotation's
        # pusher would mostly slide past the face (its arc is tangent to the face, not into it); a
        # translation's P control would take seconds over it. A translation stops `touch_margin`
        # short of where the face is believed to be: the P-controlled push meets it. Either stops
        # where the camera sees the object move: the face was nearer than believed (a rotation's
        # pusher went on to shove the box 5 mm across the fingers and, turning, out of them).
        self.phase = Phase.TOUCH

    @staticmethod
    def _push_reference(run: Run, obs: Observation) -> np.ndarray:
        """The pose a push starts from: the latest seen, if fresh and certain - the push's own poses are
        single poses from this view, while the held reference may average poses from the views on the way
        (sim, bracket: 4.2 deg of tilt averaged over an approach, 2.9 deg seen at the push start, 2.7 true;
        a level press took the difference for the object turning back and stopped closing its gap) - else
        the held reference (a blind push)."""
        seen = run.last
        if seen.object_in_holder is not None and run.fresh(seen) and run.trust.certain(seen):
            return seen.object_in_holder.copy()
        return obs.object_in_holder.copy()

    def _touch(self, run: Run, obs: Observation) -> Command | None:
        """Close the gap to the face at push speed; None once met (the push phase goes on in this tick)."""
        s, push, pushed, campaign = run.settings, run.push, run.pushed, run.campaign
        rotation = campaign.primitive.kind == PrimitiveKind.ROTATION
        closed = float((apply(invert(obs.holder), obs.pusher[:3, 3]) - pushed.pusher[:3, 3]) @ push.local_direction)
        short = s.push.touch_margin if not rotation and not campaign.leveling else 0.0
        seen = pushed.reckoning.pose
        met = slid_since(pushed.reference, seen) > s.push.touched
        if campaign.leveling:     # or pressed back about the level axis (pose noise reaches 0.5 deg; the turn about
            # the grasp axis, 1.4 deg between two poses of a still bracket, is none of the press's business)
            met = met or self._level_left(run, pushed.reference) - self._level_left(run, seen) > s.push.turn_gain
        else:
            met = met or abs(turned_since(pushed.reference, seen)) > s.push.turn_gain
        if closed < s.push.gap - short and not met:
            command = coordinated(obs, np.concatenate([s.push.speed * push.direction, np.zeros(3)]), run.alpha)
            command.holder_grip = held_grip(s) if push.carry else self._pushing_grip(run, obs)
            return command
        self.phase = Phase.PUSH
        if rotation and not campaign.leveling:
            sweep = sweep_to_touch(run.surface, obs.holder @ seen, obs.pusher, obs.holder,
                                   obs.holder[:3, :3] @ push.local_direction, s.gripper.tip_radius, 2 * s.push.missed_turn,
                                   s.fingertips)
            self.sweep_to_face = sweep if np.isfinite(sweep) else 0.0
        return None

    def _push(self, run: Run, obs: Observation) -> Command:
        """Push on under P control until what is left is within tolerance, or stop the push early."""
        s, push, pushed, campaign = run.settings, run.push, run.pushed, run.campaign
        holder = obs.holder
        forced = obs.opening - max(pushed.opening, campaign.widest_grasp)
        if forced > s.monitors.forced_open:
            return self._stop(run, obs, f"the object forced gripper 1's fingers {forced * 1000:.1f} mm wider than "
                                        "its grasp (turning over in the grip)")
        tilted = tilt_since(pushed.reference, obs.object_in_holder) if run.fresh(obs) else 0.0
        if (s.monitors.push_tilt_stop * s.slip.angle < tilted <= s.slip.angle
                and obs.object_tilt_sigma <= s.slip.tilt_sigma):
            why = f"the object tilted {np.rad2deg(tilted):.1f} deg off the grasp axis"
            if campaign.primitive.kind == PrimitiveKind.ROTATION:
                # There the push tilts the object instead of turning it: a rotation has other points to push (sim, a
                # plus: pushed there again, it tilted on and left the grip as the grip closed).
                mark_missed(run, f"a push of primitive {campaign.index} stopped: {why}: not pushed there again")
                return self._tighten(run, obs)
            return self._stop(run, obs, why)
        if campaign.primitive.kind == PrimitiveKind.TRANSLATION:
            moving = push.sense * push.direction
            along = float(campaign.remaining_motion(obs) @ (holder[:3, :3].T @ moving))
            if along <= s.tolerances.position:
                return self._tighten(run, obs)
            lag = self._carry_lag(run, obs) if push.carry and run.fresh(obs) else 0.0
            if lag > s.carry.follow_lag:
                return self._stop(run, obs, f"the object did not follow the pusher down ({lag * 1000:.1f} mm behind it): "
                                            "the loosened grip holds more of its weight than reckoned")
            speed = float(np.clip(s.push.linear_gain * along, s.push.min_speed, s.push.speed))
            # Keep the push line through the grasp axis: an offset across it would turn the object (a carry's
            # line is where it was planned, beside the axis as far as balances the weight).
            across = np.cross(push.direction, holder[:3, 0])
            touching = obs.pusher[:3, 3] + leading_tip(push.direction, obs.pusher[:3, :3], s.gripper.tip_radius,
                                                       s.fingertips.leading_tip)
            offset = float((touching - holder[:3, 3]) @ across) - self._line(run, obs)
            relative = np.concatenate([speed * moving - s.approach.gain * offset * across
                                       + self._tilt_slide(run, obs) * holder[:3, 0], np.zeros(3)])
        else:
            turn = campaign.errors[1]
            turned = turned_since(pushed.reference, obs.object_in_holder)
            most = min(s.push.max_angle, push.contact.turn_limit)     # (as far as the grasp stays on its faces)
            budget = float(np.clip(turn + turned, -most, most))   # this push's share
            left = budget - turned
            if abs(turn) <= s.tolerances.angle or left * np.sign(budget) <= s.tolerances.angle / 2:
                return self._tighten(run, obs)
            pusher_turned = abs(turned_since(pushed.pusher, invert(obs.holder) @ obs.pusher))
            known = pushed.reckoning
            if run.fresh(obs):      # the last seen pose, with the tip's sweep when its image was taken
                swept, seen_turned = known.swept(), abs(turned_since(pushed.reference, known.pose))
            else:                   # unseen: the believed pose, which follows the sweep (no stall to tell)
                swept, seen_turned = known.swept(invert(obs.holder) @ obs.pusher), abs(turned)
            stalled = self._turn_stalled(run, swept, seen_turned)
            missed = self.turn_mark is None and pusher_turned > self.sweep_to_face + s.push.missed_turn
            if (stalled and seen_turned < s.push.turn_stall) or missed:
                # No turn worth the push to show for it (a stall before the object turned as far as the tip may sweep
                # without it, or none at all): turning in the air, or shoving the object some other way (sim, a plus:
                # 1.4 deg for 14 deg of sweep; pushed there again it tilted and left the grip).
                mark_missed(run, f"a rotation push of primitive {campaign.index} missed the object (it turned "
                                 f"{np.rad2deg(turned):.1f} deg): not tried there again")
                return self._tighten(run, obs)
            if stalled:
                run.note(f"a rotation push of primitive {campaign.index} stopped after {np.rad2deg(turned):.1f} deg: "
                         f"the object stopped turning with the pusher")
                return self._tighten(run, obs)
            slid = slid_since(pushed.reference, obs.object_in_holder)
            if slid > s.push.rotation_slide:
                run.note(f"a rotation push of primitive {campaign.index} stopped after {np.rad2deg(turned):.1f} deg: "
                         f"the object slid {slid * 1000:.1f} mm in the grip")
                return self._tighten(run, obs)
            lever = max(push.lever, 1e-3)
            rate = float(np.clip(s.push.angular_gain * abs(left), s.push.min_speed / lever,
                                 min(s.limits.angular_speed, s.push.speed / lever)))
            relative = np.concatenate([np.zeros(3), np.sign(left) * rate * holder[:3, 0]])   # about the grasp axis
        command = coordinated(obs, relative, run.alpha)
        command.holder_grip = self._pushing_grip(run, obs)
        return command

    def _carry_lag(self, run: Run, obs: Observation) -> float:
        """How much further [m] the pusher has gone down than the object since the carry began."""
        pusher, object_at = self.carried_from
        way = run.push.motion
        went = float((apply(invert(obs.holder), obs.pusher[:3, 3]) - pusher) @ way)
        return went - float((obs.object_in_holder[:3, 3] - object_at) @ way)

    @staticmethod
    def _pushing_grip(run: Run, obs: Observation) -> GripCommand:
        """The holder's grip while the object is pushed: held for a level press, let down for a carry, else loosened."""
        s = run.settings
        if run.campaign.leveling:
            return held_grip(s)
        if run.push.carry:
            return carrying_grip(s, run.surface, obs, run.push.motion)
        return loosened_grip(s, run.surface, obs)

    def _press_level(self, run: Run, obs: Observation) -> Command:
        """Turn the object about `level_axis` through the grasp's middle, the grip held, under P control on
        the tilt left along that axis; stop when it is under `level.done`, or once the pusher has turned the
        tilt the press began with and the slack its tip may meet the face late by (seen: `level.slack`, the
        seen tilt stops it first; unseen: only the give before the object moves, `level.press_give`)."""
        s, pushed = run.settings, run.pushed
        left, began = self._level_left(run, obs.object_in_holder), self._level_left(run, pushed.reference)
        pusher_turned = turn_between((invert(obs.holder) @ obs.pusher)[:3, :3], pushed.pusher[:3, :3])
        lever = max(run.push.lever, 1e-3)
        slack = (s.level.press_give if pushed.reckoning.blind else s.level.slack) / lever
        if left <= s.level.done or pusher_turned > began + slack:
            return self._tighten(run, obs)
        slid = slid_since(pushed.reference, obs.object_in_holder)
        if slid > s.level.slide:
            run.note(f"a level press of primitive {run.campaign.index} stopped: the grasp slid {slid * 1000:.1f} mm "
                     "on the object (shoved across the fingers, not rolled on them)")
            return self._tighten(run, obs)
        rate = float(np.clip(s.push.angular_gain * left, s.push.min_speed / lever, min(s.limits.angular_speed, s.push.speed / lever)))
        command = coordinated(obs, np.concatenate([np.zeros(3), rate * (obs.holder[:3, :3] @ run.campaign.level_axis)]),
                              run.alpha)
        command.holder_grip = held_grip(s)
        return command

    @staticmethod
    def _level_left(run: Run, object_in_holder: np.ndarray) -> float:
        """rad of tilt off the goal's grasp axis that a press has still to turn back: along the way the object
        is seen turning once it has turned `push.turn_gain` since the press began (about the way it should), before
        that along `level_axis`.
        A press turns the object about an axis of its own (sim, bracket: pushed to turn it about an axis 30
        deg off the tilt's, it turned about one 43 deg off, and pressed on until the tilt along the tilt's
        axis was gone, it ended as tilted as it began); along the way it turns, the tilt is least where
        none is left."""
        campaign = run.campaign
        tilt = campaign.tilt_off_goal(object_in_holder)
        turned = campaign.tilt_off_goal(run.pushed.reference) - tilt
        way = float(np.linalg.norm(turned))
        seen_way = way > run.settings.push.turn_gain and float(turned @ campaign.level_axis) > 0.0
        return float(tilt @ (turned / way if seen_way else campaign.level_axis))

    def _turn_stalled(self, run: Run, swept: float, turned: float) -> bool:
        """Has the pusher's tip swept `turn_stall` round the grasp axis since the object was last seen to gain
        `push.turn_gain` with it? Then it no longer turns the object but shoves it out of the grip (sim: bracket
        and plug stuck at 31 deg - the pusher slid along the face into a corner - then 8-38 deg of tilt within
        0.5 s). `turned` is the object's turn since the push began as last seen, `swept` the tip's sweep when
        its image was taken (rad, absolute): the pose believed between images follows the pusher by
        construction, and the pusher's own turn leaves out the sweep it makes along the push line (sim, a
        plate: the arm overran the touch by 1.5 deg of sweep, the believed turn ran ahead of every seen one,
        and pushes 'stalled' after 1-2 deg). Counted from the object's first gain: the pusher takes up the
        contact's slack first."""
        push, mark = run.settings.push, self.turn_mark
        if turned >= (push.turn_gain if mark is None else mark[1] + push.turn_gain):
            self.turn_mark = (swept, turned)
            return False
        return mark is not None and swept - mark[0] > push.turn_stall

    def _line(self, run: Run, obs: Observation) -> float:
        """Where [m, across the push line from the grasp axis] a translation's touching tip is kept: where its
        torque about the grasp axis balances the weight's, steered against the turn seen since the push began
        (`balanced_line`), within the face; a carry's line stays where it was planned."""
        s, pushed = run.settings, run.pushed
        if run.push.carry or run.push.sideways or pushed.reckoning.blind or s.steering.turn_offset_limit <= 0.0:
            return self.line_offset      # (a sideways push's tips are beside or between gripper 1's fingers; blind, nothing
            #                              would tell what the line does)
        if run.fresh(obs):
            self.turn_seen = turned_since(pushed.reference, obs.object_in_holder)
        if self.line_range is None:     # (the tip stays `push.edge_margin` inside the face)
            across = invert(pushed.reference)[:3, :3] @ np.cross(run.push.local_direction, [1.0, 0.0, 0.0])
            reach, contact = s.steering.turn_offset_limit + s.push.edge_margin, run.push.contact
            step = room_step(s.push.edge_margin)
            self.line_range = tuple(max(face_room(run.surface, contact.point, contact.direction, side * across, reach,
                                                  step) - s.push.edge_margin, 0.0) for side in (-1.0, 1.0))
        torque = weight_torque(obs.object_in_holder, obs.holder[:3, :3], run.surface.centre_of_mass, run.surface.mass)
        return self.line_offset + balanced_line(self.turn_seen, float(torque[0]), self._pushing_grip(run, obs).max_force,
                                                s.grip.friction, s.steering.turn_offset, *self.line_range)

    @staticmethod
    def _tilt_slide(run: Run, obs: Observation) -> float:
        """Pusher speed [m/s] along the grasp axis that steers a translated object's tilt back
        (`tilt_steering`), from fresh poses certain of their tilt only."""
        s, pushed = run.settings, run.pushed
        if (s.steering.gain == 0.0 or pushed.reckoning.blind or obs.object_tilt_sigma > s.slip.tilt_sigma
                or obs.time - obs.object_time > s.monitors.stale_after or run.push.sideways or run.push.carry):
            return 0.0      # (a sideways push's tips slid along the grasp axis would leave the face beside the fingers or meet them;
            #                  a carry's tips hold the object up: sliding them would drag it off the grasp axis)
        tilt = turn_since(pushed.reference, obs.object_in_holder)
        pusher = invert(obs.holder) @ obs.pusher
        local = run.push.local_direction
        reach = s.gripper.tip_radius * (1.0 + abs(float(local @ pusher[:3, 0])))    # the two tips sit side by side along x
        lever = -float(pusher[:3, 3] @ local) - reach
        steer = tilt_steering(tilt, local, lever, s.grip.friction * obs.opening / 2)
        return float(np.clip(s.steering.gain * steer, -s.steering.speed, s.steering.speed))

    def _stop(self, run: Run, obs: Observation, why: str) -> Command:
        """End the push early, saying why in the result; the rest is planned from where the object is."""
        run.note(f"a push of primitive {run.campaign.index} stopped: {why}")
        return self._tighten(run, obs)

    def _tighten(self, run: Run, obs: Observation) -> Command:
        self.phase = Phase.TIGHTEN
        self.grip_until = obs.time + run.settings.grip.settle
        return Command(holder_grip=held_grip(run.settings))
