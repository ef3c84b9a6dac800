"""What the executor believes of the held object's pose while gripper 1's grip is closed.

A closed grip keeps the object still, so the pose the grip must keep (the *held reference*) is
taken from a perceived pose and then averaged over the certain poses that follow: a lone tag's
poses of a still object scatter 0.3 mm median and 2 mm p90, and one stray pose taken alone would
make a still object look slipped. A pose is *certain* when its covariance gives it a position
standard deviation within `slip_position_sigma` and a tilt one within `slip_tilt_sigma`; only
certain poses are evidence that the object moved or tilted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import from_rotation
from dmg_executor.contract import Observation


def mean_pose(poses: np.ndarray) -> np.ndarray:
    """The mean of (n, 4, 4) poses of one still object: mean rotation, mean position."""
    return from_rotation(Rotation.from_matrix(poses[:, :3, :3]).mean().as_matrix(), poses[:, :3, 3].mean(axis=0))


def mean_covariance(covariances: list[np.ndarray | None]) -> np.ndarray | None:
    """The covariance of the mean of poses with these covariances, their errors independent (sum / n^2);
    None (taken as certain) if any is."""
    if not covariances or any(c is None for c in covariances):
        return None
    return np.sum(covariances, axis=0) / len(covariances) ** 2


def _covariance(obs: Observation) -> np.ndarray | None:
    """A copy of the observation's pose covariance (None: taken as certain)."""
    return None if obs.object_covariance is None else np.array(obs.object_covariance, float)


@dataclass
class PoseTrust:
    """How certain a perceived pose must be to count as evidence (from ExecutorSettings)."""

    position_sigma: float     # m
    tilt_sigma: float         # rad
    reference_poses: int      # certain poses averaged into the held reference at most

    def certain(self, obs: Observation) -> bool:
        """Is this pose certain enough of both its position and its tilt to show a slip (and so to be
        trusted where a view may mislead)?"""
        return obs.object_position_sigma <= self.position_sigma and obs.object_tilt_sigma <= self.tilt_sigma


@dataclass
class HeldPose:
    """The object pose the closed grip must keep, and how it was formed."""

    trust: PoseTrust
    reference: np.ndarray | None = None   # object in the holder's frame, or None (pushing, or not seen since)
    sigma: float = 0.0                    # m, position uncertainty of the pose it was taken from
    poses: list[np.ndarray] = field(default_factory=list)   # the certain poses averaged into it
    covariances: list[np.ndarray | None] = field(default_factory=list)   # theirs
    covariance: np.ndarray | None = None  # 6x6 of the reference (of the mean when it averages several)
    pose_time: float = -math.inf          # when the last of them was seen
    pending: bool = False                 # the grip closed on an object not seen since: take the next fresh pose

    def take(self, obs: Observation) -> None:
        """Take this pose as the one the closed grip must keep."""
        self.reference, self.sigma = obs.object_in_holder.copy(), obs.object_position_sigma
        self.covariance = _covariance(obs)
        self.poses = [self.reference] if self.trust.certain(obs) else []
        self.covariances = [self.covariance] if self.poses else []
        self.pose_time = obs.object_time
        self.pending = False

    def take_mean(self, poses: np.ndarray, sigma: float, seen: float, covariance: np.ndarray | None) -> None:
        """Take the mean of several poses of the still object (seen from different views) as the reference."""
        self.reference = mean_pose(poses)
        self.sigma, self.poses, self.pose_time = sigma, [self.reference], seen
        self.covariance, self.covariances = covariance, [covariance]

    def await_fresh(self) -> None:
        """No reference until the next fresh pose: the grip closed on an object not seen since it moved."""
        self.reference, self.pending = None, True

    def fold_in(self, obs: Observation) -> None:
        """Fold a new certain pose that shows no slip into the reference, up to `reference_poses` of
        them; then the reference stays, so a slow slip still shows against it."""
        if (self.reference is None or not self.poses or len(self.poses) >= self.trust.reference_poses
                or obs.object_time <= self.pose_time or not self.trust.certain(obs)):
            return
        self.poses.append(obs.object_in_holder.copy())
        self.covariances.append(_covariance(obs))
        self.pose_time = obs.object_time
        self.reference = mean_pose(np.array(self.poses))
        self.covariance = mean_covariance(self.covariances)

    @property
    def uncertain(self) -> bool:
        """No reference, or one too uncertain of its position to tell a slip."""
        return self.reference is None or self.sigma > self.trust.position_sigma

    def outdone_by(self, obs: Observation) -> bool:
        """Would this pose make a better reference (the reference too uncertain to tell a slip, the pose
        certain of its position)?"""
        limit = self.trust.position_sigma
        return self.reference is not None and self.sigma > limit and obs.object_position_sigma <= limit

    def better_than(self, obs: Observation) -> bool:
        """Is the reference (a pose certain of its position, the grip closed since) a better account of
        where the object is than this pose: one too uncertain to show that it moved, or any single pose
        once the reference averages several?"""
        limit = self.trust.position_sigma
        return (self.reference is not None and self.sigma <= limit
                and (obs.object_position_sigma > limit or len(self.poses) > 1))

    def account(self, obs: Observation) -> Observation:
        """The pose to judge by: the reference, with its own certainty, where it is the better account
        (a tilt read from an uncertain image must not stand in for a certain one), else this pose."""
        if not self.better_than(obs):
            return obs
        return replace(obs, object_in_holder=self.reference, object_covariance=self.covariance)
