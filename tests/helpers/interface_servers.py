"""Serve PlanRepositioning, LoadObject, ResetScene and ExecuteRepositioning by echoing what arrived.

Every reply carries the request/goal as JSON in its `message`, so a client in another
process can check that each field crossed DDS intact; the action also sends one feedback
per primitive of the goal's plan.
"""
import json
import time

import rclpy
from rclpy.action import ActionServer

from dmg_bringup.messages import to_plain
from dmg_interfaces.action import ExecuteRepositioning
from dmg_interfaces.srv import LoadObject, PlanRepositioning, ResetScene


def plan(request, response):
    response.success = bool(request.object_id)
    response.error_code = response.OK if request.object_id else response.UNKNOWN_OBJECT
    response.message = json.dumps(to_plain(request))
    response.plan.object_id = request.object_id
    response.plan.start_pose = request.start
    response.plan.goal_pose = request.goal
    return response


def load(request, response):
    response.success = True
    response.message = json.dumps(to_plain(request))
    response.statistics.cache_key = request.mesh_path
    return response


def reset(request, response):
    response.success = True
    response.message = json.dumps(to_plain(request))
    response.object_in_gripper = request.object_in_gripper
    return response


def execute(goal_handle):
    goal = goal_handle.request
    count = len(goal.plan.primitives)
    for index in range(count):
        feedback = ExecuteRepositioning.Feedback(primitive_index=index, primitive_count=count,
                                                 step=ExecuteRepositioning.Feedback.STEP_EXECUTE)
        goal_handle.publish_feedback(feedback)
        time.sleep(0.05)
    goal_handle.succeed()
    return ExecuteRepositioning.Result(success=True, primitives_completed=count,
                                       message=json.dumps(to_plain(goal)))


rclpy.init()
node = rclpy.create_node("interface_servers")
node.create_service(PlanRepositioning, "/plan", plan)
node.create_service(LoadObject, "/load", load)
node.create_service(ResetScene, "/reset", reset)
ActionServer(node, ExecuteRepositioning, "/execute", execute)
print("serving", flush=True)
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
