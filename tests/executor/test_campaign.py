"""The campaign's corrections after the plan (dmg_executor.campaign): which primitive comes next from the grasp
left - a translation or rotation to the goal, or the level press - on synthetic poses (no simulator)."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_executor.campaign import Campaign
from dmg_executor.contract import Observation
from dmg_executor.settings import ExecutorSettings
from dmg_planner.primitives import Primitive, PrimitiveKind

OPENING = 0.040


def _goal() -> Primitive:
    """A plan of one translation that ends with the object square in the grip, its frame on the grasp's middle."""
    contacts = [np.array([side * OPENING / 2, 0.0, 0.0]) for side in (-1.0, 1.0)]
    return Primitive(PrimitiveKind.TRANSLATION, 0.0, np.zeros(3), contacts[0], contacts[0], 0.0, 0.0,
                     contacts[1], contacts[1], np.eye(4))


def _held(tilt_deg: float = 0.0, shift: float = 0.0, turn_deg: float = 0.0) -> Observation:
    """The object tilted `tilt_deg` about gripper 1's fingers (z), turned `turn_deg` about the grasp axis (x) and
    `shift` [m] along its y off the goal grasp."""
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("xz", [turn_deg, tilt_deg], degrees=True).as_matrix()
    pose[1, 3] = shift
    return Observation(0.0, np.eye(4), np.eye(4), pose, 0.0, OPENING)


def _after(campaign: Campaign, obs: Observation, failed: PrimitiveKind | None = None) -> str:
    """Finish the current primitive at `obs` (left for want of a push of kind `failed`) and say what comes next:
    'level', 'translation', 'rotation' or 'end'."""
    campaign.next_primitive()
    campaign.add_correction(obs, failed=failed)
    if campaign.over:
        return "end"
    return "level" if campaign.leveling else campaign.primitives[campaign.index].kind.name.lower()


def test_a_tilted_grasp_is_pressed_level_once_a_run_before_the_corrections_where_the_tilt_is_the_larger_error():
    s = ExecutorSettings.defaults()
    campaign = Campaign(s, [_goal()], 0)
    assert _after(campaign, _held(tilt_deg=4.0, shift=0.004)) == "level"       # the tilt first
    assert _after(campaign, _held(shift=0.004)) == "translation"               # pressed level, still 4 mm off
    for _ in range(s.campaign.max_corrections - 1):
        assert _after(campaign, _held(tilt_deg=4.0, shift=0.004)) == "translation"   # tilted again: no second press
    assert _after(campaign, _held(tilt_deg=4.0, shift=0.004)) == "end"          # the corrections used up


def test_a_grasp_within_the_goals_tolerances_is_not_pressed_however_tilted_and_a_small_tilt_never():
    s = ExecutorSettings.defaults()
    within = np.rad2deg(s.tolerances.goal_angle) * 0.9
    assert _after(Campaign(s, [_goal()], 0), _held(tilt_deg=within)) == "end"
    below = np.rad2deg(s.level.tilt) * 0.9       # outside the position tolerance, tilted less than level.tilt
    assert _after(Campaign(s, [_goal()], 0), _held(tilt_deg=below, shift=0.004)) == "translation"


def test_a_turn_larger_than_the_tilt_comes_first_unless_it_found_no_push_then_the_press_does():
    s = ExecutorSettings.defaults()
    tilted_and_turned = _held(tilt_deg=4.0, turn_deg=9.0, shift=0.004)
    assert _after(Campaign(s, [_goal()], 0), tilted_and_turned) == "rotation"
    campaign = Campaign(s, [_goal()], 0)
    assert _after(campaign, tilted_and_turned, failed=PrimitiveKind.ROTATION) == "level"
    assert _after(campaign, _held(turn_deg=9.0, shift=0.004)) == "rotation"    # level now: the turn again
