"""Fault monitors on synthetic observations (no simulator): limits, a slip in the closed grip, a tilt
while pushed, and the streak of poses a slip needs."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import from_rotation
from dmg_executor.belief import HeldPose, PoseTrust
from dmg_executor.contract import Observation
from dmg_executor.monitors import (
    Persisting,
    SlipStreak,
    limit_violation,
    moved_in_grip,
    poses_agree,
    tilt_since,
    tilted_further_while_pressed,
    tilted_while_pushed,
)
from dmg_executor.settings import ExecutorSettings

S = ExecutorSettings.defaults()


def at(xyz) -> np.ndarray:
    return from_rotation(np.eye(3), xyz)


def seen(t: float, x: float = 0.0, tilt_deg: float = 0.0, sigma: float = 0.0002, tilt_sigma_deg: float = 0.5,
         holder=(0.7, 0.2, 0.2), pusher=(0.7, -0.1, 0.2)) -> Observation:
    pose = from_rotation(Rotation.from_euler("y", tilt_deg, degrees=True).as_matrix(), [x, 0.0, 0.02])
    spreads = np.array([sigma] * 3 + [np.deg2rad(tilt_sigma_deg)] * 3)
    return Observation(time=t, holder=at(holder), pusher=at(pusher), object_in_holder=pose, object_time=t,
                       opening=0.05, object_covariance=np.diag(spreads**2))


def held_at(obs: Observation) -> HeldPose:
    held = HeldPose(PoseTrust(S.slip.position_sigma, S.slip.tilt_sigma, S.slip.reference_poses))
    held.take(obs)
    return held


def test_a_gripper_outside_the_workspace_or_a_holder_moved_too_far_is_a_limit_violation():
    start = seen(0.0)
    assert limit_violation(start, start.holder, S) is None
    outside = seen(0.1, pusher=(S.limits.workspace_max[0] + 0.01, 0.0, 0.2))
    assert "pushing gripper" in limit_violation(outside, start.holder, S)
    wandered = seen(0.1, holder=(0.7, 0.2 + S.limits.holder_travel + 0.01, 0.2))
    assert "holding gripper moved" in limit_violation(wandered, start.holder, S)


def test_a_certain_pose_moved_past_slip_distance_in_the_closed_grip_is_a_slip():
    held = held_at(seen(0.0))
    assert moved_in_grip(seen(0.1, x=S.slip.distance * 0.8), held, S) is None
    assert "in the closed grip" in moved_in_grip(seen(0.1, x=S.slip.distance * 1.2), held, S)


def test_a_turn_in_the_closed_grip_is_a_slip_only_by_a_pose_certain_of_its_orientation():
    held = held_at(seen(0.0))
    turned = np.rad2deg(S.slip.angle) + 1.0
    assert "in the closed grip" in moved_in_grip(seen(0.1, tilt_deg=turned), held, S)
    unsure = np.rad2deg(S.slip.tilt_sigma) * 1.2
    assert moved_in_grip(seen(0.1, tilt_deg=turned, tilt_sigma_deg=unsure), held, S) is None
    assert "in the closed grip" in moved_in_grip(seen(0.1, x=S.slip.distance * 1.2, tilt_sigma_deg=unsure), held, S)


def test_a_pose_too_uncertain_of_its_position_shows_no_slip_nor_does_an_uncertain_reference():
    far = S.slip.distance * 2
    assert moved_in_grip(seen(0.1, x=far, sigma=S.slip.position_sigma * 2), held_at(seen(0.0)), S) is None
    assert moved_in_grip(seen(0.1, x=far), held_at(seen(0.0, sigma=S.slip.position_sigma * 2)), S) is None


def test_a_pushed_object_tilted_past_slip_angle_is_a_slip_only_by_a_pose_certain_of_its_tilt():
    start = seen(0.0).object_in_holder
    tilted = np.rad2deg(S.slip.angle) + 1.0
    assert abs(tilt_since(start, seen(0.1, tilt_deg=tilted).object_in_holder) - np.deg2rad(tilted)) < 1e-9
    assert "tilted" in tilted_while_pushed(seen(0.1, tilt_deg=tilted), start, S)
    assert tilted_while_pushed(seen(0.1, tilt_deg=tilted, tilt_sigma_deg=np.rad2deg(S.slip.tilt_sigma) * 2), start, S) is None
    assert tilted_while_pushed(seen(0.1, tilt_deg=np.rad2deg(S.slip.angle) - 1.0), start, S) is None



def test_a_level_press_turning_a_tilt_back_is_no_slip_only_one_tilting_the_object_further_off_the_goals_axis():
    slip = np.rad2deg(S.slip.angle)
    pressed = seen(0.1, tilt_deg=1.0)
    assert tilted_further_while_pressed(pressed, np.deg2rad(slip + 1.6), np.deg2rad(1.0), S) is None   # 7.6 -> 1 deg
    assert "further" in tilted_further_while_pressed(pressed, np.deg2rad(1.0), np.deg2rad(slip + 2.0), S)
    unsure = seen(0.1, tilt_sigma_deg=np.rad2deg(S.slip.tilt_sigma) * 2)
    assert tilted_further_while_pressed(unsure, np.deg2rad(1.0), np.deg2rad(slip + 2.0), S) is None


def test_a_streak_counts_each_image_once_and_poses_agree_within_the_slip_limits():
    streak = SlipStreak()
    assert streak.add(seen(0.1)) == 1 and streak.add(seen(0.1)) == 1 and streak.add(seen(0.2)) == 2
    streak.clear()
    assert streak.poses == []
    near = [seen(t, x=0.0005 * i).object_in_holder for i, t in enumerate((0.1, 0.2, 0.3))]
    assert poses_agree(near, S)
    assert not poses_agree([*near, seen(0.4, x=S.slip.distance * 2).object_in_holder], S)


def test_a_persisting_condition_counts_once_it_held_its_whole_window_and_a_break_starts_it_again():
    stale = Persisting(window=0.25)
    assert not stale.holds(True, 10.0) and stale.began
    assert not stale.holds(True, 10.2)
    assert not stale.holds(False, 10.3) and not stale.began       # the poses came: the count starts over
    assert not stale.holds(True, 10.4) and not stale.holds(True, 10.6)
    assert stale.holds(True, 10.65)
    assert Persisting(window=0.0).holds(True, 0.0)
