"""Frame-by-frame object tracking for the perception node, ROS-free: the camera and gripper
poses at each image's time, the object pose in the gripper frame, and whether it is lost.

Times are the images' stamps (the camera's clock, simulated or real) for everything that
comes with an image; `status(now)` also needs the receiver's clock, so that a camera that
stops sending altogether still turns the state to LOST.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from dmg_common.transforms import invert
from dmg_perception.estimator import ObjectEstimate, ObjectPoseEstimator, TagObservation
from dmg_perception.pose_buffer import PoseBuffer


class TrackingState(IntEnum):
    """Same values as dmg_interfaces/msg/PerceptionStatus."""

    TRACKING = 0
    SEARCHING = 1
    LOST = 2
    NO_CAMERA = 3


@dataclass
class FrameResult:
    stamp: float
    observations: list[TagObservation] = field(default_factory=list)
    estimate: ObjectEstimate | None = None
    camera_from_frame: np.ndarray | None = None   # gripper frame in the camera frame, when known
    problem: str = ""                             # why there is no estimate


@dataclass
class TrackingStatus:
    state: TrackingState
    object_name: str
    seconds_since_seen: float
    tags_used: int
    reprojection_error: float
    message: str


class Tracker:
    def __init__(self, estimator: ObjectPoseEstimator, lost_timeout: float, pose_tolerance: float,
                 object_name: str | None = None):
        self.estimator = estimator
        self.lost_timeout = lost_timeout
        self.pose_tolerance = pose_tolerance
        self.object_name = object_name or None
        self.camera_poses = PoseBuffer()
        self.gripper_poses = PoseBuffer()
        self.last_image: tuple[float, float] | None = None   # (image stamp, receiver time)
        self.last_seen: FrameResult | None = None
        self.last_problem = "no image yet"

    def process(self, stamp: float, grey: np.ndarray, received: float) -> FrameResult:
        """Track the object in one grey image taken at `stamp`, received at `received` (receiver clock)."""
        self.last_image = (stamp, received)
        result = FrameResult(stamp)
        if self.estimator.intrinsics is None:
            result.problem = "no camera_info yet"
        else:
            result.observations = self.estimator.detect(grey)
            camera = self.camera_poses.at(stamp, self.pose_tolerance)
            gripper = self.gripper_poses.at(stamp, self.pose_tolerance)
            if camera is None or gripper is None:
                which = "camera" if camera is None else "gripper"
                result.problem = f"no {which} pose within {self.pose_tolerance * 1000:.0f} ms of the image"
            else:
                frame_from_camera = invert(gripper) @ camera
                result.camera_from_frame = invert(frame_from_camera)
                last = self.prior(stamp)
                result.estimate = self.estimator.estimate(result.observations, frame_from_camera, self.object_name,
                                                          last.pose if last else None, last.covariance if last else None,
                                                          held=True)
                if result.estimate is None:
                    known = [o.id for o in result.observations if o.id in self.estimator.tags]
                    result.problem = ("no tag of the object in view" if not known else
                                      f"tags {known} seen but none agrees with the object's layout")
        if result.estimate is not None:
            self.last_seen = result
        self.last_problem = result.problem
        return result

    def prior(self, stamp: float) -> ObjectEstimate | None:
        """The last seen estimate, to settle a lone tag's mirror in an image taken at `stamp` - only
        while it is recent (within lost_timeout): once the object was lost (a reset, a regrasp)
        it may be anywhere."""
        seen = self.last_seen
        if seen is None or stamp - seen.stamp > self.lost_timeout:
            return None
        return seen.estimate

    def status(self, now: float) -> TrackingStatus:
        """Where tracking stands at receiver time `now`."""
        seen = self.last_seen
        name = seen.estimate.object_name if seen else (self.object_name or "")
        tags = len(seen.estimate.tags_used) if seen else 0
        error = seen.estimate.reprojection_error if seen else math.nan
        if self.last_image is None or self.estimator.intrinsics is None:
            problem = "no image yet" if self.last_image is None else "no camera_info yet"
            return TrackingStatus(TrackingState.NO_CAMERA, name, math.inf, tags, error, problem)
        image_stamp, received = self.last_image
        silence = now - received                       # no images at all for this long
        since = (image_stamp - seen.stamp if seen else math.inf) + max(silence, 0.0)
        if seen is not None and seen.stamp == image_stamp and silence <= self.lost_timeout:
            return TrackingStatus(TrackingState.TRACKING, name, since, tags, error, "")
        if since > self.lost_timeout:
            message = (f"no image for {silence:.2f} s" if silence > self.lost_timeout else self.last_problem)
            return TrackingStatus(TrackingState.LOST, name, since, tags, error,
                                  f"object lost: {message} (no pose for {since:.2f} s)")
        return TrackingStatus(TrackingState.SEARCHING, name, since, tags, error, self.last_problem)
