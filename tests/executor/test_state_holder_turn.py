"""The holder's turns (dmg_executor.states.holder_turn) on synthetic observations: the pusher clears,
the holder turns the object about its fingers and the far side faces the pusher; a turn that stalls
goes back and is not tried again."""
from __future__ import annotations

import numpy as np

from dmg_executor.contract import Command
from dmg_executor.states.base import Transition
from dmg_executor.states.find_contact import FindContact
from dmg_executor.states.holder_turn import ClearForTurn, TurnHolder, start_holder_turn
from synthetic import box_cell, box_run, translation


def start_turn(cell, run):
    outcome = start_holder_turn(run, cell.observe(), back=False)
    assert isinstance(outcome, Transition) and isinstance(outcome.to, ClearForTurn)
    assert outcome.to.turns_holder and run.holder_turns.turned_by == run.settings.holder.turn
    return outcome.to


def test_the_holder_turns_the_object_once_the_pusher_is_clear_and_the_far_side_faces_the_pusher():
    cell = box_cell()
    run = box_run([translation([0.010, 0.0, 0.0])], cell)
    state = start_turn(cell, run)
    held_at = cell.holder[:3, 3].copy()
    for _ in range(5000):
        obs = cell.observe()
        outcome = state.tick(run, obs)
        while isinstance(outcome, Transition) and outcome.command is None:     # a handover: same tick
            state = outcome.to
            outcome = state.tick(run, obs)
        if isinstance(outcome, Transition):
            break
        cell.move(outcome, seen=False)
    assert isinstance(outcome.to, FindContact) and run.holder_turns.far_side
    assert run.clear_of_turn(cell.observe(), cell.pusher[:3, 3])
    turned = np.arctan2(*(cell.holder[:3, :3].T @ np.eye(3)[:, 0])[[1, 0]])   # base x seen in the holder's frame
    assert abs(abs(turned) - abs(run.settings.holder.turn)) < run.settings.approach.waypoint_turn_tolerance + 0.01
    assert np.linalg.norm(cell.holder[:3, 3] - held_at) < 0.005       # turned in place
    assert run.held.pending                                           # the next fresh pose is the reference


def test_a_turn_that_stops_gaining_turns_back_and_is_not_tried_again():
    cell = box_cell()
    run = box_run([translation([0.010, 0.0, 0.0])], cell)
    state = TurnHolder(np.pi, back=False, obs=cell.observe())
    outcome = state.tick(run, cell.observe())
    assert isinstance(outcome, Command) and outcome.holder[5] != 0.0
    cell.time += run.settings.approach.stall_time + 0.1                        # the wrist at its limit: no turn
    outcome = state.tick(run, cell.observe())
    assert isinstance(outcome, Command) and not run.holder_turns.may_turn and state.back and state.angle == 0.0
    assert "could not turn the object" in run.campaign.notes[-1]
    outcome = state.tick(run, cell.observe())                         # back to where it was: done
    assert isinstance(outcome, Transition) and isinstance(outcome.to, FindContact)
    assert not run.holder_turns.far_side
