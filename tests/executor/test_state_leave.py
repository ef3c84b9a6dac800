"""Leave and ReturnHome (dmg_executor.states.leave) on synthetic observations: the pusher backs out of
the space kept free round the grasp along the push line; after the plan it goes home and the run ends
with its result."""
from __future__ import annotations

import numpy as np

from dmg_common.transforms import apply, invert
from dmg_executor.contract import Outcome
from dmg_executor.states.find_contact import FindContact
from dmg_executor.states.leave import Leave, ReturnHome
from synthetic import box_cell, box_run, drive, planned_translation, translation


def test_after_a_push_the_pusher_backs_out_along_the_push_line_clear_of_the_kept_free_space():
    cell, run = planned_translation()
    cell.pusher[:3, 3] = run.push.start + run.settings.push.gap * run.push.direction      # at the face, as pushed
    start = cell.pusher[:3, 3].copy()
    outcome = drive(Leave(), run, cell)
    assert isinstance(outcome.to, FindContact)
    backed = cell.pusher[:3, 3] - start
    assert np.linalg.norm(np.cross(backed, run.push.direction)) < 1e-3    # straight back along the line
    assert float(backed @ run.push.direction) < 0.0
    pusher_in_holder = apply(invert(cell.holder), cell.pusher[:3, 3])
    assert not run.keep_out(cell.observe()).contains(pusher_in_holder)[0]


def test_the_plans_end_takes_the_pusher_home_and_reports_the_errors():
    cell = box_cell()
    run = box_run([translation([0.0002, 0.0, 0.0])], cell)
    run.held.take(cell.observe())
    cell.pusher[:3, 3] += [0.0, 0.03, 0.0]            # moved off its start
    drive(ReturnHome(), run, cell)
    result = run.result
    assert result.outcome == Outcome.OK, result.message
    assert np.linalg.norm(cell.pusher[:3, 3] - run.pusher_home[:3, 3]) < 0.01
    assert result.position_error < run.settings.tolerances.goal_position and "1 primitives" in result.message


def test_the_plans_end_outside_the_goals_tolerance_is_reported_as_such():
    cell = box_cell()
    run = box_run([translation([0.005, 0.0, 0.0])], cell)      # 5 mm left to do
    run.held.take(cell.observe())
    drive(ReturnHome(), run, cell)
    assert run.result.outcome == Outcome.OUT_OF_TOLERANCE
    assert abs(run.result.position_error - 0.005) < 1e-6
    assert "outside the tolerance" in run.result.message


def test_the_plans_end_is_judged_still_from_the_held_pose_then_the_pusher_sets_off_home():
    cell = box_cell()
    run = box_run([translation([0.0002, 0.0, 0.0])], cell)
    run.held.take(cell.observe())              # one pose in the held pose: it may average more first
    cell.pusher[:3, 3] += [0.0, 0.03, 0.0]
    start = cell.pusher.copy()
    state = ReturnHome()
    wait = run.settings.campaign.judge_wait
    while cell.time < wait - 0.05:
        command = state.tick(run, cell.observe())
        assert not np.any(command.pusher)      # still while it waits
        cell.move(command)
    assert np.array_equal(cell.pusher, start)
    cell.time += 0.1
    cell.move(state.tick(run, cell.observe()))       # judged: on its way
    cell.object_in_holder[:3, 3] += [0.0, 0.004, 0.0]      # seen askew on the way: 4 mm off
    drive(state, run, cell)
    assert run.result.outcome == Outcome.OK and run.result.position_error < 0.001
