"""executor_node with the whole simulated cell: sim bridge, perception, planner and executor as
separate processes over real DDS; success is judged against the simulator's ground truth."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import DMG, Processes, RosTestNode
from dmg_common.transforms import distance, homogeneous, invert

pytestmark = [pytest.mark.ros, pytest.mark.sim]

TRANSLATION = 0.015            # m the grasp moves along the fingers (the object is pushed up)
ROTATION = np.deg2rad(20.0)    # rad the grasp turns about the grasp axis


def transform(pose) -> np.ndarray:
    p, q = pose.position, pose.orientation
    return homogeneous([p.x, p.y, p.z], [q.x, q.y, q.z, q.w])


class Operator(RosTestNode):
    """What a user of the cell does: reset, plan, send goals, watch."""

    def __init__(self) -> None:
        super().__init__("executor_test_operator")
        from dmg_interfaces.action import ExecuteRepositioning
        from dmg_interfaces.msg import ExecutorState, GripperState
        from dmg_interfaces.srv import PlanRepositioning, ResetScene
        from geometry_msgs.msg import PoseStamped
        from rclpy.action import ActionClient
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Bool

        self.Action, self.Plan, self.Reset, self.Bool = ExecuteRepositioning, PlanRepositioning, ResetScene, Bool
        self.latest: dict[str, object] = {}
        for topic, kind in (("/ground_truth/object_in_arm1", PoseStamped), ("/joint_states", JointState),
                            ("/arm1/gripper/state", GripperState), ("/executor/state", ExecutorState),
                            ("/perception/object_pose", None)):
            if kind is None:
                from geometry_msgs.msg import PoseWithCovarianceStamped as kind
            self.node.create_subscription(kind, topic, lambda msg, topic=topic: self.latest.__setitem__(topic, msg), 10)
        self.client = ActionClient(self.node, ExecuteRepositioning, "/execute_repositioning")
        self.planner = self.node.create_client(PlanRepositioning, "/plan_repositioning")
        self.resetter = self.node.create_client(ResetScene, "/sim/reset")
        self.cover = self.node.create_publisher(Bool, "/sim/camera_covered", 10)
        self.feedback: list = []

    def truth(self) -> np.ndarray:
        """Ground truth: the gripper's pose in the object frame."""
        return invert(transform(self.latest["/ground_truth/object_in_arm1"].pose))

    def reset(self) -> np.ndarray:
        response = self.call(self.resetter, self.Reset.Request(object_id="box"))
        assert response.success, response.message
        self.latest.pop("/perception/object_pose", None)
        self.wait_for(lambda: self.latest.get("/perception/object_pose"), 30, "a pose after the reset")
        self.spin(0.5)
        return self.truth()

    def plan(self, start: np.ndarray, goal: np.ndarray):
        from dmg_common.ros.geometry_messages import pose_message

        request = self.Plan.Request(object_id="box", start=pose_message(start), goal=pose_message(goal))
        deadline = time.monotonic() + 120.0
        response = self.call(self.planner, request)
        while response.error_code == response.NOT_READY and "being built" in response.message \
                and time.monotonic() < deadline:
            self.spin(1.0)                    # the graph is still being built (on a loaded machine): retry, as asked
            response = self.call(self.planner, request)
        assert response.success, response.message
        return response.plan

    def send(self, **fields):
        """Send a goal; returns its handle once accepted."""
        assert self.client.wait_for_server(timeout_sec=30), "executor action server did not appear"
        self.feedback = []
        future = self.client.send_goal_async(self.Action.Goal(**fields),
                                             feedback_callback=lambda msg: self.feedback.append(msg.feedback))
        handle = self.wait_for(lambda: future.result() if future.done() else None, 30, "goal acceptance")
        assert handle.accepted
        return handle

    def result(self, handle, timeout: float = 240.0):
        future = handle.get_result_async()
        return self.wait_for(lambda: future.result() if future.done() else None, timeout, "the result").result

    def why(self, result) -> str:
        """A failed run's message and what the executor logged on the way (its states and notes)."""
        return f"{result.message}\n--- executor_node log (end) ---\n{self.executor_log()}"

    def wait_for_step(self, step: int, timeout: float = 120.0) -> None:
        self.wait_for(lambda: any(f.step == step for f in self.feedback), timeout, f"feedback step {step}")


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    processes = Processes(tmp_path_factory.mktemp("executor-cell"))
    sim_time = ["--ros-args", "-p", "use_sim_time:=true"]
    sim = processes.start_logged("sim_bridge", [DMG, "run", "dmg_sim_bridge", "sim_bridge_node", "--ros-args",
                                  "-p", "clock_rate:=100.0", "-p", "state_rate:=50.0"])
    for package, executable in (("dmg_perception", "perception_node"), ("dmg_planner", "planner_node")):
        processes.start_logged(executable, [DMG, "run", package, executable, *sim_time])
    executor = processes.start_logged("executor_node", [DMG, "run", "dmg_executor", "executor_node", *sim_time])
    operator = Operator()
    operator.sim = sim
    operator.executor_log = lambda: processes.output(executor, tail=4000)
    try:
        operator.wait_for(lambda: operator.latest.get("/perception/object_pose"), 90, "a first object pose")
        operator.wait_for(lambda: operator.latest.get("/executor/state"), 60, "the executor's state")
        yield operator
    finally:
        operator.close()
        processes.stop_all()


def translated(start: np.ndarray) -> np.ndarray:
    goal = start.copy()
    goal[:3, 3] += TRANSLATION * start[:3, 2]
    return goal


@pytest.mark.parametrize("alpha", [1.0, 0.0])
def test_single_translation_primitive_reaches_its_target_within_3_mm(cell, alpha):
    start = cell.reset()
    plan = cell.plan(start, translated(start))
    assert [p.kind for p in plan.primitives] == [1], "the planner should give one translation"
    result = cell.result(cell.send(plan=plan, alpha=alpha))
    assert result.success, cell.why(result)
    target = transform(plan.primitives[-1].gripper_after)
    moved, turned = distance(cell.truth(), target)
    assert moved < 0.003, f"{moved * 1000:.1f} mm from the target (alpha {alpha})"
    assert np.linalg.norm(cell.truth()[:3, 3] - start[:3, 3]) > 0.01       # it really moved
    assert result.final_position_error < 0.003 and result.primitives_completed == 1
    assert {f.step for f in cell.feedback} >= {0, 1, 2, 3}                   # every step was reported


def test_single_rotation_primitive_reaches_its_target_within_3_degrees(cell):
    start = cell.reset()
    goal = start.copy()
    goal[:3, :3] = Rotation.from_rotvec(ROTATION * start[:3, 0]).as_matrix() @ start[:3, :3]
    plan = cell.plan(start, goal)
    assert [p.kind for p in plan.primitives] == [0], "the planner should give one rotation"
    result = cell.result(cell.send(plan=plan, alpha=1.0))
    assert result.success, cell.why(result)
    _, turned = distance(cell.truth(), transform(plan.primitives[-1].gripper_after))
    assert np.rad2deg(turned) < 3.0
    assert np.rad2deg(distance(cell.truth(), start)[1]) > 15.0              # it really turned


def test_two_primitive_goal_is_planned_from_the_seen_grasp_and_completes(cell):
    start = cell.reset()
    goal = start.copy()
    goal[:3, :3] = Rotation.from_rotvec(ROTATION * start[:3, 0]).as_matrix() @ start[:3, :3]
    goal[:3, 3] += 0.012 * goal[:3, 2]
    from dmg_common.ros.geometry_messages import pose_message

    result = cell.result(cell.send(object_id="box", goal=pose_message(goal), alpha=1.0))
    assert result.success, cell.why(result)
    assert result.primitives_completed >= 2
    moved, turned = distance(cell.truth(), goal)
    assert moved < 0.003 and np.rad2deg(turned) < 3.0, (moved, np.rad2deg(turned))


def test_cancel_mid_push_stops_the_arms_and_closes_the_grip(cell):
    start = cell.reset()
    handle = cell.send(plan=cell.plan(start, translated(start)), alpha=1.0)
    cell.wait_for_step(2)                      # EXECUTE: the grip is loose and the pusher moving
    cell.spin(1.0)
    handle.cancel_goal_async()
    result = cell.result(handle, timeout=30)
    assert result.error_code == cell.Action.Result.CANCELED and not result.success
    cell.spin(0.5)
    speeds = np.abs(np.asarray(cell.latest["/joint_states"].velocity))
    assert speeds.max() < 0.01, f"joints still moving at {speeds.max():.3f} rad/s"
    grip = cell.wait_for(lambda: (g := cell.latest["/arm1/gripper/state"]).max_force > 14.0 and g, 5, "hold force")
    assert grip.force > 1.0
    held = cell.truth()
    cell.spin(1.0)
    assert distance(cell.truth(), held)[0] < 0.001
    state = cell.wait_for(lambda: (s := cell.latest.get("/executor/state")) and not s.active and s, 10, "idle state")
    assert "cancel" in state.message


def test_covered_camera_aborts_with_object_lost_and_the_object_stays_held(cell):
    start = cell.reset()
    handle = cell.send(plan=cell.plan(start, translated(start)), alpha=1.0)
    cell.wait_for_step(2)
    cell.cover.publish(cell.Bool(data=True))
    try:     # the push goes on by dead reckoning, the pusher looks round, then the run ends
        result = cell.result(handle, timeout=150)
        assert result.error_code == cell.Action.Result.OBJECT_LOST, result.message
        assert "lost" in result.message and "gripper 1 closed" in result.message
        cell.spin(0.5)
        grip = cell.wait_for(lambda: (g := cell.latest["/arm1/gripper/state"]).max_force > 14.0 and g, 5, "hold")
        assert grip.force > 1.0
        held = cell.truth()
        cell.spin(2.0)
        assert distance(cell.truth(), held)[0] < 0.001, "the object moved after the abort"
    finally:
        cell.cover.publish(cell.Bool(data=False))
        cell.spin(0.5)


@pytest.mark.parametrize("fields, words", [
    ({"object_id": "box", "alpha": 1.5}, "alpha"),
    ({"object_id": "no_such_object", "alpha": 1.0}, "unknown object"),
    ({"alpha": 1.0}, "neither a plan"),
])
def test_bad_goals_are_refused_with_a_reason_and_the_node_keeps_serving(cell, fields, words):
    result = cell.result(cell.send(**fields), timeout=60)
    assert not result.success and result.error_code in (cell.Action.Result.BAD_REQUEST,
                                                         cell.Action.Result.PLANNING_FAILED)
    assert words in result.message
    assert math.isnan(result.final_position_error)


def test_a_dead_robot_driver_stops_the_run_with_robot_lost_and_the_node_stays_up(cell):
    """Runs last: it kills the sim bridge (the robot's driver) in the middle of an approach."""
    import os
    import signal

    start = cell.reset()
    handle = cell.send(plan=cell.plan(start, translated(start)), alpha=1.0)
    cell.wait_for_step(1)
    os.killpg(cell.sim.pid, signal.SIGKILL)
    result = cell.result(handle, timeout=60)
    assert result.error_code == cell.Action.Result.ROBOT_LOST, result.message
    assert "robot" in result.message
    cell.latest.pop("/executor/state", None)
    state = cell.wait_for(lambda: cell.latest.get("/executor/state"), 30, "the executor still publishing")
    assert not state.active
