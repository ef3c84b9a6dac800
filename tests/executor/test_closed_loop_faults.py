"""The executor in the closed loop (real MuJoCo, rendering and tag detection in one process), faults:
slips and the slip rules, objects knocked out, steps that time out, workspace limits, arms and wrists that
stop, and pushes stopped before they become a slip."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from executor_fixtures import box_surface, bracket_run, control_tick, loop_parts, translation_executor  # noqa: F401

pytestmark = pytest.mark.sim


def in_phase(executor, phase) -> bool:
    """Is the executor in EXECUTE, in this phase of the push (dmg_executor.states.execute.Phase)?"""
    from dmg_executor.states.execute import Execute

    return isinstance(executor.state, Execute) and executor.state.phase == phase


def test_a_push_outside_the_workspace_is_refused_before_anything_moves(loop_parts, box_surface):
    from dmg_executor.contract import Outcome

    cell, loop, _, _ = loop_parts
    # A workspace that holds both grippers where they are, but not the space under the object.
    executor = translation_executor(loop_parts, box_surface, **{"limits.workspace_min": [0.3, -0.5, 0.12]})
    pusher_before = cell.grasp_pose("arm2")[:3, 3]
    outcome = loop.run(executor, time_limit=30)
    assert outcome.outcome == Outcome.LIMIT_VIOLATION and "outside the workspace" in outcome.message
    assert np.linalg.norm(cell.grasp_pose("arm2")[:3, 3] - pusher_before) < 0.002
    assert cell.gripper_status("arm1").max_force == pytest.approx(15.0)


def _translation_under_way(loop_parts, box_surface):
    """A translation's executor 50 ticks into its run: the pusher has set off."""
    loop = loop_parts[1]
    executor = translation_executor(loop_parts, box_surface)
    for _ in range(50):
        control_tick(loop, executor)
    return executor


def test_an_object_slipping_in_the_closed_grip_closes_the_grip_at_once_and_ends_the_run(loop_parts, box_surface):
    """Gripper 1 goes weak on the way to a push and the box slides out by its weight. Nothing touches the box,
    so the slip is looked at again - with the grip closed at the hold force at once - and the run ends
    there: SLIP once seen again, or OBJECT_LOST if the box was already gone (its fingers closed on nothing)."""
    from dmg_executor.contract import Outcome

    cell, loop, _, _ = loop_parts
    executor = _translation_under_way(loop_parts, box_surface)
    cell.command_gripper("arm1", 0.0, 0.3)      # fault: gripper 1 goes weak, the box slides out by its weight
    outcome = loop.run(executor, time_limit=30)
    assert outcome.outcome in (Outcome.SLIP, Outcome.OBJECT_LOST), outcome
    assert any("the object moved" in note and "looked at again" in note for note in executor.notes)
    assert outcome.primitives_completed == 0 and outcome.duration < 5.0     # no push was tried after it
    assert cell.gripper_status("arm1").max_force == pytest.approx(15.0)   # the executor closed the grip again


def test_an_object_knocked_out_of_the_grip_ends_the_run_saying_so(loop_parts, box_surface):
    """A dropped object is told from one the camera lost: gripper 1's fingers close on nothing."""
    import mujoco

    from dmg_executor.contract import Outcome

    cell, loop, _, _ = loop_parts
    executor = _translation_under_way(loop_parts, box_surface)
    knocked = cell.time
    body = mujoco.mj_name2id(cell.model, mujoco.mjtObj.mjOBJ_BODY, "object")
    cell.data.xfrc_applied[body, :3] = 60.0 * cell.grasp_pose("arm1")[:3, 1]   # fault: a knock across the fingers
    cell.run(0.1)
    cell.data.xfrc_applied[body] = 0.0
    outcome = loop.run(executor, time_limit=30)
    assert outcome.outcome == Outcome.OBJECT_LOST and "left gripper 1" in outcome.message, outcome.message
    assert cell.time - knocked < 2.0        # at once, not after the lost-pose limit (10 s)
    assert np.linalg.norm(cell.object_in_gripper("arm1")[:3, 3]) > 0.05     # it did fall out


def test_a_step_that_takes_too_long_ends_with_step_timeout_and_the_grip_held(loop_parts, box_surface):
    from dmg_executor.contract import Outcome

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface, **{"limits.step_timeout": 0.5})   # the approach needs seconds
    outcome = loop.run(executor, time_limit=30)
    assert outcome.outcome == Outcome.STEP_TIMEOUT and "APPROACH" in outcome.message
    assert cell.gripper_status("arm1").max_force == pytest.approx(15.0)
    cell.run(0.3)                                   # the arms' watchdog has stopped them
    assert np.abs(cell.joint_state().velocity).max() < 0.01


def test_a_pusher_whose_wrist_cannot_turn_on_the_way_goes_on_to_the_push_start(loop_parts, box_surface):
    """On the way to the push start the pusher turns its camera to the object at each waypoint; a wrist
    that cannot turn (its command's turn zeroed there: joints at their limits) leaves it at the waypoint
    turned otherwise. That view is not needed to go on: it passes the waypoint after `stall_time` and
    the push is made (without the rule the push was given up, never again that way)."""
    from dmg_common.transforms import turn_between
    from dmg_executor.contract import Outcome
    from dmg_executor.states.approach import Homeward

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)
    run = executor.run
    passed_turned, ends = [], cell.time + 60
    while not executor.done and cell.time < ends:
        loop.perceive()
        observation = loop.observe()
        before = run.pilot.route.index if executor.step.name == "APPROACH" else None
        command = executor.update(observation)
        on_the_way = (executor.step.name == "APPROACH" and run.push is not None
                      and not isinstance(executor.state, Homeward)
                      and run.pilot.route.index < len(run.push.route.waypoints) - 1)
        if on_the_way:
            command.pusher[3:] = 0.0                 # fault: the wrist does not turn on the way
        if before is not None and executor.step.name == "APPROACH" and run.pilot.route.index == before + 1:
            passed_turned.append(turn_between(run.pilot.route.orientations[before], observation.pusher[:3, :3]))
        loop.apply(command)
        cell.run(loop.control_period)
    outcome = executor.result
    assert outcome is not None and outcome.outcome == Outcome.OK, outcome
    assert "given up" not in outcome.message, outcome.message
    assert passed_turned and max(passed_turned) > executor.settings.approach.waypoint_turn_tolerance, passed_turned   # passed unturned


def test_a_pusher_that_cannot_get_to_the_push_start_gives_that_push_up_and_goes_home(loop_parts, box_surface):
    from dmg_executor.contract import Outcome

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)
    home = cell.grasp_pose("arm2")[:3, 3]
    while executor.step.name != "APPROACH" and not executor.done:
        loop.perceive()
        loop.apply(executor.update(loop.observe()))
        cell.run(loop.control_period)
    approach_until = cell.time + 1.0              # part of the way
    while cell.time < approach_until:
        loop.perceive()
        loop.apply(executor.update(loop.observe()))
        cell.run(loop.control_period)
    assert np.linalg.norm(cell.grasp_pose("arm2")[:3, 3] - home) > 0.02
    stuck_until = cell.time + executor.settings.approach.stall_time + 1.0
    while cell.time < stuck_until:               # fault: the pushing arm does not move (a joint at its limit)
        loop.perceive()
        command = executor.update(loop.observe())
        command.pusher[:] = 0.0
        loop.apply(command)
        cell.run(loop.control_period)
    assert any("given up" in note for note in executor.notes), executor.notes
    assert len(executor.run.memory.unreachable) == 1
    # The box's only face square to this motion is the one it gave up: the primitive is left with a note,
    # the pusher back where it started, the grip held.
    outcome = loop.run(executor, time_limit=60)
    assert outcome.outcome == Outcome.OUT_OF_TOLERANCE, outcome.message
    assert "could not get to where any push" in outcome.message
    assert np.linalg.norm(cell.grasp_pose("arm2")[:3, 3] - home) < 0.01
    assert cell.gripper_status("arm1").max_force == pytest.approx(executor.settings.grip.hold_force)


def test_a_holder_turn_that_stops_short_goes_back_and_is_not_tried_again(bracket_run):
    from dmg_common.transforms import turn_between
    from dmg_executor.contract import Outcome
    from dmg_executor.states.holder_turn import HolderHome, TurnHolder

    cell, loop, make = bracket_run
    executor = make()
    holder_before = cell.grasp_pose("arm1")
    stuck_from, ends = None, cell.time + 150
    while not executor.done and cell.time < ends:
        loop.perceive()
        command = executor.update(loop.observe())
        state = executor.state          # the holder moving (the pusher clear), not turning back
        if isinstance(state, HolderHome) or (isinstance(state, TurnHolder) and not state.back):
            stuck_from = cell.time if stuck_from is None else stuck_from
            turned = state.turned if isinstance(state, TurnHolder) else 0.0
            if abs(turned) > np.deg2rad(30):     # fault: the holding wrist stops 30 deg into the turn
                command.holder[:] = 0.0
        loop.apply(command)
        cell.run(loop.control_period)
    assert stuck_from is not None and executor.done
    outcome = executor.result
    # The far-side push is left; the run ends on what the other pushes reach, within the goal's tolerance or not.
    assert outcome.outcome in (Outcome.OK, Outcome.OUT_OF_TOLERANCE), outcome.message
    assert "could not turn the object (stopped at" in outcome.message and "into the holding gripper" in outcome.message
    assert outcome.message.count("turned the object -180 deg") == 1          # tried once
    holder_after = cell.grasp_pose("arm1")                                    # turned back, held
    assert np.rad2deg(turn_between(holder_after[:3, :3], holder_before[:3, :3])) < 3.0
    assert cell.gripper_status("arm1").max_force == pytest.approx(executor.settings.grip.hold_force)


def test_one_stray_object_pose_is_no_slip_but_poses_that_keep_showing_it_are(loop_parts, box_surface):
    from dataclasses import replace

    from dmg_executor.contract import Outcome

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)

    def tick(shift: float = 0.0) -> None:
        loop.perceive()
        observation = loop.observe()
        if shift:     # the estimate a mirrored lone tag gives: the object 14 mm off, freshly seen
            moved = observation.object_in_holder.copy()
            moved[:3, 3] += [0.0, shift, 0.0]
            observation = replace(observation, object_in_holder=moved, object_time=observation.time)
        loop.apply(executor.update(observation))
        cell.run(loop.control_period)

    while executor.step.name != "APPROACH" and not executor.done:
        tick()
    tick(0.014)
    for _ in range(5):
        tick()
    assert not executor.done, executor.result
    for _ in range(executor.settings.slip.poses):
        tick(0.014)
    # nothing touches the object on the way to a push: looked at again (the grip closed) before a slip ends it
    assert not executor.done and "with nothing touching it: looked at again" in executor.notes[-1]
    for _ in range(executor.settings.slip.poses):
        tick(0.014)
    assert executor.done and executor.result.outcome == Outcome.SLIP, executor.result
    assert cell.gripper_status("arm1").max_force == pytest.approx(executor.settings.grip.hold_force)


def test_a_held_object_seen_moved_is_a_slip_only_by_poses_certain_of_their_position(loop_parts, box_surface):
    from dataclasses import replace

    from dmg_executor.contract import Outcome

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)

    def tick(shift: float = 0.0, sigma: float | None = None) -> None:
        loop.perceive()
        observation = loop.observe()
        if sigma is not None:     # freshly seen `shift` off along the fingers, this uncertain in position
            moved = observation.object_in_holder.copy()
            moved[:3, 3] += [0.0, shift, 0.0]
            covariance = np.diag([sigma, sigma, sigma, 0.01, 0.01, 0.01]) ** 2
            observation = replace(observation, object_in_holder=moved, object_time=observation.time,
                                  object_covariance=covariance)
        loop.apply(executor.update(observation))
        cell.run(loop.control_period)

    # The grip closes on a pose 7 mm off but 3 mm uncertain: the poses seen well after it replace it.
    while executor.step.name != "APPROACH" and not executor.done:
        tick(0.007, 0.003)
    for _ in range(5 * executor.settings.slip.poses):
        tick()
    assert not executor.done, executor.result
    for _ in range(3 * executor.settings.slip.poses):      # 14 mm off, 3 mm uncertain: no evidence
        tick(0.014, 0.003)
    assert not executor.done, executor.result
    for _ in range(executor.settings.slip.poses):
        tick(0.014, 0.0002)
    assert not executor.done and "with nothing touching it: looked at again" in executor.notes[-1]
    for _ in range(executor.settings.slip.poses):
        tick(0.014, 0.0002)
    assert executor.done and executor.result.outcome == Outcome.SLIP, executor.result
    assert "moved 14." in executor.result.message and "uncertainty 0.2 mm" in executor.result.message


def test_a_pushed_object_seen_tilted_is_a_slip_only_by_poses_certain_of_their_tilt(loop_parts, box_surface):
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    from dmg_executor.contract import Outcome
    from dmg_executor.states.execute import Phase

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)
    tilted = Rotation.from_rotvec([0.0, np.deg2rad(9.0), 0.0]).as_matrix()    # about holder y: off the grasp axis

    def tick(sigma_deg: float | None = None) -> None:
        loop.perceive()
        observation = loop.observe()
        if sigma_deg is not None:     # freshly seen 9 deg tilted, this uncertain in its tilt
            pose = observation.object_in_holder.copy()
            pose[:3, :3] = tilted @ pose[:3, :3]
            covariance = np.diag([1e-3, 1e-3, 1e-3, 0.01, np.deg2rad(sigma_deg), 0.0]) ** 2
            observation = replace(observation, object_in_holder=pose, object_time=observation.time,
                                  object_covariance=covariance)
        loop.apply(executor.update(observation))
        cell.run(loop.control_period)

    while not (executor.step.name == "EXECUTE" and in_phase(executor, Phase.PUSH)) and not executor.done:
        tick()
    for _ in range(3 * executor.settings.slip.poses):      # a lone tag seen obliquely: 4 deg uncertain
        tick(4.0)
    assert not executor.done, executor.result
    for _ in range(executor.settings.slip.poses):
        tick(0.5)
    assert executor.done and executor.result.outcome == Outcome.SLIP, executor.result
    assert "tilted 9.0 deg" in executor.result.message and "uncertainty 0.5 deg" in executor.result.message


@pytest.mark.parametrize("widened, stops", [(0.001, False), (0.003, True)])
def test_a_push_stops_when_the_object_forces_the_loosened_fingers_wider_than_its_grasp(loop_parts, box_surface,
                                                                                        widened, stops):
    """The fingers' opening is felt even when the camera sees nothing: an object turning over in the
    loosened grip spreads them. Reported `monitors.forced_open` wider than the plan's widest grasp mid-push, the
    push stops within a tick (grip to the hold force, a note) and the run goes on; 1 mm wider, it does not."""
    from dataclasses import replace

    from dmg_executor.states.execute import Phase

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)
    deadline, widest = cell.time + 60.0, executor.run.campaign.widest_grasp
    while not (executor.step.name == "EXECUTE" and in_phase(executor, Phase.PUSH)) and cell.time < deadline:
        control_tick(loop, executor)
    assert in_phase(executor, Phase.PUSH), (executor.step, executor.result)
    loop.perceive()
    observation = loop.observe()
    spread = replace(observation, opening=max(observation.opening, widest) + widened)
    command = executor.update(spread)
    assert in_phase(executor, Phase.TIGHTEN) is stops, (executor.state, widest, observation.opening)
    noted = [note for note in executor.notes if "forced gripper 1's fingers" in note]
    if stops:
        assert executor.settings.monitors.forced_open < widened and command.holder_grip.max_force == executor.settings.grip.hold_force
        assert len(noted) == 1 and "3.0 mm wider" in noted[0], executor.notes
        assert not executor.done     # the run goes on
    else:
        assert not noted and command.holder_grip.max_force < executor.settings.grip.hold_force


@pytest.mark.parametrize("tilt_deg, stops", [(4.5, True), (3.0, False), (8.0, False)])
def test_a_push_stops_when_the_object_tilts_most_of_the_way_to_a_slip(loop_parts, box_surface, tilt_deg, stops):
    """A pushed object seen for certain tilted `monitors.push_tilt_stop` of `slip_angle_deg` (4 of 6 deg) off the grasp axis
    since the push began stops the push within the tick (grip to the hold force, a note) and the run goes on,
    rather than pushing on into a SLIP; 3 deg, the push goes on; one pose past 6 deg is the SLIP rule's (a slip
    after `slip_poses` in a row, see the test above), the push goes on."""
    from dataclasses import replace

    from dmg_executor.states.execute import Phase

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)
    deadline = cell.time + 60.0
    while not (executor.step.name == "EXECUTE" and in_phase(executor, Phase.PUSH)) and cell.time < deadline:
        control_tick(loop, executor)
    assert in_phase(executor, Phase.PUSH), (executor.step, executor.result)
    assert np.rad2deg(executor.settings.monitors.push_tilt_stop * executor.settings.slip.angle) == pytest.approx(4.0)
    loop.perceive()
    observation = loop.observe()
    tilted = executor.run.pushed.reference.copy()      # turned about gripper 1's y, through the object's origin
    tilted[:3, :3] = Rotation.from_euler("y", tilt_deg, degrees=True).as_matrix() @ tilted[:3, :3]
    command = executor.update(replace(observation, object_in_holder=tilted, object_time=observation.time,
                                      object_covariance=None))
    assert in_phase(executor, Phase.TIGHTEN) is stops, executor.state
    noted = [note for note in executor.notes if "tilted" in note and "stopped" in note]
    if stops:
        assert command.holder_grip.max_force == executor.settings.grip.hold_force
        assert len(noted) == 1 and f"tilted {tilt_deg:.1f} deg" in noted[0], executor.notes
        assert not executor.done     # the run goes on
    else:
        assert not noted and command.holder_grip.max_force < executor.settings.grip.hold_force


def test_a_pusher_stuck_backing_out_or_on_its_way_home_goes_on_from_where_it_is(loop_parts, box_surface):
    """Backing out after a push, and again on its way home after the last one, the pushing arm stops
    (a joint at its limit): after `stall_time` the run goes on from there, and ends there, with
    notes instead of waiting out the step's time limit."""
    from dmg_executor.contract import Outcome
    from dmg_executor.states.leave import ReturnHome

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)
    while executor.step.name != "LEAVE" and not executor.done:
        control_tick(loop, executor)
    stuck_until = cell.time + executor.settings.approach.stall_time + 1.0
    while cell.time < stuck_until and executor.step.name == "LEAVE":   # fault: the pushing arm does not move
        control_tick(loop, executor, pusher_stuck=True)
    assert executor.step.name != "LEAVE" and not executor.done, (executor.step, executor.result)
    assert any("stopped backing out" in note for note in executor.notes), executor.notes
    deadline = cell.time + 60.0
    while not isinstance(executor.state, ReturnHome) and not executor.done and cell.time < deadline:
        control_tick(loop, executor)
    stuck_until = cell.time + executor.settings.approach.stall_time + 1.0
    while cell.time < stuck_until and not executor.done:    # the same on the way home
        control_tick(loop, executor, pusher_stuck=True)
    assert executor.done, executor.step
    assert executor.result.outcome == Outcome.OK, executor.result.message
    assert "short of where it started" in executor.result.message


def test_a_tilt_seen_after_the_push_is_no_slip_while_the_grip_has_no_certain_pose(loop_parts, box_surface):
    """Once the grip has closed after a push, only a pose certain of its position can show a slip:
    poses that cannot be held (here stale ones after a push the camera lost) may be sure of a tilt
    they got wrong (sim: a pose 7 mm off with 0.4 deg of tilt uncertainty raised a false SLIP)."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    from dmg_executor.states.execute import Phase

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)
    tilted = Rotation.from_rotvec([0.0, np.deg2rad(9.0), 0.0]).as_matrix()    # about holder y: off the grasp axis
    s = executor.settings
    deadline = cell.time + 60.0

    def tick(freeze: float | None = None, tilt: bool = False) -> None:
        loop.perceive()
        observation = loop.observe()
        if freeze is not None:    # the camera lost the object: its last pose from `freeze` on
            observation = replace(observation, object_time=freeze)
        if tilt:                  # a stale pose, seen 9 deg tilted and sure of that, unsure of its position
            pose = observation.object_in_holder.copy()
            pose[:3, :3] = tilted @ pose[:3, :3]
            covariance = np.diag([3e-3, 3e-3, 3e-3, 0.01, np.deg2rad(0.5), 0.0]) ** 2
            observation = replace(observation, object_in_holder=pose, object_time=observation.time - 1.5 * s.monitors.stale_after,
                                  object_covariance=covariance)
        loop.apply(executor.update(observation))
        cell.run(loop.control_period)

    while not (executor.step.name == "EXECUTE" and in_phase(executor, Phase.PUSH)) and cell.time < deadline:
        tick()
    frozen = executor.run.last.object_time
    while executor.step.name == "EXECUTE" and cell.time < deadline:     # pushed on, on dead reckoning
        tick(freeze=frozen)
    assert executor.step.name == "LEAVE" and executor.run.held.reference is None, (executor.step, executor.result)
    for _ in range(3 * s.slip.poses):
        tick(tilt=True)
    assert not executor.done, executor.result
