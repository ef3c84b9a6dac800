"""Pushes between gripper 1's fingers on synthetic observations: a translation out along gripper 1's fingers
with no straddle push or carry is pushed on the object's palm-side face by the pusher's closed tips, which
come in across those fingers along its own and leave the same way; refused, with the reason, where the
tips fit neither between the fingers nor short of the palm; two tips side by side along the grasp axis where they
fit between the fingers, else one behind the other along the push."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply, invert
from dmg_executor.states.approach import Approach
from dmg_executor.states.base import Transition
from dmg_executor.states.execute import Execute
from dmg_executor.states.find_contact import FindContact
from dmg_executor.states.leave import Leave
from synthetic import box_cell, find_translation_push

ONLY_BETWEEN = {"straddle.opening": 0.0, "carry.enabled": False}
OUT_ALONG_THE_FINGERS = (0.0, -0.010, 0.0)   # object y is gripper 1's z: the box moves 10 mm towards the fingertips


def planned(cell=None, shift=OUT_ALONG_THE_FINGERS, **overrides):
    return find_translation_push(shift, cell, **{**ONLY_BETWEEN, **overrides})


def test_the_palm_side_face_is_pushed_between_the_fingers_by_the_closed_tips_coming_in_across_them():
    cell, run, outcome = planned()
    assert isinstance(outcome, Transition) and isinstance(outcome.to, Approach)
    push, s = run.push, run.settings
    assert push.sideways and push.spread == 0.0 and not push.carry
    assert push.motion @ [0.0, 0.0, 1.0] > 0.99                         # out along gripper 1's fingers
    face = apply(cell.object_in_holder, push.contact.point)             # holder frame
    assert face[2] == pytest.approx(-0.030, abs=1e-4)                   # the box's palm-side face
    assert np.linalg.norm(face[:2]) < 1e-3                              # on the line through the grasp's middle
    to_holder = invert(cell.holder)[:3, :3]
    orientation = to_holder @ push.route.orientations[-1]                # the pusher at the push start, holder frame
    fingers, tips = orientation[:, 2], orientation[:, 0]
    assert abs(fingers[0]) < np.sin(s.between.fingers) and abs(fingers[2]) < np.sin(s.between.fingers)
    assert abs(tips[0]) == pytest.approx(1.0, abs=1e-9)                 # tips side by side along the grasp axis
    start, entry = (apply(invert(cell.holder), p) for p in (push.route.waypoints[-1], push.route.waypoints[-2]))
    stretch = (start - entry) / np.linalg.norm(start - entry)
    assert stretch @ fingers > 0.999                                    # the last stretch runs along its fingers
    assert abs(start[0]) < 1e-6 and start[2] < face[2]                  # between the fingers, on the palm side
    assert "a push of primitive 0 went between gripper 1's fingers" in run.campaign.notes


def test_the_pusher_leaves_a_push_between_the_fingers_along_its_own_fingers():
    cell, run, _ = planned()
    cell.pusher[:3, 3], cell.pusher[:3, :3] = run.push.start, run.push.route.orientations[-1]
    Execute().enter(run, cell.observe())
    fingers = invert(cell.holder)[:3, :3] @ cell.pusher[:3, 2]
    state, path = Leave(), []
    for _ in range(3000):
        obs = cell.observe()
        run.last = obs
        outcome = state.tick(run, obs)
        if isinstance(outcome, Transition):
            break
        path.append(apply(invert(cell.holder), cell.pusher[:3, 3]))
        cell.move(outcome)
    else:
        raise AssertionError("the pusher did not leave")
    assert isinstance(outcome.to, FindContact)
    moves = np.diff(np.array(path), axis=0)
    backed = moves[:5].sum(axis=0)
    assert backed[2] < 0.0 and abs(backed[0]) < 1e-6                    # off the face first, towards the palm
    out = moves[-5:].sum(axis=0)
    assert out @ fingers < -0.99 * np.linalg.norm(out)                  # then out the way it came in
    assert np.abs(np.array(path)[:, 0]).max() < 1e-6                    # never towards gripper 1's fingers


def test_a_push_between_the_fingers_given_up_at_its_start_backs_out_along_the_pushers_fingers_first():
    """Back along the push's line from between gripper 1's fingers would take the pusher through gripper 1's hand."""
    cell, run, _ = planned()
    cell.pusher[:3, 3], cell.pusher[:3, :3] = run.push.start, run.push.route.orientations[-1]
    obs = cell.observe()
    start = apply(invert(cell.holder), cell.pusher[:3, 3])
    fingers = invert(cell.holder)[:3, :3] @ cell.pusher[:3, 2]
    run.head_home(obs)
    out = apply(invert(cell.holder), run.pilot.route.waypoints[0]) - start
    assert out @ fingers < -0.999 * np.linalg.norm(out)                 # out the way it came in ...
    assert not run.keep_out(obs).contains(start + out)[0]                # ... to outside the space kept free


def test_where_two_tips_side_by_side_do_not_fit_between_the_fingers_they_come_one_behind_the_other():
    cell = box_cell()
    cell.opening = 0.030      # 15 mm from the push line to a finger: one tip (16 mm across) with 2 mm clear, not two
    cell.object_in_holder[:3, 3] += [0.0, 0.0, 0.020]   # the palm-side face 10 mm in: the tips in line keep off the hand
    # (without a camera model the only view is the pusher's home orientation: there, turned a quarter turn
    # about its fingers, its tips lie along the push)
    cell.pusher[:3, :3] = cell.pusher[:3, :3] @ Rotation.from_euler("z", 90, degrees=True).as_matrix()
    _, run, _ = planned(cell, shift=(0.0, -0.030, 0.0))
    assert run.push is not None and run.push.sideways
    tips = invert(cell.holder)[:3, :3] @ run.push.route.orientations[-1][:, 0]
    assert abs(tips[2]) == pytest.approx(1.0, abs=1e-9)                 # along the push


def test_no_push_between_fingers_a_fingertip_does_not_fit_between():
    cell = box_cell()
    cell.opening = 0.018
    _, run, _ = planned(cell)
    assert run.push is None
    assert any("a fingertip of the pusher (16 mm) does not fit between its fingers (18 mm apart)" in note
               for note in run.campaign.notes)


def test_no_push_between_fingers_on_a_face_deeper_towards_the_palm_than_the_tips_reach():
    cell = box_cell()
    cell.object_in_holder[:3, 3] += [0.0, 0.0, -0.030]    # the box's palm-side face 60 mm towards the palm
    _, run, _ = planned(cell)
    assert run.push is None
    assert any("60 mm towards its palm (the pusher's tips fit between its fingers up to" in note
               for note in run.campaign.notes)


def test_with_pushes_between_fingers_off_the_palm_side_push_is_refused():
    _, run, _ = planned(**{"between.enabled": False})
    assert run.push is None
    assert any("comes along the holding gripper's hand from its palm side" in note for note in run.campaign.notes)
