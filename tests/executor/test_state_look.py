"""Look (dmg_executor.states.look) on synthetic observations: the held object is looked for until a
fresh pose of it comes; seen from no view and no vantage place, the run ends OBJECT_LOST."""
from __future__ import annotations

from dmg_executor.contract import Command, Outcome
from dmg_executor.states.base import Transition
from dmg_executor.states.find_contact import FindContact
from dmg_executor.states.look import Look, fruitless
from synthetic import box_cell, box_run, translation


def test_a_look_ends_with_the_first_fresh_pose_and_hands_back_to_find_contact():
    cell = box_cell()
    run = box_run([translation([0.010, 0.0, 0.0])], cell)
    run.held.await_fresh()
    cell.seen_at = cell.time - 5.0
    state = Look()
    assert isinstance(state.tick(run, cell.observe()), Command) and state.place is not None
    cell.seen_at = cell.time                      # seen again: the held reference is taken ...
    run.held.take(cell.observe())
    outcome = state.tick(run, cell.observe())     # ... and the look is over
    assert isinstance(outcome, Transition) and isinstance(outcome.to, FindContact) and outcome.command is None


def test_an_object_seen_from_nowhere_ends_the_run_object_lost_with_the_places_tried_remembered():
    cell = box_cell()
    run = box_run([translation([0.010, 0.0, 0.0])], cell)
    run.held.await_fresh()
    cell.seen_at = -float("inf")
    state = Look()
    for _ in range(20000):
        obs = cell.observe()
        run.last = obs
        outcome = state.tick(run, obs)
        if run.result is not None:
            break
        cell.move(outcome, seen=False)
    assert run.result.outcome == Outcome.OBJECT_LOST, run.result
    assert "vantage place" in run.result.message
    assert run.fruitless and fruitless(run, cell.observe(), state.place)
