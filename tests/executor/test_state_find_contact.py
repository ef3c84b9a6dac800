"""FindContact (dmg_executor.states.find_contact) on synthetic observations: it plans the push, hands a
run with no pose (or one too uncertain to decide by) over to a look, and the plan's end over to the way
home (once the holder has turned back)."""
from __future__ import annotations

from dataclasses import replace

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
    run.held.take(obs)     # (a certain pose: an uncertain one is looked at again first, below)
    run.campaign.measure(obs)
    outcome = FindContact().tick(run, obs)
    assert not isinstance(outcome, Transition) and run.campaign.index == 1
    note = run.campaign.notes[0]
    assert note.startswith("primitive 0 (rotation) left at 0.0 mm, -20.0 deg: no safe push: rotation: "), note
    reasons = note.split("no safe push: ")[1].split("; ")
    assert len(reasons) == len(set(reasons)) > 1


def _slab_to_press(holder_turned_deg: float):
    """A run about to press level a 40 x 60 x 60 mm slab held across its 40 mm side, tilted 3.5 deg about gripper
    1's fingers; the pusher's fingers (at home) point across the grasp axis, so a press along it needs the holder
    turned a quarter turn about its fingers first. Gripper 1 has turned `holder_turned_deg` about its grasp axis
    since the run began (at alpha 0 a rotation's pushes turn it)."""
    from scipy.spatial.transform import Rotation

    from dmg_executor.push_points import ObjectSurface
    from dmg_executor.run import Run
    from dmg_executor.settings import ExecutorSettings
    from dmg_planner.objects import Box, box_union_mesh
    from dmg_planner.primitives import Primitive, PrimitiveKind
    from synthetic import SyntheticCell, pose

    surface = ObjectSurface(*box_union_mesh([Box(np.zeros(3), np.array([0.040, 0.060, 0.060]))]), mass=0.05)
    contacts = [np.array([side * 0.020, 0.0, 0.0]) for side in (-1.0, 1.0)]
    goal = Primitive(PrimitiveKind.TRANSLATION, 0.0, np.zeros(3), contacts[0], contacts[0], 0.0, 0.0,
                     contacts[1], contacts[1], np.eye(4))
    held = np.eye(4)
    held[:3, :3] = Rotation.from_euler("z", 3.5, degrees=True).as_matrix()
    cell = SyntheticCell(pose([0.55, 0.10, 0.15], [180, 0, 0]), pose([0.51, -0.02, 0.15], [-90, 0, 0]), held)
    run = Run(ExecutorSettings.defaults(), surface, [goal], 0, 1.0, cell.time, None, None)
    run.begin(cell.observe())
    run.campaign.level_index = 0       # the press after the plan
    cell.holder[:3, :3] = cell.holder[:3, :3] @ Rotation.from_euler("x", holder_turned_deg, degrees=True).as_matrix()
    obs = cell.observe()
    run.last = obs
    run.campaign.measure(obs)
    return run, obs


def test_a_level_press_along_the_grasp_axis_is_reached_by_a_quarter_turn_of_the_holder_about_its_fingers():
    from dmg_executor.states.holder_turn import ClearForTurn

    run, obs = _slab_to_press(0.0)
    outcome = FindContact().tick(run, obs)
    assert isinstance(outcome, Transition) and isinstance(outcome.to, ClearForTurn), run.campaign.notes
    assert outcome.to.move.home is None and abs(np.rad2deg(outcome.to.move.angle)) == 90.0


def test_a_holder_turned_in_the_pushes_goes_back_first_when_only_a_quarter_turn_from_there_reaches_a_press():
    """Turned 70 deg about its grasp axis, no quarter turn of gripper 1 from where it is brings the grasp axis the
    way the pusher's fingers point: it goes back to where it started (from where one does), not leaving the press."""
    from dmg_executor.states.holder_turn import ClearForTurn

    run, obs = _slab_to_press(70.0)
    outcome = FindContact().tick(run, obs)
    assert isinstance(outcome, Transition) and isinstance(outcome.to, ClearForTurn), run.campaign.notes
    assert outcome.to.move.home is not None and np.allclose(outcome.to.move.home, run.holder_start)
    assert not any("no safe push" in note for note in run.campaign.notes)


def test_a_push_route_comes_in_along_the_line_of_the_pushers_start():
    """The last stretch of a push's route runs along the push direction onto the start itself. A T (a 112 x 58 x
    10 mm bar on a stem) held across its bar and turned about the grasp axis has its rotation pushes' starts set
    beside the push points' own lines by the fingertips; coming in along a push point's line, the tip would cut
    across the bar's corner."""
    from scipy.spatial.transform import Rotation

    from dmg_common.transforms import invert
    from dmg_executor.push_points import ObjectSurface
    from dmg_executor.run import Run
    from dmg_executor.settings import ExecutorSettings
    from dmg_planner.objects import Box, box_union_mesh
    from dmg_planner.primitives import Primitive, PrimitiveKind
    from synthetic import SyntheticCell, pose

    parts = [Box(np.zeros(3), np.array([0.112, 0.058, 0.010])),
             Box(np.array([0.0, 0.0, -0.026]), np.array([0.014, 0.034, 0.042]))]
    tee = ObjectSurface(*box_union_mesh(parts), mass=0.09)
    for turned, angle in ((10.0, 20.0), (25.0, -20.0), (35.0, 40.0)):
        holder_in_object = np.eye(4)
        holder_in_object[:3, :3] = np.column_stack([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ \
            Rotation.from_rotvec([np.deg2rad(turned), 0.0, 0.0]).as_matrix()
        after = holder_in_object.copy()
        after[:3, :3] = holder_in_object[:3, :3] @ Rotation.from_rotvec([np.deg2rad(angle), 0.0, 0.0]).as_matrix()
        contacts = [holder_in_object[:3, :3] @ [side * 0.029, 0, 0] for side in (-1, 1)]
        turn = Primitive(PrimitiveKind.ROTATION, np.deg2rad(angle), np.zeros(3), contacts[0], contacts[0], 0.0, 0.0,
                         contacts[1], contacts[1], after)
        cell = SyntheticCell(pose([0.55, 0.10, 0.15], [180, 0, 0]), pose([0.51, -0.02, 0.15], [-90, 0, 0]),
                             invert(holder_in_object), opening=0.058)
        run = Run(ExecutorSettings.defaults(), tee, [turn], 0, 1.0, cell.time, None, None)
        obs = cell.observe()
        run.begin(obs)
        run.last = obs
        run.campaign.measure(obs)
        FindContact().tick(run, obs)
        push = run.push
        assert push is not None, run.campaign.notes
        last = push.route.waypoints[-1] - push.route.waypoints[-2]
        assert np.allclose(push.route.waypoints[-1], push.start)
        assert float(last @ push.direction) / np.linalg.norm(last) > 1 - 1e-6, (turned, angle)


def uncertain(obs, sigma: float):
    """The observation with its pose `sigma` [m] uncertain in position."""
    return replace(obs, object_covariance=np.diag([sigma**2] * 3 + [1e-6] * 3))


def test_a_push_is_not_planned_from_a_pose_too_uncertain_to_tell_the_goal_but_after_a_look_for_a_better_one():
    cell = box_cell()
    run = box_run([translation([0.010, 0.0, 0.0])], cell)
    sigma = 1.5 * run.settings.tolerances.goal_position
    obs = uncertain(cell.observe(), sigma)
    run.held.take(obs)
    run.campaign.measure(obs)
    outcome = FindContact().tick(run, obs)
    assert isinstance(outcome, Transition) and isinstance(outcome.to, Look) and run.push is None
    assert run.search.seeking_certain and run.search.sought_certain
    run.search.searching = run.search.seeking_certain = False     # the look found none better
    outcome = FindContact().tick(run, obs)
    assert isinstance(outcome, Transition) and isinstance(outcome.to, Approach) and run.push is not None
    assert not run.search.sought_certain      # (the next push's end is looked at again)


def test_a_primitive_is_given_up_for_want_of_a_push_only_after_a_look_for_a_certain_pose():
    cell = box_cell()
    run = box_run([rotation(20.0)], cell, **{"push.edge_margin": 0.05, "holder.turn_deg": 0.0})
    sigma = 2.0 * run.settings.slip.position_sigma
    assert sigma < run.settings.tolerances.goal_position      # certain enough to push from, not to give up on
    obs = uncertain(cell.observe(), sigma)
    run.held.take(obs)
    run.campaign.measure(obs)
    outcome = FindContact().tick(run, obs)
    assert isinstance(outcome, Transition) and isinstance(outcome.to, Look) and run.campaign.index == 0
    run.search.searching = run.search.seeking_certain = False
    outcome = FindContact().tick(run, obs)
    assert not isinstance(outcome, Transition) and run.campaign.index == 1
    assert "no safe push" in run.campaign.notes[0]


def test_a_pose_uncertain_within_the_goal_tolerance_is_pushed_from_without_a_look():
    cell = box_cell()
    run = box_run([translation([0.010, 0.0, 0.0])], cell)
    obs = uncertain(cell.observe(), 2.0 * run.settings.slip.position_sigma)
    run.held.take(obs)
    run.campaign.measure(obs)
    outcome = FindContact().tick(run, obs)
    assert isinstance(outcome, Transition) and isinstance(outcome.to, Approach) and not run.search.sought_certain
