"""PlanExecutor (dmg_executor.controller) on a synthetic cell: the whole state machine - monitors,
belief, states and their transitions - from the first observation to the result, without MuJoCo."""
from __future__ import annotations

import numpy as np

from dmg_executor.contract import Outcome, Step
from dmg_executor.controller import PlanExecutor
from dmg_executor.settings import ExecutorSettings
from dmg_executor.states.leave import ReturnHome
from synthetic import box_cell, box_run, translation


def executor_for(primitives, cell, **overrides) -> PlanExecutor:
    surface = box_run(primitives, cell).surface
    return PlanExecutor(ExecutorSettings.defaults(**overrides), surface, primitives, 0, 1.0, cell.time)


def test_a_translation_runs_through_every_step_to_an_ok_result_with_the_pusher_back_home():
    cell = box_cell()
    executor = executor_for([translation([0.010, 0.0, 0.0])], cell)
    home = cell.pusher[:3, 3].copy()
    steps, states = [], []
    while not executor.done and cell.time < 120.0:
        command = executor.update(cell.observe())
        steps.append(executor.step)
        states.append(type(executor.state).__name__)
        cell.move(command, surface=executor.run.surface, tip_radius=executor.settings.gripper.tip_radius)
    result = executor.result
    assert result is not None and result.outcome == Outcome.OK, result
    # (the first tick plans the push: its step is already APPROACH)
    assert [s for i, s in enumerate(steps) if i == 0 or steps[i - 1] != s][:4] == \
        [Step.APPROACH, Step.EXECUTE, Step.LEAVE, Step.FIND_CONTACT]
    assert isinstance(executor.state, ReturnHome) and "ReturnHome" in states
    assert result.position_error < executor.settings.tolerances.goal_position
    assert np.linalg.norm(cell.pusher[:3, 3] - home) < 0.01
    progress = executor.progress()
    assert progress.primitive_count == len(executor.primitives) and progress.pushes >= 0


def test_the_object_leaving_the_grip_ends_the_run_object_lost_with_the_grip_closed():
    cell = box_cell()
    executor = executor_for([translation([0.010, 0.0, 0.0])], cell)
    executor.update(cell.observe())
    cell.opening = 0.0                                   # the fingers closed on nothing
    command = executor.update(cell.observe())
    assert executor.result.outcome == Outcome.OBJECT_LOST and "left gripper 1" in executor.result.message
    assert command.holder_grip.max_force == executor.settings.grip.hold_force and not command.pusher.any()


def test_a_step_that_does_not_finish_in_time_ends_the_run_step_timeout():
    """(With the time limit under the time a stalled arm is given, the limit ends the run first.)"""
    cell = box_cell()
    stall_time = ExecutorSettings.defaults().approach.stall_time
    executor = executor_for([translation([0.010, 0.0, 0.0])], cell, **{"limits.step_timeout": stall_time / 2})
    executor.update(cell.observe())
    while not executor.done:                             # the arms never move
        cell.time += 0.5
        cell.seen_at = cell.time
        executor.update(cell.observe())
    assert executor.result.outcome == Outcome.STEP_TIMEOUT, executor.result
    assert executor.result.message.startswith("APPROACH of primitive 0")


def test_cancel_ends_the_run_and_every_later_tick_holds_the_object():
    cell = box_cell()
    executor = executor_for([translation([0.010, 0.0, 0.0])], cell)
    executor.update(cell.observe())
    executor.cancel()
    assert executor.result.outcome == Outcome.CANCELED
    later = executor.update(cell.observe())
    assert later.holder_grip.max_force == executor.settings.grip.hold_force and not later.pusher.any()


def test_a_pusher_that_never_moves_gives_its_pushes_up_and_the_run_ends_with_what_is_left():
    cell = box_cell()
    executor = executor_for([translation([0.010, 0.0, 0.0])], cell)
    while not executor.done and cell.time < 300.0:      # the arms never move
        command = executor.update(cell.observe())
        assert command.holder_grip is None or command.holder_grip.max_force == executor.settings.grip.hold_force
        cell.time += 0.1
        cell.seen_at = cell.time
    assert executor.result.outcome == Outcome.OUT_OF_TOLERANCE, executor.result
    assert abs(executor.result.position_error - 0.010) < 1e-6
    assert any("given up" in note for note in executor.notes)
    assert any("no safe push" in note for note in executor.notes)
