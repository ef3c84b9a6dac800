"""dmg_interfaces: every interface crosses real DDS between two processes intact."""
from __future__ import annotations

import json

import pytest
import yaml

from conftest import DMG, Processes, dmg, helper_command

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def servers():
    """One echoing server process for every round trip; each round trip is a client process of its own."""
    procs = Processes()
    try:
        server = procs.start(helper_command("interface_servers.py"))
        assert server.stdout.readline().strip() == "serving"
        yield server
    finally:
        procs.stop_all()


def _message_json(stdout: str) -> dict:
    response = yaml.safe_load(stdout.split("response:\n", 1)[1])
    return json.loads(response["message"])


def test_error_codes_are_distinct_constants():
    from dmg_interfaces.srv import LoadObject, PlanRepositioning
    from dmg_interfaces.action import ExecuteRepositioning
    for cls, names in [
        (PlanRepositioning.Response, ["OK", "UNKNOWN_OBJECT", "INVALID_START", "INVALID_GOAL",
                                      "DIFFERENT_COMPONENTS", "NO_PATH", "BAD_REQUEST", "NOT_READY"]),
        (LoadObject.Response, ["OK", "BAD_REQUEST", "MESH_ERROR", "ALREADY_LOADED", "BUILD_FAILED"]),
        (ExecuteRepositioning.Result, ["OK", "BAD_REQUEST", "PLANNING_FAILED", "OBJECT_LOST", "SLIP",
                                       "STEP_TIMEOUT", "CANCELED", "LIMIT_VIOLATION"]),
    ]:
        values = [getattr(cls, name) for name in names]
        assert values[0] == 0 and len(set(values)) == len(values)


def test_plan_repositioning_round_trip(servers):
    request = {
        "object_id": "box",
        "start": {"position": {"x": 0.01, "y": -0.02, "z": 0.03},
                  "orientation": {"x": 0.0, "y": 0.0, "z": 0.7071067811865476, "w": 0.7071067811865476}},
        "start_opening": 0.04,
        "goal": {"position": {"x": -0.01, "y": 0.02, "z": 0.0}, "orientation": {"w": 1.0}},
        "goal_opening": 0.06,
        "options": {"principal_finger": 1, "rotation_penalty": 0.5, "pull_penalty": 2.0},
    }
    result = dmg("service", "call", "/plan", "dmg_interfaces/srv/PlanRepositioning", json.dumps(request))
    assert result.returncode == 0, result.stderr
    echoed = _message_json(result.stdout)
    assert echoed["object_id"] == "box"
    assert echoed["start"]["position"] == request["start"]["position"]
    assert echoed["start"]["orientation"] == request["start"]["orientation"]
    assert echoed["goal"]["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert (echoed["start_opening"], echoed["goal_opening"]) == (0.04, 0.06)
    assert echoed["options"] == {"principal_finger": 1, "rotation_penalty": 0.5,
                                 "opening_change_penalty": -1.0, "pull_penalty": 2.0,
                                 "arm_collision_penalty": -1.0, "unpushable_penalty": -1.0}
    response = yaml.safe_load(result.stdout.split("response:\n", 1)[1])
    assert response["plan"]["goal_pose"]["position"]["y"] == 0.02


def test_load_object_round_trip(servers):
    request = {"object_id": "plug", "mesh_path": "/tmp/plug.stl", "mesh_units": "mm",
               "parameters": {"seed_resolution": 0.005, "delta": 0.05, "angle_step_deg": 10.0,
                              "finger_length": 0.08, "finger_width": 0.02, "finger_thickness": 0.01},
               "replace": True, "wait": True}
    result = dmg("service", "call", "/load", "dmg_interfaces/srv/LoadObject", json.dumps(request))
    assert result.returncode == 0, result.stderr
    echoed = _message_json(result.stdout)
    assert {k: echoed[k] for k in ("object_id", "mesh_path", "mesh_units", "replace", "wait")} == \
        {"object_id": "plug", "mesh_path": "/tmp/plug.stl", "mesh_units": "mm", "replace": True, "wait": True}
    for key, value in request["parameters"].items():
        assert echoed["parameters"][key] == value
    assert echoed["parameters"]["voxel_resolution"] == 0.0  # unset = planner default


def test_reset_scene_round_trip(servers):
    request = {"object_id": "plug", "grip_force": 12.5, "use_pose": True,
               "object_in_gripper": {"position": {"x": 0.0, "y": 0.01, "z": 0.03},
                                     "orientation": {"x": 1.0, "y": 0.0, "z": 0.0, "w": 0.0}}}
    result = dmg("service", "call", "/reset", "dmg_interfaces/srv/ResetScene", json.dumps(request))
    assert result.returncode == 0, result.stderr
    assert _message_json(result.stdout) == request


def test_execute_repositioning_action_round_trip(servers):
    primitive = {"kind": 1, "translation": {"x": 0.01, "y": 0.0, "z": 0.0},
                 "contact_before": {"x": 0.05}, "contact_after": {"x": 0.06},
                 "opening_before": 0.04, "opening_after": 0.04}
    rotation = {"kind": 0, "angle": -0.5, "finger_angle_before": 1.0, "finger_angle_after": 0.5}
    goal = {"plan": {"object_id": "box", "primitives": [primitive, rotation, primitive],
                     "principal_path": [{"x": 0.05}, {"x": 0.06}], "finger_angles": [1.0, 0.5],
                     "cost": 0.02}, "alpha": 0.5}
    result = dmg("action", "send_goal", "/execute", "dmg_interfaces/action/ExecuteRepositioning",
                 json.dumps(goal), "--feedback")
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.count("Feedback:") == 3
    assert "Goal finished with status: SUCCEEDED" in result.stdout
    result_yaml = yaml.safe_load(result.stdout.split("Result:\n", 1)[1].split("\nGoal finished", 1)[0])
    assert result_yaml["primitives_completed"] == 3
    echoed = json.loads(result_yaml["message"])
    assert echoed["alpha"] == 0.5
    assert [p["kind"] for p in echoed["plan"]["primitives"]] == [1, 0, 1]
    assert echoed["plan"]["primitives"][1]["angle"] == -0.5
    assert echoed["plan"]["primitives"][0]["contact_after"] == {"x": 0.06, "y": 0.0, "z": 0.0}
    assert echoed["plan"]["finger_angles"] == [1.0, 0.5]


def test_gripper_command_over_a_topic(processes):
    processes.start([DMG, "topic", "pub", "/arm1/gripper/command", "dmg_interfaces/msg/GripperCommand",
                     "{header: {frame_id: arm1_gripper}, opening: 0.045, max_force: 3}", "-r", "5"])
    result = dmg("topic", "echo", "/arm1/gripper/command", "dmg_interfaces/msg/GripperCommand", "--once",
                 "--json", "--timeout", "20")
    assert result.returncode == 0, result.stderr
    echoed = json.loads(result.stdout.splitlines()[0])
    assert (echoed["header"]["frame_id"], echoed["opening"], echoed["max_force"]) == ("arm1_gripper", 0.045, 3.0)


def test_plan_message_over_a_topic(processes):
    """A RepositioningPlan published by one process is echoed by another."""
    plan = {"object_id": "bracket", "principal_finger": 1, "cost": 0.125,
            "primitives": [{"kind": 0, "angle": 0.25}], "secondary_path": [{"y": -0.03}]}
    processes.start([DMG, "topic", "pub", "/plan_out", "dmg_interfaces/msg/RepositioningPlan",
                     json.dumps(plan), "-r", "5"])
    result = dmg("topic", "echo", "/plan_out", "dmg_interfaces/msg/RepositioningPlan", "--once", "--json",
                 "--timeout", "20")
    assert result.returncode == 0, result.stderr
    echoed = json.loads(result.stdout.splitlines()[0])
    assert echoed["object_id"] == "bracket" and echoed["principal_finger"] == 1 and echoed["cost"] == 0.125
    assert echoed["primitives"][0]["angle"] == 0.25
    assert echoed["secondary_path"] == [{"x": 0.0, "y": -0.03, "z": 0.0}]
