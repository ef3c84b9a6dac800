"""PlanExecutor (dmg_executor.controller) on a synthetic cell: the whole state machine - monitors,
belief, states and their transitions - from the first observation to the result, without MuJoCo."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply, invert
from dmg_executor.contract import Outcome, Step
from dmg_executor.controller import PlanExecutor
from dmg_executor.settings import ExecutorSettings
from dmg_executor.states.leave import ReturnHome
from synthetic import box_cell, box_run, rotation, translation


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


def test_a_step_that_does_not_finish_in_time_ends_the_run_step_timeout_with_the_runs_notes():
    """(With the time limit under the time a stalled arm is given, the limit ends the run first.)"""
    cell = box_cell()
    stall_time = ExecutorSettings.defaults().approach.stall_time
    executor = executor_for([translation([0.010, 0.0, 0.0])], cell, **{"limits.step_timeout": stall_time / 2})
    executor.update(cell.observe())
    executor.run.note("an earlier push went on unseen")
    while not executor.done:                             # the arms never move
        cell.time += 0.5
        cell.seen_at = cell.time
        executor.update(cell.observe())
    assert executor.result.outcome == Outcome.STEP_TIMEOUT, executor.result
    assert executor.result.message.startswith("APPROACH of primitive 0")
    assert executor.result.message.endswith("; an earlier push went on unseen")


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


def test_a_push_whose_way_loses_the_object_twice_is_not_planned_a_third_time():
    """The camera sees the object only while the pusher is still (a made-up blind spot on every way to the
    push): each time the object goes unseen on the way it is looked for and found; the second time that
    push's direction is given up, and the run ends with the translation left."""
    cell = box_cell()
    executor = executor_for([translation([0.010, 0.0, 0.0])], cell, **{"monitors.stale_after_held": 0.5})
    while not executor.done and cell.time < 300.0:
        command = executor.update(cell.observe())
        moving = bool(np.any(command.pusher)) and executor.step == Step.APPROACH
        cell.move(command, seen=not moving, surface=executor.run.surface,
                  tip_radius=executor.settings.gripper.tip_radius)
    lost = [note for note in executor.notes if "on the way to a push" in note]
    assert len(lost) == 2 and lost[1].endswith("the second time this way: no push this way again")
    assert executor.result.outcome == Outcome.OUT_OF_TOLERANCE, executor.result


def test_a_slip_seen_with_nothing_touching_the_object_is_looked_at_again_once_before_it_ends_the_run():
    """On the way to the push a view shows the held box 8 mm off (a misleading lone-tag pose, sure of
    itself): the run goes on to look at it again; the same seen again before any push is a slip."""
    cell = box_cell()
    executor = executor_for([translation([0.010, 0.0, 0.0])], cell)
    for _ in range(5):      # the grip's reference: the mean of several poses (one alone could be the stray)
        cell.move(executor.update(cell.observe()))
    assert executor.step == Step.APPROACH
    held = cell.object_in_holder.copy()
    misleading = held.copy()
    misleading[:3, 3] += [0.0, 0.0, 0.008]

    def seen_off(ticks: int) -> None:
        for _ in range(ticks):
            cell.object_in_holder = misleading
            command = executor.update(cell.observe())
            cell.object_in_holder = held
            if executor.done:
                return
            cell.move(command)

    seen_off(executor.settings.slip.poses + 2)
    assert not executor.done
    assert any("with nothing touching it: looked at again from other views" in note for note in executor.notes)
    seen_off(executor.settings.slip.poses + 2)
    assert executor.done and executor.result.outcome == Outcome.SLIP, executor.result


def _rotation_run(follow: float, give: float, stuck_after_deg: float = np.inf, about=(1.0, 0.0, 0.0)) -> PlanExecutor:
    """A 20 deg rotation of the box on the synthetic cell, to its end. Once the pusher's tip has pressed `give`
    [m] into the box, the box turns about the grasp axis `follow` deg per deg the tip sweeps round it,
    up to `stuck_after_deg` (then it sticks: the pusher slides on along the face) - or, given another axis
    `about` (holder frame), about that one instead (it tilts). The camera's images come
    every other tick, each a tick old when it arrives; the arms take up a commanded twist with a lag (a
    pusher closing its gap overruns the face as the push begins)."""
    cell = box_cell()
    executor = executor_for([rotation(20.0)], cell)
    surface, tip_radius = executor.run.surface, executor.settings.gripper.tip_radius
    start, image, turned = cell.object_in_holder.copy(), (cell.object_in_holder.copy(), cell.time), 0.0
    holder_twist, pusher_twist = np.zeros(6), np.zeros(6)
    while not executor.done and cell.time < 120.0:
        command = executor.update(replace(cell.observe(), object_in_holder=image[0], object_time=image[1]))
        if round(cell.time / 0.02) % 2 == 0:
            image = (cell.object_in_holder.copy(), cell.time)
        holder_twist += 0.3 * (command.holder - holder_twist)
        pusher_twist += 0.3 * (command.pusher - pusher_twist)
        command = replace(command, holder=holder_twist.copy(), pusher=pusher_twist.copy())
        before = apply(invert(cell.holder), cell.pusher[:3, 3])
        cell.move(command, seen=False)
        after = apply(invert(cell.holder), cell.pusher[:3, 3])     # (holder frame: the grasp axis is x)
        swept = float(np.arctan2(before[1] * after[2] - before[2] * after[1], before[1:] @ after[1:]))
        # the tip presses along its arc round the grasp axis, `give` into the face before the box turns
        ahead = np.sign(swept) * np.cross([1.0, 0.0, 0.0], after) / max(np.linalg.norm(after[1:]), 1e-9)
        touching = surface.inside(apply(invert(cell.object_in_holder), after + (tip_radius + give) * ahead)[None])[0]
        if executor.step == Step.EXECUTE and touching and abs(np.rad2deg(turned)) < stuck_after_deg:
            turn = np.eye(4)
            turn[:3, :3] = Rotation.from_rotvec(follow * swept * np.asarray(about)).as_matrix()
            cell.object_in_holder = turn @ cell.object_in_holder
            turned = Rotation.from_matrix(cell.object_in_holder[:3, :3] @ start[:3, :3].T).as_rotvec()[0]
    return executor


def test_a_rotation_push_whose_object_turns_slower_than_the_pusher_sweeps_is_not_taken_for_stalled():
    """The box turns only after the contact's give and then 0.75 deg per deg of the tip's sweep, seen every
    other tick: one push does the rotation, none is stopped as stalled or missed."""
    executor = _rotation_run(follow=0.75, give=0.0015)
    assert executor.result.outcome == Outcome.OK, executor.result
    assert not any("stopped" in note or "missed" in note for note in executor.notes), executor.notes


def test_a_rotation_push_whose_object_sticks_is_stopped_within_the_stall_sweep():
    """The box sticks after 5 deg: the push stops (grip closed) before the pusher has swept much further."""
    executor = _rotation_run(follow=0.75, give=0.0015, stuck_after_deg=5.0)
    stalls = [note for note in executor.notes if "stopped turning with the pusher" in note]
    assert stalls, executor.notes
    assert abs(float(stalls[0].split("stopped after ")[1].split(" deg")[0])) < 5.0 + 2.0, stalls[0]


def test_a_rotation_push_that_tilts_the_object_instead_of_turning_it_is_stopped_and_not_pushed_there_again():
    """(The box here tilts about gripper 1's fingers as far as a turn would have gone.)"""
    executor = _rotation_run(follow=0.75, give=0.0015, about=(0.0, 0.0, 1.0))
    tilted = [note for note in executor.notes if "tilted" in note]
    assert tilted and tilted[0].endswith("not pushed there again"), executor.notes
    assert executor.run.memory.missed, executor.notes


class _Faulty(ReturnHome):
    """A state with a bug in it."""

    def tick(self, run, obs):
        raise ZeroDivisionError("a bug")


def test_an_error_in_a_state_ends_the_run_internal_error_with_the_arms_still_and_the_object_held():
    cell = box_cell()
    executor = executor_for([translation([0.010, 0.0, 0.0])], cell)
    executor.update(cell.observe())
    executor.run.note("a push went on unseen")
    executor.state = _Faulty()
    command = executor.update(cell.observe())
    result = executor.result
    assert result.outcome == Outcome.INTERNAL_ERROR and "ZeroDivisionError: a bug" in result.message
    assert result.message.endswith("; a push went on unseen")      # what the run did before
    assert "_Faulty" in result.message and "ZeroDivisionError" in executor.failure
    assert not np.any(command.holder) and not np.any(command.pusher)
    assert command.holder_grip.max_force == executor.settings.grip.hold_force
    assert executor.update(cell.observe()).holder_grip.max_force == executor.settings.grip.hold_force
