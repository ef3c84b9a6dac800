"""sim_bridge_node: the simulated dual-arm cell behind the ROS interfaces of a real one.

Publishes:  /clock (rosgraph_msgs/Clock)                 simulated time, clock_rate per sim second
            joint_states (sensor_msgs/JointState)        both arms' joints and fingers
            arm1/endpoint_pose, arm2/endpoint_pose (geometry_msgs/PoseStamped, base frame):
                                                         each gripper's grasp frame
            arm1/gripper/state, arm2/gripper/state (dmg_interfaces/GripperState)
            arm2/camera/image_raw (sensor_msgs/Image, rgb8), arm2/camera/camera_info,
            arm2/camera/pose (PoseStamped, base frame, optical frame: z forward, x right, y down)
            ground_truth/object_in_arm1, ground_truth/object_in_arm2 (PoseStamped):
                                                         the object in each gripper frame, for
                                                         evaluation only (a real cell has none)
            /diagnostics
Subscribes: arm1/cmd_vel, arm2/cmd_vel (geometry_msgs/TwistStamped, base frame): grasp-frame
            velocity; none for 100 ms (config/sim.yaml control.watchdog) -> the arm holds still
            arm1/gripper/command, arm2/gripper/command (dmg_interfaces/GripperCommand)
            sim/camera_covered (std_msgs/Bool): fault injection - true puts a lens cap on the
                                                         wrist camera (black images), false takes it off
Services:   sim/reset (dmg_interfaces/ResetScene): arms home, object held in gripper 1
Parameters: config/sim_bridge.yaml; the cell itself: config/sim.yaml.

One thread owns the simulation (MuJoCo and its EGL renderer are used from one thread);
ROS callbacks only queue commands for it. Bad commands are logged and dropped, bad resets
answered with the reason; the simulation keeps running either way.
"""
from __future__ import annotations

import math
import os
import queue
import threading
import time
from dataclasses import dataclass, field

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")   # headless rendering; must precede the first mujoco import

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from dmg_interfaces.msg import GripperCommand, GripperState  # noqa: E402
from dmg_interfaces.srv import ResetScene  # noqa: E402
from geometry_msgs.msg import PoseStamped, TwistStamped  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image, JointState  # noqa: E402
from std_msgs.msg import Bool  # noqa: E402

from dmg_common.ros.geometry_messages import pose_message, time_message, transform_from_pose  # noqa: E402
from dmg_common.ros.node_main import run_node  # noqa: E402
from dmg_common.ros.parameters import declare_from_config  # noqa: E402
from dmg_sim_bridge.cell import Cell, CellError, ResetResult  # noqa: E402
from dmg_sim_bridge.recording import FrameRecorder  # noqa: E402
from dmg_sim_bridge.sim_config import ARM_ROLES, SimConfigError  # noqa: E402

RESET_TIMEOUT = 60.0         # s of wall time a reset request waits for the simulation thread
RESYNC_LAG = 0.5             # s; further behind real time than this, pacing restarts from now
SLOW_PASS = 0.25             # s (wall) one pass of the loop may take before it is logged with its parts
IMAGE_QOS = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)   # reliable: bags and echo get every frame


class PassTimer:
    """Wall time of the named parts of one pass of the simulation loop."""

    def __init__(self) -> None:
        self.start = self.last = time.monotonic()
        self.parts: dict[str, float] = {}

    def lap(self, name: str) -> None:
        now = time.monotonic()
        self.parts[name] = self.parts.get(name, 0.0) + now - self.last
        self.last = now

    def total(self) -> float:
        return self.last - self.start

    def __str__(self) -> str:
        return ", ".join(f"{name} {seconds:.2f} s" for name, seconds in self.parts.items())


@dataclass
class ResetRequest:
    object_name: str
    object_in_gripper: np.ndarray | None   # 4x4, None = the object's default grasp
    grip_force: float
    done: threading.Event = field(default_factory=threading.Event)
    result: ResetResult | None = None
    error: str = ""


def main(argv: list[str] | None = None) -> int:
    return run_node("sim_bridge_node", __doc__, "example: sim_bridge_node --ros-args -p object:=plug -p camera_rate:=15.0",
                    argv, SimBridgeNode, startup_errors=(CellError, SimConfigError))


class SimBridgeNode(Node):
    def __init__(self) -> None:
        super().__init__("sim_bridge")
        self.values = declare_from_config(self, "sim_bridge")
        self.base_frame = self.values["base_frame"]
        self.commands: queue.SimpleQueue = queue.SimpleQueue()
        self.stopping = threading.Event()
        # Built and reset here; from now on only the simulation thread touches it.
        self.cell = Cell()
        self.cell.reset(object_name=self.values["object"])
        self.statistics = {"real_time_factor": 0.0, "frames": 0, "commands_refused": 0, "slowest_pass": 0.0}

        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        self.joint_pub = self.create_publisher(JointState, "joint_states", 10)
        self.endpoint_pubs = {r: self.create_publisher(PoseStamped, f"{r}/endpoint_pose", 10) for r in ARM_ROLES}
        self.gripper_pubs = {r: self.create_publisher(GripperState, f"{r}/gripper/state", 10) for r in ARM_ROLES}
        self.truth_pubs = {r: self.create_publisher(PoseStamped, f"ground_truth/object_in_{r}", 10) for r in ARM_ROLES}
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        for role in ARM_ROLES:
            self.create_subscription(TwistStamped, f"{role}/cmd_vel",
                                     lambda msg, role=role: self.on_twist(role, msg), 10)
            self.create_subscription(GripperCommand, f"{role}/gripper/command",
                                     lambda msg, role=role: self.commands.put(("gripper", role, msg)), 10)
        camera = self.cell.config.camera
        self.image_pub = self.create_publisher(Image, f"{camera.arm}/camera/image_raw", IMAGE_QOS)
        self.info_pub = self.create_publisher(CameraInfo, f"{camera.arm}/camera/camera_info", IMAGE_QOS)
        self.camera_pose_pub = self.create_publisher(PoseStamped, f"{camera.arm}/camera/pose", 10)
        self.camera_covered = False
        self.create_subscription(Bool, "sim/camera_covered", self.on_camera_covered, 10)
        self.create_service(ResetScene, "sim/reset", self.on_reset)
        self.create_timer(1.0, self.publish_diagnostics)
        self.thread = threading.Thread(target=self.simulate, name="simulation", daemon=True)
        self.thread.start()
        self.get_logger().info(
            f"sim bridge up: object '{self.cell.object.name}' held in arm1, camera on {camera.arm} "
            f"{camera.width}x{camera.height} at {self.values['camera_rate']:g} Hz, "
            f"real-time factor target {self.values['real_time_factor']:g}")

    # --- ROS callbacks (executor thread): validate, then queue for the simulation ----------
    def on_twist(self, role: str, msg: TwistStamped) -> None:
        frame = msg.header.frame_id
        linear, angular = msg.twist.linear, msg.twist.angular
        values = [linear.x, linear.y, linear.z, angular.x, angular.y, angular.z]
        if frame not in ("", self.base_frame):
            self.refuse(f"{role}/cmd_vel refused: frame_id '{frame}' (velocities must be in '{self.base_frame}')")
        elif not all(math.isfinite(v) for v in values):
            self.refuse(f"{role}/cmd_vel refused: non-finite velocity {values}")
        else:
            self.commands.put(("twist", role, values))

    def on_camera_covered(self, msg: Bool) -> None:
        if bool(msg.data) != self.camera_covered:
            self.camera_covered = bool(msg.data)
            self.get_logger().warning(f"wrist camera {'covered: images are black' if msg.data else 'uncovered'}")

    def refuse(self, text: str) -> None:
        self.statistics["commands_refused"] += 1
        self.get_logger().error(text, throttle_duration_sec=1.0)

    def on_reset(self, request, response):
        try:
            pose = transform_from_pose(request.object_in_gripper, "object_in_gripper") if request.use_pose else None
        except ValueError as error:
            return self._reset_failed(response, str(error))
        pending = ResetRequest(request.object_id or self.cell.object.name, pose, request.grip_force)
        if not self.thread.is_alive():
            return self._reset_failed(response, "the simulation thread has stopped; restart the node")
        self.commands.put(("reset", None, pending))
        if not pending.done.wait(RESET_TIMEOUT):
            return self._reset_failed(response, f"the simulation did not answer within {RESET_TIMEOUT:.0f} s")
        if pending.result is None:
            return self._reset_failed(response, pending.error)
        response.success = True
        response.message = f"'{self.cell.object.name}' held in arm1 (opening {pending.result.opening * 1000:.1f} mm)"
        response.object_in_gripper = pose_message(pending.result.object_in_gripper)
        response.opening = pending.result.opening
        self.get_logger().info(f"reset: {response.message}")
        return response

    def _reset_failed(self, response, text: str):
        response.success = False
        response.message = text
        self.get_logger().error(f"reset refused: {text}")
        return response

    # --- the simulation thread ----------------------------------------------------------
    def simulate(self) -> None:
        cell = self.cell
        recorder = None
        if self.values["record_path"] and self.values["camera_rate"] > 0:
            recorder = FrameRecorder(self.values["record_path"], self.values["camera_rate"], self.values["record_every"])
        steps = max(1, round(1.0 / (self.values["clock_rate"] * cell.model.opt.timestep)))
        state_period = 1.0 / self.values["state_rate"]
        camera_period = 1.0 / self.values["camera_rate"] if self.values["camera_rate"] > 0 else math.inf
        rtf = self.values["real_time_factor"]
        anchor = (time.monotonic(), cell.time)
        next_state = next_camera = cell.time
        window = (time.monotonic(), cell.time)
        try:
            while not self.stopping.is_set() and rclpy.ok():
                parts = PassTimer()
                if self.apply_commands():
                    anchor = (time.monotonic(), cell.time)
                    next_state = next_camera = cell.time
                parts.lap("commands")
                cell.step(steps)
                parts.lap("physics")
                now = cell.time
                self.clock_pub.publish(Clock(clock=time_message(now)))
                if now >= next_state - 1e-9:
                    self.publish_state()
                    next_state += state_period
                parts.lap("state")
                if now >= next_camera - 1e-9:
                    image = cell.render()
                    parts.lap("render")
                    if self.camera_covered:
                        image = np.zeros_like(image)
                    self.publish_camera(image)
                    parts.lap("image")
                    if recorder is not None:
                        recorder.add(image)
                        parts.lap("recording")
                    next_camera += camera_period
                self.note_pass(parts)
                wall = time.monotonic()
                if wall - window[0] >= 1.0:
                    self.statistics["real_time_factor"] = (now - window[1]) / (wall - window[0])
                    window = (wall, now)
                if rtf > 0:
                    ahead = anchor[0] + (now - anchor[1]) / rtf - wall
                    if ahead > 0:
                        time.sleep(ahead)
                    elif ahead < -RESYNC_LAG:
                        anchor = (wall, now)
        except Exception as error:   # noqa: BLE001 - reported (diagnostics turn ERROR), not swallowed
            if not self.stopping.is_set() and self.context.ok():   # not just the shutdown racing a publish
                self.get_logger().fatal(f"simulation stopped: {type(error).__name__}: {error}")
        finally:
            if recorder is not None:
                recorder.close()
            cell.close()

    def note_pass(self, parts: "PassTimer") -> None:
        """Log a pass of the loop that held every topic back (other nodes see the robot fall silent)."""
        total = parts.total()
        self.statistics["slowest_pass"] = max(self.statistics["slowest_pass"], total)
        if total > SLOW_PASS:
            self.get_logger().warning(f"one simulation pass took {total:.2f} s (wall): {parts}",
                                      throttle_duration_sec=1.0)

    def apply_commands(self) -> bool:
        """Apply every queued command in order; True when the scene was reset."""
        was_reset = False
        while True:
            try:
                kind, role, payload = self.commands.get_nowait()
            except queue.Empty:
                return was_reset
            if kind == "twist":
                self.cell.command_twist(role, payload[:3], payload[3:])
            elif kind == "gripper":
                try:
                    self.cell.command_gripper(role, payload.opening, payload.max_force)
                except CellError as error:
                    self.refuse(f"{role}/gripper/command refused: {error}")
            else:
                try:
                    payload.result = self.cell.reset(payload.object_name, payload.object_in_gripper, payload.grip_force)
                except CellError as error:
                    payload.error = str(error)
                was_reset = True
                payload.done.set()

    def _stamped(self, transform, frame_id: str, stamp) -> PoseStamped:
        msg = PoseStamped(pose=pose_message(transform))
        msg.header.stamp, msg.header.frame_id = stamp, frame_id
        return msg

    def publish_state(self) -> None:
        cell = self.cell
        stamp = time_message(cell.time)
        joints = cell.joint_state()
        msg = JointState(name=joints.names, position=joints.position.tolist(), velocity=joints.velocity.tolist(),
                         effort=joints.effort.tolist())
        msg.header.stamp = stamp
        self.joint_pub.publish(msg)
        for role in ARM_ROLES:
            self.endpoint_pubs[role].publish(self._stamped(cell.grasp_pose(role), self.base_frame, stamp))
            self.truth_pubs[role].publish(self._stamped(cell.object_in_gripper(role), f"{role}_gripper", stamp))
            status = cell.gripper_status(role)
            state = GripperState(opening=status.opening, target_opening=status.target_opening,
                                 max_force=status.max_force, force=status.force)
            state.header.stamp, state.header.frame_id = stamp, f"{role}_gripper"
            self.gripper_pubs[role].publish(state)
        self.camera_pose_pub.publish(self._stamped(cell.camera_pose(), self.base_frame, stamp))

    def publish_camera(self, rgb) -> None:
        camera = self.cell.config.camera
        stamp = time_message(self.cell.time)
        frame_id = f"{camera.arm}_camera_optical"
        image = Image(height=camera.height, width=camera.width, encoding="rgb8", is_bigendian=0,
                      step=camera.width * 3, data=rgb.tobytes())
        image.header.stamp, image.header.frame_id = stamp, frame_id
        intrinsics = camera.intrinsic_matrix()
        projection = [*intrinsics[0], 0.0, *intrinsics[1], 0.0, *intrinsics[2], 0.0]
        info = CameraInfo(height=camera.height, width=camera.width, distortion_model="plumb_bob", d=[0.0] * 5,
                          k=intrinsics.ravel().tolist(), r=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], p=projection)
        info.header = image.header
        self.image_pub.publish(image)
        self.info_pub.publish(info)
        # The camera pose at exactly the image's time (perception need not interpolate).
        self.camera_pose_pub.publish(self._stamped(self.cell.camera_pose(), self.base_frame, stamp))
        self.statistics["frames"] += 1

    def publish_diagnostics(self) -> None:
        target = self.values["real_time_factor"]
        achieved = self.statistics["real_time_factor"]
        status = DiagnosticStatus(name="sim_bridge: cell", hardware_id="mujoco")
        alive = self.thread.is_alive()
        if not alive:
            status.level, status.message = DiagnosticStatus.ERROR, "simulation thread stopped"
        elif target > 0 and achieved < 0.9 * target:
            status.level, status.message = DiagnosticStatus.WARN, f"slower than real time x{target:g}: x{achieved:.2f}"
        else:
            status.level, status.message = DiagnosticStatus.OK, "running"
        values = {"object": self.cell.object.name, "sim_time": f"{self.cell.time:.3f}",
                  "real_time_factor": f"{achieved:.3f}", "camera_frames": str(self.statistics["frames"]),
                  "commands_refused": str(self.statistics["commands_refused"]),
                  "slowest_pass": f"{self.statistics['slowest_pass']:.3f}"}
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(msg)

    def shutdown(self) -> None:
        self.stopping.set()
        self.thread.join(timeout=5.0)
