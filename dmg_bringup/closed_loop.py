"""The cell's control loop in one process, without ROS: MuJoCo cell, wrist-camera perception
and the executor, on simulated time.

Same cores as the nodes, same data path (rendered image -> AprilTags -> object pose in the
holder's frame -> executor -> arm twists and gripper commands), so it measures what the
nodes would do, minus DDS. Used by tests of the executor core, `dmg eval` and benchmarks.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from dmg_common.transforms import invert
from dmg_executor.contract import Command, Observation, Result
from dmg_executor.controller import PlanExecutor
from dmg_executor.views import CameraModel
from dmg_perception.estimator import ObjectPoseEstimator
from dmg_sim_bridge.cell import Cell


@dataclass
class Trace:
    """What happened, one row per control tick."""

    time: list[float] = field(default_factory=list)
    step: list[int] = field(default_factory=list)
    primitive: list[int] = field(default_factory=list)
    contact_error: list[float] = field(default_factory=list)
    angle_error: list[float] = field(default_factory=list)
    true_object_in_holder: list[np.ndarray] = field(default_factory=list)


class ClosedLoop:
    def __init__(self, cell: Cell, estimator: ObjectPoseEstimator, control_rate: float = 50.0,
                 camera_rate: float = 30.0):
        self.cell, self.estimator = cell, estimator
        self.control_period, self.camera_period = 1.0 / control_rate, 1.0 / camera_rate
        estimator.set_camera(cell.config.camera.intrinsic_matrix())
        self.seen: np.ndarray | None = None
        self.seen_time = -math.inf
        self.seen_covariance: np.ndarray | None = None
        self.next_frame = -math.inf

    def forget(self) -> None:
        """Forget earlier sightings and the frame schedule: a reset moved the object (and may have
        restarted the clock)."""
        self.seen, self.seen_time, self.seen_covariance, self.next_frame = None, -math.inf, None, -math.inf

    def watch(self, seconds: float) -> None:
        """Forget earlier sightings, then let the cell run, arms still, perceiving as it goes."""
        self.forget()
        ends = self.cell.time + seconds
        while self.cell.time < ends:
            self.perceive()
            self.cell.run(self.control_period)

    def perceive(self) -> None:
        """Render and estimate when a camera frame is due."""
        cell = self.cell
        if cell.time + 1e-9 < self.next_frame:
            return
        self.next_frame = cell.time + self.camera_period
        grey = cv2.cvtColor(cell.render(), cv2.COLOR_RGB2GRAY)
        holder_from_camera = invert(cell.grasp_pose("arm1")) @ cell.camera_pose()
        estimate = self.estimator.estimate(self.estimator.detect(grey), holder_from_camera, cell.object.name,
                                           self.seen, self.seen_covariance, held=True)
        if estimate is not None:
            self.seen, self.seen_time, self.seen_covariance = estimate.pose, cell.time, estimate.covariance

    def observe(self) -> Observation:
        cell = self.cell
        pusher = cell.grasp_pose("arm2")
        return Observation(cell.time, cell.grasp_pose("arm1"), pusher, self.seen, self.seen_time, cell.opening("arm1"),
                           self.seen_covariance)

    def camera_model(self) -> CameraModel:
        """The wrist camera as the executor needs it: intrinsics, size, place on the pusher."""
        cell, spec = self.cell, self.cell.config.camera
        return CameraModel(spec.intrinsic_matrix(), spec.width, spec.height,
                           invert(cell.grasp_pose("arm2")) @ cell.camera_pose())

    def apply(self, command: Command) -> None:
        cell = self.cell
        cell.command_twist("arm1", command.holder[:3], command.holder[3:])
        cell.command_twist("arm2", command.pusher[:3], command.pusher[3:])
        for role, grip in (("arm1", command.holder_grip), ("arm2", command.pusher_grip)):
            if grip is not None:
                cell.command_gripper(role, grip.opening, grip.max_force)

    def run(self, executor: PlanExecutor, time_limit: float = 300.0, trace: Trace | None = None) -> Result:
        """Tick the executor until it finishes (or `time_limit` simulated seconds pass: cancelled)."""
        cell = self.cell
        ends = cell.time + time_limit
        while not executor.done:
            self.perceive()
            command = executor.update(self.observe()) if cell.time < ends else executor.cancel(
                f"time limit {time_limit:.0f} s reached")
            self.apply(command)
            if trace is not None:
                progress = executor.progress()
                trace.time.append(cell.time)
                trace.step.append(int(progress.step))
                trace.primitive.append(progress.primitive_index)
                trace.contact_error.append(progress.contact_error)
                trace.angle_error.append(progress.angle_error)
                trace.true_object_in_holder.append(cell.object_in_gripper("arm1"))
            cell.run(self.control_period)
        for role in ("arm1", "arm2"):
            cell.stop(role)
        return executor.result
