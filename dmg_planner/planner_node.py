"""planner_node: the DMG planning service a live cell calls.

Services:  load_object (dmg_interfaces/srv/LoadObject),
           plan_repositioning (dmg_interfaces/srv/PlanRepositioning)
Topics:    dmg/graph_markers (visualization_msgs/MarkerArray, transient local): every object's DMG
           dmg/plan (dmg_interfaces/msg/RepositioningPlan, transient local): the last plan
           dmg/plan_markers (visualization_msgs/MarkerArray, transient local): its contact paths
           /diagnostics (diagnostic_msgs/DiagnosticArray, 1 Hz)
Parameters: config/planner.yaml (declared with descriptions and ranges); `objects: ["*"]` (the
            default) preloads every object of the objects folder, leaving out (with an error
            in the log that names it and why) any whose object.yaml is broken.

The node only translates: dmg_planner.library holds the objects, builds graphs on a worker
thread and plans. One thread serves the requests in turn (a plan takes milliseconds; a
LoadObject that waits for its graph awaits it without holding up the others, see
dmg_common.ros.waiting) and every failure is answered with an error code, never raised.
"""
from __future__ import annotations

import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from dmg_interfaces.msg import RepositioningPlan
from dmg_interfaces.srv import LoadObject, PlanRepositioning
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import MarkerArray

from dmg_common.ros.node_main import run_node
from dmg_common.ros.parameters import declare_from_config
from dmg_common.ros.waiting import wait_until
from dmg_planner import ros_conversions as rc
from dmg_planner.library import LoadStatus, ObjectLibrary, ObjectState, options_from_parameters
from dmg_planner.objects import object_names
from dmg_planner.search_options import PlanStatus


def main(argv: list[str] | None = None) -> int:
    return run_node("planner_node", __doc__, "example: planner_node --ros-args -p objects:=[box] -p cache_dir:=/tmp/graphs",
                    argv, PlannerNode)


def preload_names(entries) -> list[str]:
    """The objects to load at start: the `objects` parameter with "*" standing for every object
    of the objects folder (config/objects or $DMG_OBJECTS_DIR), each name once."""
    return list(dict.fromkeys(name for entry in entries for name in (object_names() if entry == "*" else [entry])))


class PlannerNode(Node):
    def __init__(self) -> None:
        super().__init__("planner")
        began = time.perf_counter()
        values = declare_from_config(self, "planner")
        graph_defaults, search_defaults = options_from_parameters(values)
        self.frame_prefix = values["object_frame_prefix"]
        self.last_planning_time = float("nan")
        self.plans_served = 0
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
        self.graph_pub = self.create_publisher(MarkerArray, "dmg/graph_markers", latched)
        self.plan_pub = self.create_publisher(RepositioningPlan, "dmg/plan", latched)
        self.plan_marker_pub = self.create_publisher(MarkerArray, "dmg/plan_markers", latched)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.publish_lock = threading.Lock()
        self.library = ObjectLibrary(graph_defaults, search_defaults, values["cache_dir"] or None,
                                     on_change=self.on_object_change)
        service_qos = QoSProfile(depth=int(values["service_queue_depth"]))
        group = ReentrantCallbackGroup()   # plans and diagnostics go on while a LoadObject awaits its graph
        self.create_service(LoadObject, "load_object", self.on_load_object, qos_profile=service_qos, callback_group=group)
        self.create_service(PlanRepositioning, "plan_repositioning", self.on_plan, qos_profile=service_qos,
                            callback_group=group)
        self.create_timer(1.0, self.publish_diagnostics, callback_group=group)
        names = preload_names(values["objects"])
        for name in names:
            result = self.library.load_config_object(name)
            if result.status != 0:   # the object is left out; the others are served
                self.get_logger().error(f"preloading {name}: {result.message}; the planner goes on without it")
        ready = [o for o in self.library.objects() if o.state == ObjectState.READY]
        self.get_logger().info(f"planner up in {time.perf_counter() - began:.2f} s: {len(ready)} of "
                               f"{len(names)} objects ready at start "
                               f"({sum(o.from_cache for o in ready)} from cache), others building")

    # --- services ------------------------------------------------------------------------------
    async def on_load_object(self, request, response):
        began = time.perf_counter()
        overrides = rc.parameter_overrides(request.parameters)
        try:
            result = self.library.load(request.object_id, request.mesh_path, request.mesh_units, overrides,
                                       request.replace)
            if request.wait and result.status == LoadStatus.OK:
                await wait_until(self, result.entry.done.is_set)
                result = self.library.outcome(result.entry)
        except Exception as error:  # noqa: BLE001 - the node answers, it never dies on a request
            self.get_logger().error(f"load_object {request.object_id!r} failed: {error!r}")
            response.success, response.error_code, response.message = False, response.BUILD_FAILED, repr(error)
            return response
        response.success = int(result.status) == response.OK
        response.error_code = int(result.status)
        response.message = result.message
        if result.entry is not None and result.entry.graph is not None:
            rc.fill_statistics(response.statistics, result.entry.statistics())
        self.report(response.success, f"load_object {request.object_id!r} -> {result.status.name} in "
                    f"{(time.perf_counter() - began) * 1000:.0f} ms: {result.message}")
        return response

    def on_plan(self, request, response):
        began = time.perf_counter()
        try:
            start, goal = rc.gripper_pose(request.start, request.start_opening), rc.gripper_pose(request.goal, request.goal_opening)
            options = self.library.search_options(int(request.options.principal_finger), rc.penalties(request.options))
            result = self.library.plan(request.object_id, start, goal, options)
        except ValueError as error:
            result = rc.bad_request(str(error))
        except Exception as error:  # noqa: BLE001 - the node answers, it never dies on a request
            self.get_logger().error(f"plan_repositioning failed unexpectedly: {error!r}")
            result = rc.bad_request(f"internal error: {error!r}")
        response.success = result.status == PlanStatus.OK
        response.error_code = int(result.status)
        response.message = result.message
        response.start_component = int(result.start_component)
        response.goal_component = int(result.goal_component)
        if result.regrasp_pose is not None:
            response.regrasp_suggested = True
            response.regrasp_pose = rc.pose_message(result.regrasp_pose)
        if response.success:
            rc.fill_plan(response.plan, result, request, self.frame_prefix + request.object_id,
                         self.get_clock().now().to_msg())
            self.last_planning_time = result.planning_time
            self.plans_served += 1
            with self.publish_lock:
                self.plan_pub.publish(response.plan)
                self.plan_marker_pub.publish(rc.plan_markers(response.plan))
        self.report(response.success, f"plan {request.object_id!r} -> {result.status.name} "
                    f"({result.planning_time * 1000:.2f} ms planning, "
                    f"{(time.perf_counter() - began) * 1000:.2f} ms in the node): {result.message}")
        return response

    def shutdown(self) -> None:
        self.library.shutdown()

    def report(self, success: bool, text: str) -> None:
        """Log a request's outcome (rclpy wants one severity per call site, hence two calls)."""
        if success:
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)

    # --- publishing ----------------------------------------------------------------------------
    def on_object_change(self, entry) -> None:
        """A graph became ready (or failed): republish all graphs and the diagnostics."""
        self.get_logger().info(self.library.describe(entry))
        with self.publish_lock:
            self.graph_pub.publish(rc.graph_markers(self.library.objects(), self.frame_prefix,
                                                    self.get_clock().now().to_msg()))
        self.publish_diagnostics()

    def publish_diagnostics(self) -> None:
        self.diagnostics_pub.publish(rc.diagnostics(self.get_name(), self.library.objects(), self.last_planning_time,
                                                    self.plans_served, self.get_clock().now().to_msg()))


if __name__ == "__main__":
    sys.exit(main())
