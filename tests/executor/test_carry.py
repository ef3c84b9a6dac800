"""Carries on synthetic observations: a translation down along gripper 1's fingers is planned as a carry
on the face below the grasp (the pusher's tips meet it from below), and executed in its own order - the
tips touch with the grip held, the grip loosens to the force that leaves part of the weight on them, the
pusher goes down with the object following - and stopped when the object does not follow."""
from __future__ import annotations

import numpy as np
import pytest

from dmg_common.transforms import apply, invert
from dmg_executor.grip import GRAVITY
from dmg_executor.states.approach import Approach
from dmg_executor.states.base import Transition
from dmg_executor.states.execute import Execute, Phase
from dmg_executor.states.leave import Leave
from synthetic import box_cell, find_translation_push

NO_STRADDLE = {"straddle.opening": 0.0, "between.enabled": False}   # (the box takes either: only the carry is left)
DOWN_THE_FINGERS = (0.0, -0.010, 0.0)     # the grasp 10 mm up the box (object y is gripper 1's z): the box goes down


def planned(shift=DOWN_THE_FINGERS, cell=None, **overrides):
    return find_translation_push(shift, cell, **{**NO_STRADDLE, **overrides})


def test_a_translation_down_the_fingers_is_carried_from_the_face_below():
    cell, run, outcome = planned()
    assert isinstance(outcome, Transition) and isinstance(outcome.to, Approach)
    push = run.push
    assert push.carry
    down = cell.holder[:3, :3].T @ GRAVITY / np.linalg.norm(GRAVITY)
    assert push.motion @ down > 0.99                                  # the object goes down ...
    assert push.local_direction @ down < -0.99                        # ... the tips meet its face going up
    face = apply(cell.object_in_holder, push.contact.point)           # holder frame
    assert face[2] == pytest.approx(0.030, abs=1e-4)                  # the box's lower face, 30 mm below the grasp
    assert abs(face[1]) < 1e-3                                        # on the line through the grasp's middle


def test_the_carry_line_balances_the_weights_torque_about_the_grasp_axis():
    """The box held 5 mm off its centre across the fingers: the tips, carrying 40 % of the weight, must push
    5 / 0.4 = 12.5 mm out on that side for their torque about the grasp axis to balance the weight's."""
    cell = box_cell()
    cell.object_in_holder[:3, 3] += [0.0, 0.005, 0.0]
    _, run, _ = planned(cell=cell)
    face = apply(cell.object_in_holder, run.push.contact.point)
    share = run.settings.carry.weight_share
    assert run.push.carry and face[1] == pytest.approx(0.005 / (1.0 - share), abs=1e-4)


def test_no_carry_for_an_object_the_carrying_grip_could_not_keep_from_tilting():
    """The box held 10 mm along the grasp axis off its centre: its weight's torque across the axis needs a
    grip (with the margin a push's loosened grip keeps) that would hold all of its weight, not let it down."""
    cell = box_cell()
    cell.object_in_holder[:3, 3] += [0.010, 0.0, 0.0]
    _, run, _ = planned(cell=cell)
    assert run.push is None
    assert any("no carry: the grip that keeps the object from tilting" in note for note in run.campaign.notes)


def test_with_carries_off_and_no_straddle_the_translation_is_left_with_the_reason():
    cell, run, outcome = planned(**{"carry.enabled": False})
    assert run.push is None
    assert any("palm side" in note for note in run.campaign.notes)


def test_no_carry_when_gravity_is_mostly_along_the_grasp_axis():
    from scipy.spatial.transform import Rotation
    cell = box_cell()
    # gripper 1 turned 45 deg about its y: half of the weight along the grasp axis, which the fingers take
    cell.holder[:3, :3] = cell.holder[:3, :3] @ Rotation.from_euler("y", 45, degrees=True).as_matrix()
    _, run, outcome = planned(cell=cell)
    assert run.push is None
    assert any("no carry: across the grasp axis, straight down is 45 deg away" in note for note in run.campaign.notes)


def carry(follows: bool, ticks: int = 4000):
    """Execute a planned carry from its start on the synthetic cell; the box follows the pusher down while
    it rests on the tips (`follows`), else stays where the grip holds it. Phases, grips, the outcome."""
    cell, run, _ = planned()
    cell.pusher[:3, 3], cell.pusher[:3, :3] = run.push.start, run.push.route.orientations[-1]
    state = Execute()
    state.enter(run, cell.observe())
    phases, grips, way = [], [], run.push.motion
    for _ in range(ticks):
        obs = cell.observe()
        run.last = obs
        run.campaign.measure(obs)
        outcome = state.tick(run, obs)
        if isinstance(outcome, Transition):
            return cell, run, phases, grips, outcome
        phases.append(state.phase)
        grips.append(outcome.holder_grip)
        before = apply(invert(cell.holder), cell.pusher[:3, 3])
        cell.move(outcome)
        went = float((apply(invert(cell.holder), cell.pusher[:3, 3]) - before) @ way)
        if follows and state.phase == Phase.PUSH and went > 0.0:
            cell.object_in_holder[:3, 3] += went * way
    raise AssertionError("the carry did not end")


def test_the_carry_touches_with_the_grip_held_then_loosens_and_lets_the_object_down():
    cell, run, phases, grips, outcome = carry(follows=True)
    s = run.settings
    assert isinstance(outcome.to, Leave)
    assert [p for i, p in enumerate(phases) if i == 0 or phases[i - 1] != p] == \
        [Phase.TOUCH, Phase.LOOSEN, Phase.PUSH, Phase.TIGHTEN]
    touch = [g for p, g in zip(phases, grips) if p == Phase.TOUCH]
    assert all(g.max_force == s.grip.hold_force for g in touch)       # nothing slides before the tips are under it
    loosened = [g.max_force for p, g in zip(phases, grips) if p == Phase.PUSH]
    weight = run.surface.mass * np.linalg.norm(GRAVITY)
    # friction of two fingers holds the share of the weight; the tips carry the rest
    assert loosened[0] == pytest.approx(s.carry.weight_share * weight / (2 * s.grip.friction), rel=1e-6)
    run.campaign.measure(cell.observe())
    assert run.campaign.errors[0] <= s.tolerances.position + 1e-4
    assert not any("did not follow" in note for note in run.campaign.notes)


def test_an_object_that_does_not_follow_the_pusher_down_stops_the_carry():
    cell, run, phases, grips, outcome = carry(follows=False)
    assert isinstance(outcome.to, Leave) and phases[-1] == Phase.TIGHTEN
    assert any("did not follow the pusher down" in note for note in run.campaign.notes)
    run.campaign.measure(cell.observe())
    assert run.campaign.errors[0] > run.settings.tolerances.position     # it stopped short: planned again

