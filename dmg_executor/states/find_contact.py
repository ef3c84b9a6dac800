"""FIND_CONTACT: nothing moves; the campaign moves on past finished primitives, and from the perceived
pose the next push is planned - or the held object looked for, or the holder turned for a push the
pusher cannot reach as it stands, or, with every primitive done, the pusher sent home."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import distance
from dmg_executor.contract import Command, Observation, Outcome, Step
from dmg_executor.push_planning import plan_push
from dmg_executor.push_points import PushError
from dmg_executor.routes import RouteError
from dmg_executor.run import Run
from dmg_executor.states import approach, holder_turn, leave, look
from dmg_executor.states.base import State, Transition
from dmg_planner.primitives import Primitive, PrimitiveKind


def _turned_holder(obs: Observation, angle: float) -> np.ndarray:
    """The holder's pose turned `angle` about its finger axis (z)."""
    holder = obs.holder.copy()
    holder[:3, :3] = obs.holder[:3, :3] @ Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix()
    return holder


def push_when_turned(run: Run, primitive: Primitive, obs: Observation) -> bool:
    """Would the pusher, back where it started, find a push for `primitive` with the holder turned
    `holder_turn` about its fingers (the object's far side towards it)? Such a push is done on dead
    reckoning, so only with blind pushes."""
    s, turns = run.settings, run.holder_turns
    if (s.holder.turn == 0.0 or not s.push.blind or turns.far_side or not turns.may_turn
            or not run.clear_of_turn(obs, run.pusher_home[:3, 3])):
        return False
    try:
        plan_push(run, primitive, replace(obs, holder=_turned_holder(obs, s.holder.turn), pusher=run.pusher_home.copy()))
    except (PushError, RouteError):
        return False
    return True


def quarter_turn(run: Run, obs: Observation) -> float | None:
    """Where no push is found: the turn of the holder about its fingers (+-90 deg) after which the pusher,
    back where it started, finds one - a level press or a straddle push, each with the pusher's fingers
    pointing along the grasp axis, which Baxter's right arm does only about the way they point at home.
    (Not for other pushes a quarter turn would allow: sim, a T probe, a push along its bar so found
    knocked it out of the grip at every alpha.)"""
    if run.holder_turns.far_side or not run.holder_turns.may_turn:
        return None
    campaign = run.campaign
    for angle in (np.pi / 2, -np.pi / 2):
        try:
            push = plan_push(run, campaign.primitives[campaign.index],
                             replace(obs, holder=_turned_holder(obs, angle), pusher=run.pusher_home.copy()))
        except (PushError, RouteError):
            continue
        if campaign.leveling or push.spread:
            return angle
    return None


def push_when_returned(run: Run, primitive: Primitive, obs: Observation) -> bool:
    """At alpha < 1 the holder moves in the pushes (at 0 it does all of a rotation: turned 45 deg
    about its grasp axis, its hand is where the pusher has to go). Would the pusher, back where it
    started, find a push for `primitive` with the holder back where it started, holding the object
    as it does now (or with the holder then turning the object's far side towards it, or, for a level
    press, a quarter turn about its fingers: a press along the grasp axis is reachable only with that
    axis the way the pusher's fingers point at home, which a quarter turn of the moved holder misses;
    a translation's quarter turn is tried where the holder stands)?"""
    offset, turned = distance(run.holder_start, obs.holder)
    moved, turns = run.settings.holder, run.holder_turns
    if not turns.may_return or turns.far_side or (offset < moved.moved_distance and turned < moved.moved_turn):
        return False
    returned = replace(obs, holder=run.holder_start.copy(), pusher=run.pusher_home.copy())
    try:
        plan_push(run, primitive, returned)
    except (PushError, RouteError):
        return (push_when_turned(run, primitive, returned)
                or (run.campaign.leveling and quarter_turn(run, returned) is not None))
    return True


class FindContact(State):
    """Plan the next push from the perceived pose (the hub the other states come back to)."""

    step = Step.FIND_CONTACT

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        turns, search, campaign = run.holder_turns, run.search, run.campaign
        if turns.far_side_pushed:
            return holder_turn.start_holder_turn(run, obs, back=True)     # to see what the push did
        if (run.held.pending or search.searching) and not turns.far_side:
            return Transition.handover(look.Look())     # plan the next push from a fresh pose
        while not campaign.over and campaign.finished(obs):
            last = campaign.index == len(campaign.primitives) - 1
            if turns.far_side and (campaign.leveling or last):
                # The plan's end (and a press) is judged with the holder turned back, from the pose the result is
                # judged from (sim: a far side seen 1 mm off ended a rotation whose grasp, seen turned back, was 4.7 mm
                # from its goal, with no correction left to plan). The look counts as one of the primitive's pushes.
                campaign.pushes += not campaign.leveling
                turns.far_side_pushed = True
                return Command()
            if last and self._may_seek_certain(run, run.settings.slip.position_sigma):
                return self._seek_certain(run)
            campaign.next_primitive()
            if campaign.over:
                campaign.add_correction(obs)
            campaign.measure(obs)
        if campaign.over:
            return (holder_turn.start_holder_turn(run, obs, back=True) if turns.far_side
                    else Transition.handover(leave.ReturnHome()))
        s = run.settings
        if run.held.reference is not None and self._may_seek_certain(run, s.tolerances.goal_position):
            return self._seek_certain(run)
        primitive = campaign.primitives[campaign.index]
        try:
            push = plan_push(run, primitive, obs)
            run.push = push
            campaign.error_before_push = campaign.error_and_tolerance(obs)[0]
        except (PushError, RouteError) as error:
            return self._no_push(run, obs, primitive, error)
        outside = [p for p in push.route.waypoints if np.any(p < s.limits.workspace_min) or np.any(p > s.limits.workspace_max)]
        if outside:
            return run.abort(Outcome.LIMIT_VIOLATION, f"primitive {campaign.index}: the push needs the pusher at "
                             f"{np.round(outside[0], 3).tolist()} m, outside the workspace")
        if push.sideways and not push.spread:
            between = f"a push of primitive {campaign.index} went between gripper 1's fingers"
            if between not in campaign.notes:
                run.note(between)
        run.pilot.follow(push.route)
        search.sought_certain = False
        return Transition(approach.Approach())

    @staticmethod
    def _may_seek_certain(run: Run, sigma: float) -> bool:
        """Is the held pose more uncertain of its position than `sigma`, with no look for a better one since the
        last push (and the object's near side towards the pusher)? None (not seen since a blind push) counts as
        uncertain. Asked before what an uncertain pose would get wrong for good: the plan's end judged (sigma
        `slip.position_sigma`; sim, plug: a lone tag seen obliquely, 1.2-3.6 mm sigma, put a grasp 2.5 mm from
        its goal 2.4-8.1 mm from it), a primitive given up as having no push (the same), a push planned from a
        pose seen (`tolerances.goal_position`: a pose less certain than the goal's tolerance cannot tell a push
        that helps from one that undoes what is done)."""
        held = run.held
        return (not run.search.sought_certain and not run.holder_turns.far_side
                and (held.reference is None or held.sigma > sigma))

    @staticmethod
    def _seek_certain(run: Run) -> Transition:
        search = run.search
        search.sought_certain = search.seeking_certain = search.searching = True
        return Transition.handover(look.Look())

    @staticmethod
    def _no_push(run: Run, obs: Observation, primitive: Primitive, error: Exception) -> Command | Transition:
        """No push for `primitive` as the grippers stand: turn the holder (or send it back to where it started)
        for one the pusher can reach, else leave the primitive and go on to the next."""
        turns, campaign = run.holder_turns, run.campaign
        if campaign.leveling and turns.pressed_turned:   # the next press another way: turn back, plan from there
            turns.far_side_pushed = True
            return Command()
        turn = quarter_turn(run, obs) if campaign.leveling else None
        if turn is not None:
            return holder_turn.start_holder_turn(run, obs, back=False, angle=turn)
        if push_when_returned(run, primitive, obs):
            return holder_turn.start_holder_turn(run, obs, back=False, home=run.holder_start)
        if push_when_turned(run, primitive, obs):
            return holder_turn.start_holder_turn(run, obs, back=False)
        turn = quarter_turn(run, obs) if primitive.kind == PrimitiveKind.TRANSLATION and not campaign.leveling else None
        if turn is not None:
            return holder_turn.start_holder_turn(run, obs, back=False, angle=turn)
        if FindContact._may_seek_certain(run, run.settings.slip.position_sigma):
            return FindContact._seek_certain(run)     # a primitive is given up only on a certain pose
        turns.far_side_pushed = turns.far_side     # (turned, and still no push: turn back)
        # No push can do (the rest of) it: the next primitive aims at its own target from here,
        # and the result says what was left and why.
        failed = None if campaign.leveling else primitive.kind
        run.note(f"primitive {campaign.index} ({'level press' if failed is None else failed.name.lower()}) left at "
                 f"{campaign.errors[0] * 1000:.1f} mm, {np.rad2deg(campaign.errors[1]):.1f} deg: no safe push: {error}")
        campaign.next_primitive()
        if campaign.over:
            campaign.add_correction(obs, failed=failed)
        return Command()
