"""Approach and Homeward (dmg_executor.states.approach) on synthetic observations: along the route, at
the start into EXECUTE with the grip loosening; a route the arm cannot follow is given up."""
from __future__ import annotations

import numpy as np

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
