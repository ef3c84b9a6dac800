"""sim_bridge_node as a user runs it: a separate process, driven and watched over real DDS."""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import time

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import DMG, REPO, Processes, RosTestNode
from dmg_perception.tags import detector

pytestmark = [pytest.mark.ros, pytest.mark.sim]

ROLES = ("arm1", "arm2")


class CellClient(RosTestNode):
    """Records the bridge's topics and commands it."""

    def __init__(self) -> None:
        super().__init__("sim_test_client")
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped, TwistStamped
        from rclpy.qos import QoSProfile
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import CameraInfo, Image, JointState

        from dmg_interfaces.msg import GripperCommand, GripperState
        from dmg_interfaces.srv import ResetScene

        self.TwistStamped, self.GripperCommand, self.ResetScene = TwistStamped, GripperCommand, ResetScene
        self.latest: dict[str, object] = {}
        self.history: dict[str, list] = {}
        topics = {"/clock": Clock, "/joint_states": JointState, "/arm2/camera/image_raw": Image,
                  "/arm2/camera/camera_info": CameraInfo, "/arm2/camera/pose": PoseStamped, "/diagnostics": DiagnosticArray}
        for role in ROLES:
            topics[f"/{role}/endpoint_pose"] = PoseStamped
            topics[f"/{role}/gripper/state"] = GripperState
            topics[f"/ground_truth/object_in_{role}"] = PoseStamped
        for topic, kind in topics.items():
            self.node.create_subscription(kind, topic, lambda msg, topic=topic: self._record(topic, msg), QoSProfile(depth=50))
        self.twist_pubs = {r: self.node.create_publisher(TwistStamped, f"/{r}/cmd_vel", 10) for r in ROLES}
        self.gripper_pubs = {r: self.node.create_publisher(GripperCommand, f"/{r}/gripper/command", 10) for r in ROLES}
        self.reset_client = self.node.create_client(ResetScene, "/sim/reset")

    def _record(self, topic: str, msg) -> None:
        self.latest[topic] = msg
        if topic.endswith("endpoint_pose") or topic.startswith("/ground_truth") or topic == "/diagnostics":
            self.history.setdefault(topic, []).append(msg)

    def sim_time(self) -> float:
        clock = self.wait_for(lambda: self.latest.get("/clock"), what="/clock").clock
        return clock.sec + clock.nanosec * 1e-9

    def twist(self, role: str, linear, angular=(0.0, 0.0, 0.0), frame_id: str = "base") -> None:
        msg = self.TwistStamped()
        msg.header.frame_id = frame_id
        msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = (float(v) for v in linear)
        msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = (float(v) for v in angular)
        self.twist_pubs[role].publish(msg)

    def drive(self, role: str, linear, seconds: float, rate: float = 50.0, wall_limit: float = 30.0) -> None:
        """Publish the same velocity at `rate` Hz (wall clock) for `seconds` of simulated time (a loaded machine
        runs the sim slower: so many sim seconds give the same number of robot states)."""
        until, deadline = self.sim_time() + seconds, time.monotonic() + wall_limit
        while self.sim_time() < until and time.monotonic() < deadline:
            self.twist(role, linear)
            self.spin(1.0 / rate)

    def spin_sim(self, seconds: float, wall_limit: float = 30.0) -> None:
        """Spin until `seconds` of simulated time have passed (a loaded machine runs the sim slower)."""
        until, deadline = self.sim_time() + seconds, time.monotonic() + wall_limit
        while self.sim_time() < until and time.monotonic() < deadline:
            self.spin(0.02)

    def reset(self, **fields):
        return self.call(self.reset_client, self.ResetScene.Request(**fields))


def position(pose_stamped) -> np.ndarray:
    p = pose_stamped.pose.position
    return np.array([p.x, p.y, p.z])


def stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


@pytest.fixture(scope="module")
def bridge(tmp_path_factory):
    processes = Processes(tmp_path_factory.mktemp("sim-bridge"))
    process = processes.start_logged("sim_bridge", [DMG, "run", "dmg_sim_bridge", "sim_bridge_node"])
    client = CellClient()
    try:
        client.wait_for(lambda: client.latest.get("/arm2/camera/image_raw"), timeout=60, what="the first camera image")
        yield process, client, processes
    finally:
        client.close()
        processes.stop_all()


def test_publishes_the_cell_state_camera_and_ground_truth(bridge):
    process, client, processes = bridge
    start = client.sim_time()
    client.spin(0.5)
    assert client.sim_time() > start
    joints = client.latest["/joint_states"]
    assert len(joints.name) == 18 and len(joints.position) == 18 and all(map(math.isfinite, joints.position))
    for role in ROLES:
        assert client.latest[f"/{role}/endpoint_pose"].header.frame_id == "base"
        assert client.latest[f"/ground_truth/object_in_{role}"].header.frame_id == f"{role}_gripper"
    # The default grasp pinches the 100 x 60 x 40 mm box across its 60 mm side, centred.
    assert client.latest["/arm1/gripper/state"].opening == pytest.approx(0.060, abs=0.001)
    assert np.linalg.norm(position(client.latest["/ground_truth/object_in_arm1"])) < 0.002
    image = client.latest["/arm2/camera/image_raw"]
    info = client.latest["/arm2/camera/camera_info"]
    assert (image.width, image.height, image.encoding) == (640, 480, "rgb8")
    assert info.header.frame_id == image.header.frame_id == "arm2_camera_optical"
    assert info.k[0] > 0 and info.k[2] == pytest.approx(319.5)
    pixels = np.frombuffer(image.data, np.uint8).reshape(image.height, image.width, 3)
    _, ids, _ = detector().detectMarkers(cv2.cvtColor(pixels, cv2.COLOR_RGB2GRAY))
    assert ids is not None and {0, 1} <= set(ids.ravel().tolist())


def _moving_velocities(poses) -> np.ndarray:
    """Velocities over the state intervals in which the endpoint moved faster than 2 cm/s."""
    if len(poses) < 2:
        return np.empty((0, 3))
    steps = np.diff([position(p) for p in poses], axis=0) / np.diff([stamp(p) for p in poses])[:, None]
    return steps[np.linalg.norm(steps, axis=1) > 0.02]


def test_velocity_commands_move_the_arm_and_the_watchdog_stops_it(bridge):
    _, client, _ = bridge
    topic = "/arm2/endpoint_pose"
    client.drive("arm2", (0.0, 0.0, 0.04), seconds=0.3)
    client.history[topic].clear()
    # Driven until the arm has been seen moving over 20 of the 10 ms state intervals, for at most 3 s of simulated
    # time (12 cm, inside the arm's reach). Only moving intervals count: a test process stalled past the watchdog
    # (100 ms) on a loaded machine (the parallel tests' simulators) rightly stops the arm until the next command
    # comes, and must not count as slow tracking; the speed it moves at is the command's.
    driven, moving = 0.0, np.empty((0, 3))
    while len(moving) < 20 and driven < 3.0:
        started = client.sim_time()
        client.drive("arm2", (0.0, 0.0, 0.04), seconds=0.25)
        driven += client.sim_time() - started
        moving = _moving_velocities(client.history[topic])
    assert len(moving) >= 20, (len(client.history[topic]), len(moving), driven)
    assert np.median(moving, axis=0) == pytest.approx([0.0, 0.0, 0.04], abs=0.04 * 0.05)
    # No more commands: the watchdog (0.1 s of sim time) stops the arm. Judged on the poses' own stamps (a starved
    # test process may still hold poses from before the stop when its clock has moved on).
    stopped = client.sim_time()
    held = client.wait_for(lambda: stamp(p := client.latest[topic]) >= stopped + 1.0 and p, what="a pose after the stop")
    later = client.wait_for(lambda: stamp(p := client.latest[topic]) >= stamp(held) + 0.5 and p, what="a later pose")
    assert np.linalg.norm(position(later) - position(held)) < 1e-4
    client.drive("arm2", (0.0, 0.0, -0.04), seconds=0.3 + driven)   # back down, clear of the object


def test_gripper_command_sets_the_opening(bridge):
    _, client, _ = bridge
    client.gripper_pubs["arm2"].publish(client.GripperCommand(opening=0.05, max_force=10.0))
    state = client.wait_for(lambda: (s := client.latest["/arm2/gripper/state"]).opening > 0.049 and s, what="arm2 open")
    assert state.target_opening == pytest.approx(0.05) and state.max_force == pytest.approx(10.0)
    client.gripper_pubs["arm2"].publish(client.GripperCommand(opening=0.0, max_force=0.0))
    client.wait_for(lambda: client.latest["/arm2/gripper/state"].opening < 0.001, what="arm2 closed")


def test_bad_commands_are_refused_and_the_node_carries_on(bridge):
    process, client, processes = bridge
    client.spin(0.5)                          # any earlier motion has stopped
    before = position(client.latest["/arm2/endpoint_pose"])
    client.twist("arm2", (math.nan, 0.0, 0.0))
    client.twist("arm2", (0.05, 0.0, 0.0), frame_id="arm2_gripper")
    client.gripper_pubs["arm1"].publish(client.GripperCommand(opening=5.0, max_force=0.0))
    client.gripper_pubs["arm1"].publish(client.GripperCommand(opening=0.0, max_force=math.inf))
    client.spin(1.5)
    assert process.poll() is None, processes.output(process)
    assert np.linalg.norm(position(client.latest["/arm2/endpoint_pose"]) - before) < 1e-4
    assert client.latest["/arm1/gripper/state"].opening == pytest.approx(0.060, abs=0.001)   # still holding

    def reported() -> dict[str, str]:
        return {kv.key: kv.value for kv in client.history["/diagnostics"][-1].status[0].values}

    # (diagnostics come once a second: a starved test process can still hold an older one)
    values = client.wait_for(lambda: int((v := reported())["commands_refused"]) >= 4 and v, timeout=10.0,
                             what="diagnostics counting the 4 refused commands")
    assert float(values["slowest_pass"]) > 0.0          # the loop's slowest pass is reported (seconds)


def test_reset_holds_the_requested_object_at_the_requested_pose_and_refuses_bad_requests(bridge):
    process, client, processes = bridge
    from geometry_msgs.msg import Pose

    for fields, reason in [({"object_id": "no_such_object"}, "unknown object"),
                           ({"use_pose": True, "object_in_gripper": Pose()}, None)]:   # identity: the 100 mm side
        response = client.reset(**fields)
        assert response.success is (reason is None), response.message
        if reason:
            assert reason in response.message
    bad = Pose()
    bad.position.x = math.nan
    bad.orientation.w = 1.0
    response = client.reset(use_pose=True, object_in_gripper=bad)
    assert not response.success and "non-finite" in response.message
    tilted = Pose()
    tilted.orientation.w = 1.0
    tilted.orientation.x = 0.0
    # The plug pinched across its 60 mm side (object y along the grasp axis), turned 20 deg about it.
    x, y, z, w = (Rotation.from_euler("x", 20, degrees=True) * Rotation.from_matrix(
        [[0, 1, 0], [0, 0, 1], [1, 0, 0]])).as_quat()
    tilted.orientation.x, tilted.orientation.y, tilted.orientation.z, tilted.orientation.w = x, y, z, w
    time_before = client.sim_time()
    response = client.reset(object_id="plug", use_pose=True, object_in_gripper=tilted, grip_force=12.0)
    assert response.success, response.message
    settled = response.object_in_gripper.orientation
    turned = Rotation.from_quat([x, y, z, w]).inv() * Rotation.from_quat([settled.x, settled.y, settled.z, settled.w])
    assert turned.magnitude() < np.deg2rad(2)
    assert response.opening == pytest.approx(0.060, abs=0.001)
    # The ground truth comes to show the requested pose (the client may still be reading older
    # messages from its queues when the reply arrives, so wait for it rather than for a stamp).
    requested = Rotation.from_quat([x, y, z, w])

    def shows_request():
        q = client.latest["/ground_truth/object_in_arm1"].pose.orientation
        return (Rotation.from_quat([q.x, q.y, q.z, q.w]).inv() * requested).magnitude() < np.deg2rad(2)

    client.wait_for(shows_request, timeout=10, what="ground truth of the requested pose")
    client.spin(0.3)
    assert shows_request()                           # and it stays there (held)
    assert client.sim_time() >= time_before          # simulated time never runs backwards
    assert process.poll() is None


def test_an_unknown_start_object_exits_with_the_reason():
    result = subprocess.run([DMG, "run", "dmg_sim_bridge", "sim_bridge_node", "--ros-args", "-p", "object:=no_such_object"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert "cannot start: unknown object 'no_such_object'" in result.stderr


@pytest.mark.parametrize("argument, words", [("camera_rate:=30", "needs a decimal point"),
                                             ("camera_rate:=500.0", "out of range")])
def test_a_refused_parameter_exits_with_the_reason(argument, words):
    result = subprocess.run([DMG, "run", "dmg_sim_bridge", "sim_bridge_node", "--ros-args", "-p", argument],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1 and "cannot start" in result.stderr and words in result.stderr, result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("breakage, words", [("gripper: [not, a, mapping]\n", "section 'gripper'"),
                                             ("physics: {timestep: 0.002\n", "cannot be read")])
def test_a_broken_sim_yaml_exits_with_the_reason(tmp_path, breakage, words):
    config = tmp_path / "config"
    shutil.copytree(REPO / "config", config)
    (config / "sim.yaml").write_text(breakage)
    result = subprocess.run([DMG, "run", "dmg_sim_bridge", "sim_bridge_node"], capture_output=True, text=True,
                            timeout=60, env={**os.environ, "DMG_CONFIG_DIR": str(config)})
    assert result.returncode == 1 and "cannot start" in result.stderr and words in result.stderr, result.stderr
    assert "Traceback" not in result.stderr
