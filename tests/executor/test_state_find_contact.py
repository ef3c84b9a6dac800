"""FindContact (dmg_executor.states.find_contact) on synthetic observations: it plans the push, hands a
run with no pose over to a look, and the plan's end over to the way home (once the holder has turned back)."""
from __future__ import annotations

import numpy as np

from dmg_executor.contract import Step
from dmg_executor.states.approach import Approach
from dmg_executor.states.base import Transition
from dmg_executor.states.find_contact import FindContact
from dmg_executor.states.leave import ReturnHome
from dmg_executor.states.look import Look
from synthetic import box_cell, box_run, rotation, translation


def test_a_translation_is_planned_as_a_push_square_onto_the_face_towards_the_pusher():
    cell = box_cell()
    run = box_run([translation([0.010, 0.0, 0.0])], cell)      # the object 10 mm along gripper 1's -y
    obs = cell.observe()
    run.campaign.measure(obs)
    outcome = FindContact().tick(run, obs)
    assert isinstance(outcome, Transition) and isinstance(outcome.to, Approach) and outcome.command is not None
    push = run.push
    # gripper 1's -y is the base's +y: pushed on the face 50 mm towards the pusher, square onto it
    assert np.allclose(push.direction, [0.0, 1.0, 0.0], atol=1e-9)
    assert np.allclose(push.contact.normal, [1.0, 0.0, 0.0], atol=1e-6)
    face_y = cell.holder[1, 3] - 0.050
    assert push.start[1] < face_y - run.settings.push.gap / 2          # the pusher starts short of the face
    assert run.pilot.route is push.route and np.allclose(push.route.waypoints[-1], push.start)
    assert run.campaign.error_before_push == 0.010


def test_no_pose_yet_hands_over_to_a_look_in_the_same_tick():
    cell = box_cell()
    run = box_run([translation([0.010, 0.0, 0.0])], cell)
    run.held.await_fresh()
    outcome = FindContact().tick(run, cell.observe())
    assert isinstance(outcome, Transition) and isinstance(outcome.to, Look) and outcome.command is None
    assert run.push is None


def test_a_primitive_within_tolerance_is_passed_and_the_plans_end_goes_home():
    cell = box_cell()
    run = box_run([translation([0.0002, 0.0, 0.0])], cell)      # 0.2 mm: within the position tolerance
    run.held.take(cell.observe())
    obs = cell.observe()
    run.campaign.measure(obs)
    outcome = FindContact().tick(run, obs)
    assert isinstance(outcome, Transition) and isinstance(outcome.to, ReturnHome) and outcome.command is None
    assert outcome.to.step == Step.LEAVE and run.campaign.over


def test_the_last_primitive_finished_as_seen_with_the_holder_turned_is_judged_once_turned_back():
    cell = box_cell()
    run = box_run([translation([0.0002, 0.0, 0.0])], cell)
    run.held.take(cell.observe())
    run.holder_turns.far_side = True
    obs = cell.observe()
    run.campaign.measure(obs)
    outcome = FindContact().tick(run, obs)
    assert not isinstance(outcome, Transition)
    assert run.holder_turns.far_side_pushed and not run.campaign.over
    assert run.campaign.pushes == 1           # (the look counts as a push: such turns are bounded)


def test_a_rotation_no_push_can_do_is_left_with_a_note_naming_it_and_each_reason_once():
    """(Rotation is kind 0: the note once called it a level press.) Here every rotation push lies within a
    50 mm edge margin, and the holder may not turn the object for another."""
    cell = box_cell()
    run = box_run([rotation(20.0)], cell, **{"push.edge_margin": 0.05, "holder.turn_deg": 0.0})
    obs = cell.observe()
    run.campaign.measure(obs)
    outcome = FindContact().tick(run, obs)
    assert not isinstance(outcome, Transition) and run.campaign.index == 1
    note = run.campaign.notes[0]
    assert note.startswith("primitive 0 (rotation) left at 0.0 mm, -20.0 deg: no safe push: rotation: "), note
    reasons = note.split("no safe push: ")[1].split("; ")
    assert len(reasons) == len(set(reasons)) > 1
