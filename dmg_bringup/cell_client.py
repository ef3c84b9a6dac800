"""What an operator of the cell does over ROS: reset the scene, read the grasp, ask for a
plan, execute it and follow its progress. Used by `dmg demo` and the end-to-end tests."""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from dmg_common.ros.geometry_messages import pose_message, transform_from_pose
from dmg_common.transforms import invert


class CellError(RuntimeError):
    """Something the operator waited for did not happen; the message says what."""


class CellClient:
    def __init__(self, node: Node, guard: Callable[[], str | None] = lambda: None) -> None:
        """`guard` is asked while waiting: a text (e.g. "planner exited with 1") ends the wait."""
        from dmg_interfaces.action import ExecuteRepositioning
        from dmg_interfaces.msg import ExecutorState
        from dmg_interfaces.srv import PlanRepositioning, ResetScene
        from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
        from rclpy.action import ActionClient

        self.node = node
        self.guard = guard
        self.latest: dict[str, object] = {}
        self.state_listeners: list[Callable] = []
        for topic, kind in (("/perception/object_pose", PoseWithCovarianceStamped),
                            ("/ground_truth/object_in_arm1", PoseStamped)):
            node.create_subscription(kind, topic, lambda msg, topic=topic: self.latest.__setitem__(topic, msg), 10)
        node.create_subscription(ExecutorState, "/executor/state", self._on_state,
                                 QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
        self.Action, self.Plan, self.Reset = ExecuteRepositioning, PlanRepositioning, ResetScene
        self.actions = ActionClient(node, ExecuteRepositioning, "/execute_repositioning")
        self.planner = node.create_client(PlanRepositioning, "/plan_repositioning")
        self.resetter = node.create_client(ResetScene, "/sim/reset")

    def _on_state(self, msg) -> None:
        self.latest["/executor/state"] = msg
        for listener in self.state_listeners:
            listener(msg)

    def wait_for_subscriber(self, topic: str, node_name: str, timeout: float) -> bool:
        """Wait until the node `node_name` subscribes to `topic`; False if it did not within `timeout` s.
        A volatile subscriber that comes late misses what was sent before."""
        def subscribed() -> bool:
            return any(info.node_name == node_name for info in self.node.get_subscriptions_info_by_topic(topic))
        try:
            self.wait_for(subscribed, timeout, f"a subscriber {node_name} on {topic}")
        except CellError:
            if self.guard():
                raise
            return False
        return True

    def wait_for(self, condition: Callable, timeout: float, what: str):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = condition()
            if value:
                return value
            trouble = self.guard()
            if trouble:
                raise CellError(f"waiting for {what}: {trouble}")
            rclpy.spin_once(self.node, timeout_sec=0.05)
        raise CellError(f"no {what} within {timeout:.0f} s")

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def wait_until_ready(self, timeout: float) -> None:
        """Every node of the cell answers: sim reset, planner, executor, and a perceived pose."""
        deadline = time.monotonic() + timeout
        for ready, what in ((self.resetter.wait_for_service, "/sim/reset (sim bridge)"),
                            (self.planner.wait_for_service, "/plan_repositioning"),
                            (self.actions.wait_for_server, "/execute_repositioning")):
            if not ready(timeout_sec=max(0.1, deadline - time.monotonic())):
                raise CellError(f"{what} did not appear within {timeout:.0f} s")
        self.wait_for(lambda: self.latest.get("/executor/state"), max(0.1, deadline - time.monotonic()),
                      "executor state")

    def call(self, client, request, timeout: float, what: str):
        future = client.call_async(request)
        return self.wait_for(lambda: future.result() if future.done() else None, timeout, f"answer from {what}")

    def reset(self, object_id: str, timeout: float = 60.0):
        """The object in gripper 1 at its default grasp; returns once perception sees it again."""
        response = self.call(self.resetter, self.Reset.Request(object_id=object_id), timeout, "/sim/reset")
        if not response.success:
            raise CellError(f"reset refused: {response.message}")
        self.latest.pop("/perception/object_pose", None)
        self.wait_for(lambda: self.latest.get("/perception/object_pose"), timeout, "object pose after the reset")
        return response

    def perceived_grasp(self) -> np.ndarray:
        """Gripper 1's pose in the object frame, as perceived (what a real cell knows)."""
        return invert(transform_from_pose(self.latest["/perception/object_pose"].pose.pose))

    def true_grasp(self) -> np.ndarray:
        """The same from the simulator's ground truth (for judging, never for control)."""
        return invert(transform_from_pose(self.latest["/ground_truth/object_in_arm1"].pose))

    def plan(self, object_id: str, start: np.ndarray, goal: np.ndarray, timeout: float = 60.0):
        """The planner's answer; while it says NOT_READY (the object's graph still building) asked again
        each second until `timeout`."""
        request = self.Plan.Request(object_id=object_id, start=pose_message(start), goal=pose_message(goal))
        deadline = time.monotonic() + timeout
        response = self.call(self.planner, request, timeout, "/plan_repositioning")
        while response.error_code == response.NOT_READY and "being built" in response.message \
                and time.monotonic() < deadline:
            self.spin_for(1.0)
            response = self.call(self.planner, request, max(1.0, deadline - time.monotonic()), "/plan_repositioning")
        return response

    def execute(self, plan, alpha: float, timeout: float):
        """Send the plan, wait for the result (the action's result message)."""
        future = self.actions.send_goal_async(self.Action.Goal(plan=plan, alpha=float(alpha)))
        handle = self.wait_for(lambda: future.result() if future.done() else None, 30, "goal acceptance")
        if not handle.accepted:
            raise CellError("the executor rejected the goal")
        result = handle.get_result_async()
        return self.wait_for(lambda: result.result() if result.done() else None, timeout, "execution result").result
