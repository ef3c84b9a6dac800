"""The held-pose belief on synthetic observations (no simulator): which poses form the reference the
closed grip must keep, and when it is a better account of the object than the latest pose."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import distance, from_rotation
from dmg_executor.belief import HeldPose, PoseTrust, mean_covariance, mean_pose
from dmg_executor.contract import Observation

TRUST = PoseTrust(position_sigma=0.001, tilt_sigma=np.deg2rad(2.0), reference_poses=3)


def seen(t: float, x: float = 0.0, sigma: float = 0.0002, tilt_sigma_deg: float = 0.5, turn_deg: float = 0.0) -> Observation:
    """The object seen at time t, `x` m along the grasp axis, with a covariance of the given spreads."""
    pose = from_rotation(Rotation.from_euler("x", turn_deg, degrees=True).as_matrix(), [x, 0.0, 0.02])
    spreads = np.array([sigma] * 3 + [np.deg2rad(tilt_sigma_deg)] * 3)
    return Observation(time=t, holder=np.eye(4), pusher=np.eye(4), object_in_holder=pose, object_time=t,
                       opening=0.05, object_covariance=np.diag(spreads**2))


def test_a_pose_is_certain_only_when_sure_of_both_its_position_and_its_tilt():
    assert TRUST.certain(seen(0.0))
    assert not TRUST.certain(seen(0.0, sigma=0.002))
    assert not TRUST.certain(seen(0.0, tilt_sigma_deg=4.0))


def test_the_reference_is_the_mean_of_certain_poses_up_to_reference_poses():
    held = HeldPose(TRUST)
    held.take(seen(0.0, x=0.000))
    for t, x in ((0.1, 0.002), (0.2, 0.004), (0.3, 0.010)):
        held.fold_in(seen(t, x=x))
    assert len(held.poses) == 3                                   # the fourth pose is not folded in
    assert abs(held.reference[0, 3] - 0.002) < 1e-9               # mean of 0, 2 and 4 mm


def test_uncertain_or_repeated_poses_are_not_folded_in():
    held = HeldPose(TRUST)
    held.take(seen(0.0))
    held.fold_in(seen(0.1, x=0.005, sigma=0.003))     # a lone tag seen obliquely
    held.fold_in(seen(0.0, x=0.005))                  # the same image again
    assert len(held.poses) == 1 and distance(held.reference, seen(0.0).object_in_holder)[0] < 1e-12


def test_a_reference_taken_from_an_uncertain_pose_is_outdone_by_a_certain_one():
    held = HeldPose(TRUST)
    held.take(seen(0.0, sigma=0.003))
    assert held.uncertain and held.poses == []
    assert held.outdone_by(seen(0.1)) and not held.outdone_by(seen(0.1, sigma=0.002))
    held.take(seen(0.1))
    assert not held.uncertain and not held.outdone_by(seen(0.2))


def test_a_certain_reference_stands_for_the_object_against_an_uncertain_pose_or_once_it_averages_several():
    held = HeldPose(TRUST)
    held.take(seen(0.0))
    assert held.better_than(seen(0.1, sigma=0.003))
    assert not held.better_than(seen(0.1))            # one pose against another as certain: the latest counts
    held.fold_in(seen(0.1, x=0.0004))
    assert held.better_than(seen(0.2))


def test_awaiting_a_fresh_pose_drops_the_reference():
    held = HeldPose(TRUST)
    held.take(seen(0.0))
    held.await_fresh()
    assert held.reference is None and held.pending and held.uncertain and not held.better_than(seen(0.1))
    held.take(seen(0.1))
    assert not held.pending


def test_the_mean_pose_averages_rotations_and_positions():
    poses = np.array([seen(0.0, x=0.001, turn_deg=-4.0).object_in_holder, seen(0.0, x=0.003, turn_deg=4.0).object_in_holder])
    moved, turned = distance(mean_pose(poses), seen(0.0, x=0.002).object_in_holder)
    assert moved < 1e-9 and turned < 1e-9


def test_the_reference_standing_in_for_an_uncertain_pose_brings_its_own_certainty():
    held = HeldPose(TRUST)
    held.take(seen(0.0, tilt_sigma_deg=0.5))
    blurred = seen(0.1, x=0.004, sigma=0.003, tilt_sigma_deg=6.0)     # a lone tag seen obliquely
    judged = held.account(blurred)
    assert np.allclose(judged.object_in_holder, held.reference)
    assert abs(np.rad2deg(judged.object_tilt_sigma) - 0.5) < 1e-6 and judged.object_position_sigma < 0.0003
    assert held.account(seen(0.2, x=0.001)).object_in_holder[0, 3] == 0.001   # as certain as the reference: its own


def test_the_covariance_of_a_mean_shrinks_with_the_poses_it_averages():
    held = HeldPose(TRUST)
    held.take(seen(0.0))
    for t in (0.1, 0.2):
        held.fold_in(seen(t))
    single = seen(0.0).object_covariance
    assert np.allclose(held.covariance, single / 3)
    assert np.allclose(mean_covariance([single, 3 * single]), single)
    assert mean_covariance([single, None]) is None and mean_covariance([]) is None
