"""executor_node: executes in-hand repositioning plans with two arms (action ExecuteRepositioning).

Action:     execute_repositioning (dmg_interfaces/ExecuteRepositioning): a plan + alpha, or an
            object + goal grasp (the node asks the planner, starting from the grasp it sees)
Subscribes: arm1/endpoint_pose, arm2/endpoint_pose (geometry_msgs/PoseStamped, base frame),
            arm1/gripper/state (dmg_interfaces/GripperState), perception/object_pose
            (geometry_msgs/PoseWithCovarianceStamped), arm2/camera/pose, arm2/camera/camera_info
Publishes:  arm1/cmd_vel, arm2/cmd_vel (geometry_msgs/TwistStamped, base frame),
            arm1/gripper/command, arm2/gripper/command (dmg_interfaces/GripperCommand),
            executor/state (dmg_interfaces/ExecutorState)
Client:     plan_repositioning (dmg_interfaces/PlanRepositioning)
Parameters: config/executor.yaml (topic prefixes, gains, speeds, limits, tolerances, timeouts).

The control loop runs on a timer of the node's clock (simulated time with use_sim_time). One
goal at a time; a second is rejected. Every way a run ends - done, cancelled, a fault - stops
both arms and leaves the object gripped at the hold force. One thread runs every callback (see
dmg_common.ros.waiting): a goal awaits its run's end while the control tick, the watchdog and the
subscriptions go on.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from dmg_interfaces.action import ExecuteRepositioning
from dmg_interfaces.msg import ExecutorState, GripperCommand, GripperState
from dmg_interfaces.srv import PlanRepositioning
from geometry_msgs.msg import Point, PoseStamped, PoseWithCovarianceStamped, TwistStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.task import Future
from sensor_msgs.msg import CameraInfo

from dmg_common.ros.geometry_messages import pose_message, seconds, transform_from_pose
from dmg_common.ros.node_main import run_node
from dmg_common.ros.parameters import declare_from_config
from dmg_common.ros.waiting import wait_until
from dmg_common.transforms import invert
from dmg_executor.contract import Command, Observation, Outcome, Result
from dmg_executor.controller import PlanExecutor
from dmg_executor.monitors import Persisting
from dmg_executor.push_points import ObjectSurface
from dmg_executor.settings import ExecutorSettings
from dmg_executor.views import CameraModel, TagLayout
from dmg_planner.objects import load_object
from dmg_planner.primitives import Primitive, PrimitiveKind

# executor/state: the last 100 messages (2 s at the 50 Hz control rate) kept for readers that lag and,
# transient local, handed to one that matches late - a bag recorder matched ~1 s after it subscribed
# lost a run's first states (measured in the demo); a volatile reader (`dmg monitor`) gets no history.
STATE_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
# The robot's state and the object pose: the newest only, best effort, as rclpy takes /clock. A deeper
# queue hands a node that fell behind its backlog oldest first, against a clock already current (50 poses
# at 50 Hz read as a robot silent for 1.0 s); a reliable one holds every later sample back until a lost
# one is resent (gripper state 1.2 s old). Measured with three cells on two cores.
LATEST = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)


def main(argv: list[str] | None = None) -> int:
    return run_node("executor_node", __doc__, "example: executor_node --ros-args -p use_sim_time:=true",
                    argv, ExecutorNode, startup_errors=(ValueError,))


class GoalError(ValueError):
    """A goal the node cannot run; carries the result code."""

    def __init__(self, outcome: Outcome, message: str):
        super().__init__(message)
        self.outcome = outcome


def _vector(point) -> np.ndarray:
    return np.array([point.x, point.y, point.z], float)


def primitives_from_message(messages) -> list[Primitive]:
    """ManipulationPrimitive messages -> the planner core's primitives (ValueError on bad values)."""
    primitives = []
    for index, m in enumerate(messages):
        if m.kind not in (PrimitiveKind.ROTATION, PrimitiveKind.TRANSLATION):
            raise ValueError(f"primitive {index} has kind {m.kind} (0 = rotation, 1 = translation)")
        values = [m.angle, m.finger_angle_before, m.finger_angle_after, m.opening_before, m.opening_after,
                  *(_vector(p) for p in (m.translation, m.contact_before, m.contact_after, m.secondary_before,
                                         m.secondary_after))]
        if not all(np.all(np.isfinite(v)) for v in values):
            raise ValueError(f"primitive {index} has non-finite values")
        primitives.append(Primitive(
            PrimitiveKind(m.kind), float(m.angle), _vector(m.translation), _vector(m.contact_before),
            _vector(m.contact_after), float(m.finger_angle_before), float(m.finger_angle_after),
            _vector(m.secondary_before), _vector(m.secondary_after),
            transform_from_pose(m.gripper_after, f"primitive {index} gripper_after")))
    return primitives


@dataclass
class Run:
    goal_handle: object
    executor: PlanExecutor
    object_id: str
    done: Future            # set by the tick (or the watchdog) that ends the run
    robot_stale: Persisting  # the robot's poses too old (wall clock), ended ROBOT_LOST once it persists
    last_feedback: float = -math.inf
    last_step: int = -1
    last_state: str = ""      # logged as it changes
    notes_logged: int = 0


class ExecutorNode(Node):
    def __init__(self) -> None:
        super().__init__("executor")
        values = self.values = declare_from_config(self, "executor")
        self.settings = ExecutorSettings.from_values(values)
        self.poses: dict[str, tuple[float, np.ndarray]] = {}    # holder, pusher, camera, object: (stamp, 4x4)
        self.opening: tuple[float, float] | None = None          # (stamp, m)
        self.object_covariance: np.ndarray | None = None          # 6x6 of the latest object pose
        self.camera_info: CameraInfo | None = None
        self.objects: dict[str, tuple[ObjectSurface, TagLayout]] = {}
        self.run: Run | None = None
        self.last_message = ""
        self.last_idle_state = -math.inf
        holder, pusher = values["holder_prefix"], values["pusher_prefix"]
        self.roles = {"holder": holder, "pusher": pusher}

        self.twist_pubs = {k: self.create_publisher(TwistStamped, f"{p}/cmd_vel", 10) for k, p in self.roles.items()}
        self.grip_pubs = {k: self.create_publisher(GripperCommand, f"{p}/gripper/command", 10)
                          for k, p in self.roles.items()}
        self.state_pub = self.create_publisher(ExecutorState, "executor/state", STATE_QOS)
        for key, topic in (("holder", f"{holder}/endpoint_pose"), ("pusher", f"{pusher}/endpoint_pose"),
                           ("camera", values["camera_pose_topic"])):
            self.create_subscription(PoseStamped, topic, lambda msg, key=key: self.on_pose(key, msg.header, msg.pose),
                                     LATEST)
        self.create_subscription(PoseWithCovarianceStamped, values["object_pose_topic"], self.on_object_pose, LATEST)
        self.create_subscription(GripperState, f"{holder}/gripper/state", self.on_gripper, LATEST)
        self.create_subscription(CameraInfo, values["camera_info_topic"], self.on_camera_info, qos_profile_sensor_data)
        self.planner = self.create_client(PlanRepositioning, values["planner_service"])
        self.action = ActionServer(self, ExecuteRepositioning, "execute_repositioning", execute_callback=self.execute,
                                   goal_callback=self.on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT)
        self.create_timer(1.0 / values["control_rate"], self.tick)
        # Wall-clock watchdog: with use_sim_time a dead simulator also stops the clock, and so the tick.
        self.robot_heard = time.monotonic()
        self.tick_finished = time.monotonic()   # a tick that plans pushes holds the subscriptions off a while
        self.create_timer(values["watchdog_period"], self.watchdog, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"executor up: {holder} holds, {pusher} pushes; control at {values['control_rate']:g} Hz "
                               f"on {values['object_pose_topic']}")

    # --- inputs ---------------------------------------------------------------------------
    def on_pose(self, key: str, header, pose) -> bool:
        """Keep a pose (False: refused, logged)."""
        try:
            transform = transform_from_pose(pose, key)
        except ValueError as error:
            self.get_logger().error(f"{key} pose ignored: {error}", throttle_duration_sec=2.0)
            return False
        self.poses[key] = (seconds(header.stamp), transform)
        if key in ("holder", "pusher"):
            self.robot_heard = time.monotonic()
        return True

    def on_object_pose(self, msg: PoseWithCovarianceStamped) -> None:
        if self.on_pose("object", msg.header, msg.pose.pose):
            self.object_covariance = np.asarray(msg.pose.covariance, float).reshape(6, 6)

    def on_gripper(self, msg: GripperState) -> None:
        if math.isfinite(msg.opening):
            self.opening = (seconds(msg.header.stamp), float(msg.opening))

    def on_camera_info(self, msg: CameraInfo) -> None:
        self.camera_info = msg

    def now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # --- goals ----------------------------------------------------------------------------------
    def on_goal(self, request) -> GoalResponse:
        if self.run is not None:
            self.get_logger().warning("goal rejected: a repositioning is already running")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    async def execute(self, goal_handle):
        request = goal_handle.request
        try:
            executor, object_id = await self.prepare(request)
        except GoalError as error:
            self.get_logger().error(f"goal refused ({error.outcome.name}): {error}")
            goal_handle.abort()
            return self.result(Result(error.outcome, str(error), 0, math.nan, math.nan, 0.0))
        run = Run(goal_handle, executor, object_id, Future(), Persisting(self.values["robot_confirm"]))
        self.run = run
        self.get_logger().info(f"executing {len(executor.primitives)} primitives on '{object_id}' "
                               f"(alpha {executor.alpha:g})")
        result = await run.done
        self.run = None
        self.last_message = result.message
        summary = f"{result.outcome.name}: {result.message} ({result.duration:.1f} s)"
        if result.outcome == Outcome.OK:   # one call site per severity: rclpy refuses to mix them
            self.get_logger().info(summary)
        else:
            self.get_logger().warning(summary)
        if result.outcome == Outcome.OK:
            goal_handle.succeed()
        elif result.outcome == Outcome.CANCELED and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return self.result(result)

    @staticmethod
    def result(result: Result) -> ExecuteRepositioning.Result:
        return ExecuteRepositioning.Result(
            success=result.outcome == Outcome.OK, error_code=int(result.outcome), message=result.message,
            primitives_completed=result.primitives_completed, final_position_error=float(result.position_error),
            final_angle_error=float(result.angle_error), execution_time=float(result.duration))

    async def prepare(self, request) -> tuple[PlanExecutor, str]:
        """Validate the goal, plan if asked, and build the run's executor."""
        alpha = float(request.alpha)
        if not 0.0 <= alpha <= 1.0:
            raise GoalError(Outcome.BAD_REQUEST, f"alpha {alpha} is outside [0, 1]")
        # Right after start-up on a loaded machine some of these come late; the camera model is not
        # required (without it the pusher keeps its orientation) but a run without it goes blind.
        await wait_until(self, lambda: self.seen_fresh() and self.camera_inputs() is not None,
                         self.values["startup_wait"])
        if self.observation() is None:
            raise GoalError(Outcome.ROBOT_LOST, "no gripper poses or gripper state from the robot: is the sim bridge "
                            f"(or driver) publishing {self.roles['holder']}/endpoint_pose, "
                            f"{self.roles['pusher']}/endpoint_pose and {self.roles['holder']}/gripper/state?")
        if not self.seen_fresh():
            raise GoalError(Outcome.OBJECT_LOST, f"no fresh object pose on {self.values['object_pose_topic']}: is "
                            "perception running and the object in the camera's view?")
        plan = request.plan
        if not plan.primitives:
            if not request.object_id:
                raise GoalError(Outcome.BAD_REQUEST, "the goal has neither a plan nor an object_id + goal to plan for")
            plan = await self.ask_planner(request)
        object_id = plan.object_id or request.object_id
        try:
            primitives = primitives_from_message(plan.primitives)
        except ValueError as error:
            raise GoalError(Outcome.BAD_REQUEST, f"bad plan: {error}") from None
        surface, tags = self.object_geometry(object_id)
        try:
            executor = PlanExecutor(self.settings, surface, primitives, int(plan.principal_finger), alpha, self.now(),
                                    self.camera_model(), tags)
        except ValueError as error:
            raise GoalError(Outcome.BAD_REQUEST, str(error)) from None
        return executor, object_id

    def object_geometry(self, object_id: str) -> tuple[ObjectSurface, TagLayout]:
        if object_id not in self.objects:
            try:
                model = load_object(object_id)
            except KeyError as error:
                raise GoalError(Outcome.BAD_REQUEST, str(error.args[0])) from None
            try:
                self.objects[object_id] = (ObjectSurface.of(model), TagLayout.of(model))
            except ValueError as error:
                raise GoalError(Outcome.BAD_REQUEST, str(error)) from None
        return self.objects[object_id]

    async def ask_planner(self, request):
        """Plan from the grasp perception sees now to the goal (PlanRepositioning)."""
        timeout = self.values["planner_timeout"]
        observation = self.observation()
        if not await wait_until(self, self.planner.service_is_ready, timeout):
            raise GoalError(Outcome.PLANNING_FAILED, f"planner service '{self.values['planner_service']}' is not "
                            f"available (waited {timeout:g} s)")
        start = invert(observation.object_in_holder)
        plan_request = PlanRepositioning.Request(object_id=request.object_id, start=pose_message(start),
                                                 start_opening=float(observation.opening), goal=request.goal,
                                                 goal_opening=float(request.goal_opening))
        future = self.planner.call_async(plan_request)
        if not await wait_until(self, future.done, timeout):
            self.planner.remove_pending_request(future)
            raise GoalError(Outcome.PLANNING_FAILED, f"the planner did not answer within {timeout:g} s")
        response = future.result()
        if not response.success:
            raise GoalError(Outcome.PLANNING_FAILED, f"planner: {response.message}")
        return response.plan

    # --- the control loop ------------------------------------------------------------------------
    def observation(self) -> Observation | None:
        poses, opening = self.poses, self.opening
        if "holder" not in poses or "pusher" not in poses or opening is None:
            return None
        seen_time, seen = poses.get("object", (-math.inf, None))
        return Observation(self.now(), poses["holder"][1], poses["pusher"][1], seen, seen_time, opening[1],
                           self.object_covariance)

    def seen_fresh(self) -> bool:
        observation = self.observation()
        return (observation is not None and observation.object_in_holder is not None
                and observation.time - observation.object_time <= self.settings.monitors.stale_after)

    def robot_age(self) -> tuple[float, str]:
        """How old (node clock) the robot's oldest input is, and which it is."""
        stamps = {f"{self.roles[key]}/endpoint_pose": self.poses[key][0] if key in self.poses else -math.inf
                  for key in ("holder", "pusher")}
        stamps[f"{self.roles['holder']}/gripper/state"] = self.opening[0] if self.opening else -math.inf
        oldest = min(stamps, key=stamps.get)
        return self.now() - stamps[oldest], oldest

    def camera_inputs(self) -> tuple[CameraInfo, dict] | None:
        """The latest camera_info and poses, once they hold what the camera model needs."""
        info, poses = self.camera_info, self.poses
        return (info, poses) if info is not None and info.k[0] > 0 and "camera" in poses and "pusher" in poses else None

    def camera_model(self) -> CameraModel | None:
        inputs = self.camera_inputs()
        if inputs is None:
            self.get_logger().warning("no camera model yet (camera_info and camera pose): the pusher keeps its "
                                      "orientation instead of keeping the tags in view")
            return None
        info, poses = inputs
        return CameraModel(np.asarray(info.k, float).reshape(3, 3), int(info.width), int(info.height),
                           invert(poses["pusher"][1]) @ poses["camera"][1])

    def silence(self) -> float:
        """Wall-clock seconds since the robot was last heard or a control tick last finished."""
        return time.monotonic() - max(self.robot_heard, self.tick_finished)

    def watchdog(self) -> None:
        """Wall clock: idle state messages, and a run stopped when the robot falls silent."""
        run, silent = self.run, self.silence()
        if run is None:
            self.publish_idle_state()
        elif silent > self.values["silence_timeout"] and not run.executor.done:
            # Silent robot and no control tick either (with sim time a dead simulator stops them
            # both); while ticks run, the tick's own check of the poses' age (node clock) applies.
            self.finish(run, run.executor.abort(Outcome.ROBOT_LOST, f"no gripper poses from the robot for "
                                                f"{silent:.1f} s (wall clock): stopped"))

    def tick(self) -> None:
        run = self.run
        if run is None or run.executor.done:
            return
        executor = run.executor
        age, oldest = self.robot_age()
        stale, now = age > self.settings.monitors.robot_timeout, time.monotonic()
        if run.goal_handle.is_cancel_requested:
            command = executor.cancel()
        elif run.robot_stale.holds(stale, now):
            command = executor.abort(Outcome.ROBOT_LOST, f"no gripper poses or gripper state from the robot for "
                                     f"{age:.2f} s (the oldest: {oldest}): stopped")
        elif stale:       # (the arms stop until the poses come, or robot_confirm has passed)
            if run.robot_stale.since == now:
                self.get_logger().warning(f"the robot's poses are {age:.2f} s old (the oldest: {oldest}): the arms "
                                          f"stop until they come")
            command = Command()
        else:
            command = executor.update(self.observation())
            if executor.failure is not None:     # (set once, as the run ends: later ticks do not come here)
                self.get_logger().error(executor.failure)
        self.finish(run, command)
        self.tick_finished = time.monotonic()

    def finish(self, run: Run, command: Command) -> None:
        """Send a tick's command and progress; when the run has ended, stop and hold once more."""
        executor = run.executor
        self.publish_command(command)
        self.publish_progress(run)
        self.log_progress(run)
        if executor.done:
            self.publish_command(Command(holder_grip=command.holder_grip))
            run.done.set_result(executor.result)

    def publish_command(self, command: Command) -> None:
        stamp = self.get_clock().now().to_msg()
        for key, twist in (("holder", command.holder), ("pusher", command.pusher)):
            msg = TwistStamped()
            msg.header.stamp, msg.header.frame_id = stamp, self.values["base_frame"]
            msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = (float(v) for v in twist[:3])
            msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = (float(v) for v in twist[3:])
            self.twist_pubs[key].publish(msg)
        for key, grip in (("holder", command.holder_grip), ("pusher", command.pusher_grip)):
            if grip is not None:
                msg = GripperCommand(opening=float(grip.opening), max_force=float(grip.max_force))
                msg.header.stamp = stamp
                self.grip_pubs[key].publish(msg)

    def log_progress(self, run: Run) -> None:
        """Each change of state and each note, as it happens: the log says what the run did."""
        executor, logger = run.executor, self.get_logger()
        if executor.state_name != run.last_state and not executor.done:
            run.last_state = executor.state_name
            progress = executor.progress()
            logger.info(f"primitive {progress.primitive_index + 1}/{progress.primitive_count}: {run.last_state}")
        for note in executor.notes[run.notes_logged:]:
            logger.info(f"note: {note}")
        run.notes_logged = len(executor.notes)

    def publish_progress(self, run: Run) -> None:
        progress = run.executor.progress()
        now = self.now()
        if now - run.last_feedback >= 1.0 / self.values["state_rate"] or int(progress.step) != run.last_step:
            run.last_feedback, run.last_step = now, int(progress.step)
            run.goal_handle.publish_feedback(ExecuteRepositioning.Feedback(
                primitive_index=progress.primitive_index, primitive_count=progress.primitive_count,
                step=int(progress.step), contact_error=float(progress.contact_error),
                angle_error=float(progress.angle_error)))
        primitive = run.executor.primitives[progress.primitive_index] if run.executor.primitives else None
        result = run.executor.result
        self.publish_state(ExecutorState(
            active=result is None, object_id=run.object_id, primitive_index=progress.primitive_index,
            primitive_count=progress.primitive_count, kind=int(primitive.kind) if primitive else 0,
            step=int(progress.step), step_name=progress.step.name, contact_error=float(progress.contact_error),
            angle_error=float(progress.angle_error), alpha=run.executor.alpha,
            contact=Point(**dict(zip("xyz", map(float, progress.contact)))),
            message=result.message if result else "; ".join(run.executor.notes)))

    def publish_idle_state(self) -> None:
        now = time.monotonic()
        if now - self.last_idle_state >= 1.0 / self.values["state_rate"]:
            self.last_idle_state = now
            self.publish_state(ExecutorState(active=False, step_name="IDLE", contact_error=math.nan,
                                             angle_error=math.nan, message=self.last_message))

    def publish_state(self, msg: ExecutorState) -> None:
        msg.header.stamp = self.get_clock().now().to_msg()
        self.state_pub.publish(msg)

    def shutdown(self) -> None:
        run = self.run
        if run is not None and self.context.ok():
            self.publish_command(run.executor.cancel("executor_node shutting down"))
