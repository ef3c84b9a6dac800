"""Execute (dmg_executor.states.execute) on synthetic observations: its phases in order - the grip
loosens, the pusher closes its gap along the push line, pushes under P control until what is left is
within tolerance, the grip tightens - then LEAVE."""
from __future__ import annotations

import numpy as np

from dmg_common.transforms import apply, invert
from dmg_executor.contract import Command
from dmg_executor.states.base import Transition
from dmg_executor.states.execute import Execute, Phase
from dmg_executor.states.leave import Leave
from synthetic import planned_translation


def at_push_start():
    cell, run = planned_translation()
    cell.pusher[:3, 3], cell.pusher[:3, :3] = run.push.start, run.push.route.orientations[-1]
    state = Execute()
    state.enter(run, cell.observe())
    return cell, run, state


def test_the_push_goes_through_its_phases_and_moves_the_object_to_within_tolerance():
    cell, run, state = at_push_start()
    s = run.settings
    face = apply(cell.holder @ cell.object_in_holder, run.push.contact.point)
    phases, pushed_speeds = [], []
    for _ in range(5000):
        obs = cell.observe()
        run.last = obs
        run.campaign.measure(obs)
        outcome = state.tick(run, obs)
        if isinstance(outcome, Transition):
            break
        phases.append(state.phase)
        if state.phase == Phase.PUSH:
            pushed_speeds.append(float(outcome.pusher[:3] @ run.push.direction))
        cell.move(outcome)
        # the object moves with the pusher's tip once it has reached the face (the held object otherwise stays)
        tip = cell.pusher[:3, 3] + s.gripper.tip_radius * run.push.direction
        beyond = float((tip - face) @ run.push.direction)
        if beyond > 0:
            moved = np.eye(4)
            moved[:3, 3] = beyond * run.push.direction
            face = face + moved[:3, 3]
            cell.object_in_holder = invert(cell.holder) @ moved @ cell.holder @ cell.object_in_holder
    assert isinstance(outcome.to, Leave) and run.campaign.pushes == 1
    assert [p for i, p in enumerate(phases) if i == 0 or phases[i - 1] != p] == \
        [Phase.LOOSEN, Phase.TOUCH, Phase.PUSH, Phase.TIGHTEN]
    assert phases.count(Phase.LOOSEN) * 0.02 >= s.grip.settle - 0.03     # the grip had time to loosen
    assert all(0.0 < speed <= s.push.speed + 1e-9 for speed in pushed_speeds)
    assert pushed_speeds[-1] < pushed_speeds[0]           # P control slows down as the goal nears
    run.campaign.measure(cell.observe())
    assert run.campaign.errors[0] <= s.tolerances.position + 1e-4
    assert run.pushed is not None and np.allclose(run.pushed.along, run.push.local_direction)


def test_a_push_that_loses_sight_of_the_object_without_blind_pushes_tightens_at_once():
    cell, run, state = at_push_start()
    obs = cell.observe()
    assert isinstance(state.tick(run, obs), Command) and state.phase == Phase.LOOSEN
    stop = state.unseen_push(run, obs)
    assert state.phase == Phase.TIGHTEN and stop.holder_grip.max_force == run.settings.grip.hold_force
    assert "unseen" in run.campaign.notes[-1]
    assert state.unseen_push(run, obs) is None           # already tightening: nothing more to stop


def test_the_object_forcing_the_fingers_open_stops_the_push():
    cell, run, state = at_push_start()
    obs = cell.observe()
    cell.time += run.settings.grip.settle + 0.01
    state.tick(run, cell.observe())
    assert state.phase == Phase.TOUCH
    cell.pusher[:3, 3] += run.settings.push.gap * run.push.direction       # the gap closed: pushing
    state.tick(run, cell.observe())
    assert state.phase == Phase.PUSH
    cell.opening = obs.opening + 2 * run.settings.monitors.forced_open
    command = state.tick(run, cell.observe())
    assert state.phase == Phase.TIGHTEN and command.holder_grip.max_force == run.settings.grip.hold_force
    assert "forced gripper 1's fingers" in run.campaign.notes[-1]


def test_a_translation_push_moves_its_line_against_the_turn_it_sees_about_the_grasp_axis():
    """With the line's offset allowed: the box held at its centre of mass has no weight to balance, the line runs
    through the grasp's middle until the object is seen turned about the grasp axis; then the pusher moves across
    the push, to the side whose torque turns it back."""
    from scipy.spatial.transform import Rotation

    from dmg_executor.settings import ExecutorSettings

    for turn_deg in (3.0, -3.0):
        cell, run, state = at_push_start()
        run.settings = ExecutorSettings.defaults(**{"steering.turn_offset_limit": 0.02})    # (off by default)
        across = np.cross(run.push.direction, cell.holder[:3, 0])
        sideways = []
        for _ in range(400):
            obs = cell.observe()
            run.last = obs
            run.campaign.measure(obs)
            outcome = state.tick(run, obs)
            if state.phase == Phase.PUSH:
                sideways.append(float(outcome.pusher[:3] @ across))
                if len(sideways) == 5:     # seen turned from here on
                    turned = np.eye(4)
                    turned[:3, :3] = Rotation.from_rotvec([np.deg2rad(turn_deg), 0.0, 0.0]).as_matrix()
                    cell.object_in_holder = turned @ cell.object_in_holder
                if len(sideways) == 10:
                    break
            cell.move(outcome)
        assert max(abs(v) for v in sideways[:5]) < 1e-6
        assert np.sign(sideways[-1]) == -np.sign(turn_deg) and abs(sideways[-1]) > 1e-4
