"""Approach and Homeward (dmg_executor.states.approach) on synthetic observations: along the route, at
the start into EXECUTE with the grip loosening; a route the arm cannot follow is given up."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_executor.contract import Command
from dmg_executor.states.approach import Approach, Homeward
from dmg_executor.states.base import Transition
from dmg_executor.states.execute import Execute
from dmg_executor.states.find_contact import FindContact
from synthetic import drive, planned_translation


def test_the_pusher_follows_its_route_and_at_the_push_start_the_grip_loosens_for_execute():
    cell, run = planned_translation()
    outcome = drive(Approach(), run, cell)
    assert isinstance(outcome.to, Execute)
    grip = outcome.command.holder_grip
    assert grip is not None and grip.opening < cell.opening and grip.max_force < run.settings.grip.hold_force
    assert np.linalg.norm(cell.pusher[:3, 3] - run.push.start) < run.settings.tolerances.position


def test_at_the_push_start_with_no_fresh_pose_it_waits_then_pushes_blind():
    cell, run = planned_translation()
    cell.pusher[:3, 3] = run.push.start
    cell.pusher[:3, :3] = run.push.route.orientations[-1]
    run.pilot.route.index = len(run.pilot.route.waypoints) - 1
    cell.seen_at = cell.time - 2 * run.settings.monitors.stale_after     # the last pose is stale
    state = Approach()
    outcome = state.tick(run, cell.observe())
    assert isinstance(outcome, Command) and not run.push.blind      # waiting for a fresh pose
    cell.time += 1.5 * run.settings.monitors.stale_after
    outcome = state.tick(run, cell.observe())        # none came, and no other view to try: the push goes blind
    assert isinstance(outcome, Transition) and isinstance(outcome.to, Execute) and run.push.blind


def test_a_pusher_that_makes_no_headway_gives_the_push_up_and_heads_home():
    cell, run = planned_translation()
    state = Approach()
    direction = run.push.direction.copy()
    outcome = state.tick(run, cell.observe())
    while isinstance(outcome, Command):                    # the arm does not move
        cell.time += 0.1
        outcome = state.tick(run, cell.observe())
    assert isinstance(outcome.to, Homeward)
    assert len(run.memory.unreachable) == 1 and np.allclose(run.memory.unreachable[0], direction)
    assert run.push is None and "given up" in run.campaign.notes[-1]
    outcome = drive(outcome.to, run, cell)
    assert isinstance(outcome.to, FindContact)
    assert np.linalg.norm(cell.pusher[:3, 3] - run.pusher_home[:3, 3]) < 0.01


def test_a_pusher_creeping_far_short_of_its_view_counts_as_stuck_and_one_turning_to_it_does_not():
    """Far from where it is going, 1 deg a second of a 100 deg turn is no headway (an arm at its joint limits
    turning in its null space); 30 deg a second is."""
    for rate_deg, stuck in ((1.0, True), (30.0, False)):
        cell, run = planned_translation()
        pilot = run.pilot
        target, wanted = run.push.start, run.push.route.orientations[-1]
        cell.pusher[:3, 3] = target
        cell.pusher[:3, :3] = Rotation.from_rotvec([0.0, 0.0, np.deg2rad(100.0)]).as_matrix() @ wanted
        stalled = False
        for _ in range(int(1.5 * run.settings.approach.stall_time / 0.1)):
            stalled = stalled or pilot.stalled(cell.observe(), target, wanted)
            step = Rotation.from_rotvec([0.0, 0.0, -np.deg2rad(rate_deg * 0.1)]).as_matrix()
            cell.pusher[:3, :3] = step @ cell.pusher[:3, :3]
            cell.time += 0.1
        assert stalled == stuck, rate_deg


def test_a_pusher_on_the_push_line_whose_wrist_cannot_turn_the_last_degrees_pushes_when_it_sees_the_object():
    cell, run = planned_translation()
    wanted = run.push.route.orientations[-1]
    short = Rotation.from_rotvec(np.deg2rad(4.0) * np.array([0.0, 0.0, 1.0])).as_matrix()   # 4 deg short
    run.pilot.route.index = len(run.pilot.route.waypoints) - 1
    cell.pusher[:3, 3], cell.pusher[:3, :3] = run.push.start, short @ wanted
    state, began = Approach(), cell.time
    outcome = state.tick(run, cell.observe())
    while isinstance(outcome, Command):          # the wrist stays 4 deg short of the turn, the object in view
        cell.pusher[:3, :3] = short @ wanted
        cell.time += 0.1
        cell.seen_at = cell.time
        outcome = state.tick(run, cell.observe())
    assert isinstance(outcome.to, Execute) and not run.memory.unreachable and not run.push.blind
    assert cell.time - began >= run.settings.approach.stall_time       # (after trying to turn)


def test_a_pusher_short_of_the_push_start_is_not_there_however_well_it_sees():
    cell, run = planned_translation()
    run.pilot.route.index = len(run.pilot.route.waypoints) - 1
    cell.pusher[:3, 3] = run.push.start - 3 * run.settings.tolerances.position * run.push.direction
    cell.pusher[:3, :3] = run.push.route.orientations[-1]
    state = Approach()
    outcome = state.tick(run, cell.observe())
    while isinstance(outcome, Command):          # the arm stuck 3 mm short, the object in view
        cell.pusher[:3, 3] = run.push.start - 3 * run.settings.tolerances.position * run.push.direction
        cell.time += 0.1
        cell.seen_at = cell.time
        outcome = state.tick(run, cell.observe())
    assert not isinstance(outcome.to, Execute)


def test_a_wrist_stuck_far_short_of_the_push_starts_view_tries_only_the_views_near_where_it_got_to():
    """At the push start, unseen, the wrist 40 deg short of the view wanted: of the other views, the one 10 deg
    from where it got to is tried, the one 60 deg away is not (as far out of reach); then the push is given up."""
    cell, run = planned_translation()
    wanted = run.push.route.orientations[-1]

    def turned(deg: float) -> np.ndarray:
        return Rotation.from_rotvec(np.deg2rad(deg) * np.array([0.0, 0.0, 1.0])).as_matrix() @ wanted

    near, far = turned(30.0), turned(-20.0)          # 10 deg and 60 deg from where the wrist stops
    run.push.other_views = [far, near]
    run.pilot.route.index = len(run.pilot.route.waypoints) - 1
    cell.pusher[:3, 3], cell.pusher[:3, :3] = run.push.start, turned(40.0)
    cell.seen_at = -np.inf                          # no tag in view from there
    state, tried = Approach(), []
    outcome = state.tick(run, cell.observe())
    while isinstance(outcome, Command):             # the wrist does not turn
        if not tried or tried[-1] is not run.pilot.route.orientations[-1]:
            tried.append(run.pilot.route.orientations[-1])
        cell.pusher[:3, :3] = turned(40.0)
        cell.time += 0.1
        outcome = state.tick(run, cell.observe())
    assert [view is near for view in tried] == [False, True]     # the planned view, then the near one only
    assert isinstance(outcome.to, Homeward) and len(run.memory.unreachable) == 1
