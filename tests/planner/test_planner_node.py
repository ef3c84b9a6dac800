"""planner_node as a user runs it: a separate process, called over real DDS."""
from __future__ import annotations

import subprocess
import time

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from conftest import DMG, Processes, side_by_side, sphere_mesh

pytestmark = pytest.mark.ros

SERVICE_TIMEOUT = 30.0


class Client:
    """An in-test rclpy node with clients for the planner's services (own context)."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.qos import QoSProfile
        from dmg_interfaces.srv import LoadObject, PlanRepositioning

        self.rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("planner_test_client", context=self.context)
        qos = QoSProfile(depth=100)
        self.plan_client = self.node.create_client(PlanRepositioning, "/plan_repositioning", qos_profile=qos)
        self.load_client = self.node.create_client(LoadObject, "/load_object", qos_profile=qos)
        self.PlanRepositioning, self.LoadObject = PlanRepositioning, LoadObject
        from rclpy.executors import SingleThreadedExecutor
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def wait_ready(self, timeout: float = SERVICE_TIMEOUT) -> None:
        assert self.plan_client.wait_for_service(timeout_sec=timeout), "planner service did not appear"
        assert self.load_client.wait_for_service(timeout_sec=timeout)

    def call_all(self, client, requests: list, timeout: float = SERVICE_TIMEOUT) -> list:
        futures = [client.call_async(r) for r in requests]
        deadline = time.monotonic() + timeout
        while not all(f.done() for f in futures) and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        return [f.result() if f.done() else None for f in futures]

    def plan(self, object_id: str, start, goal, principal: int = -1, **fields):
        request = self.PlanRepositioning.Request(object_id=object_id, start=pose_message(start), goal=pose_message(goal),
                                                 start_opening=float(start.opening), **fields)
        request.options.principal_finger = principal
        return self.call_all(self.plan_client, [request])[0]

    def spin(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)

    def load(self, **fields):
        return self.call_all(self.load_client, [self.LoadObject.Request(**fields)], timeout=120)[0]

    def close(self) -> None:
        self.node.destroy_node()
        self.rclpy.shutdown(context=self.context)


def pose_message(pose):
    from geometry_msgs.msg import Pose

    message = Pose()
    message.position.x, message.position.y, message.position.z = (float(v) for v in pose.position)
    q = message.orientation
    q.x, q.y, q.z, q.w = (float(v) for v in pose.quaternion)
    return message


def start_planner(processes: Processes, cache_dir, *extra: str) -> subprocess.Popen:
    return processes.start([DMG, "run", "dmg_planner", "planner_node", "--ros-args",
                            "-p", f"cache_dir:={cache_dir}", *extra], stderr=subprocess.STDOUT)


def wait_for_line(process: subprocess.Popen, words: str, timeout: float = 60.0) -> list[str]:
    """Read the node's log until a line contains `words`; return the lines read."""
    lines = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            break
        lines.append(line)
        if words in line:
            return lines
    raise AssertionError(f"no log line with {words!r} in {timeout} s:\n{''.join(lines)}")


def wait_all_built(process: subprocess.Popen, names=("box", "plug", "bracket"), timeout: float = 90.0) -> list[str]:
    """Read the log until every object says it was built or loaded from cache."""
    lines: list[str] = []
    pending = set(names)
    deadline = time.monotonic() + timeout
    while pending and time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            break
        lines.append(line)
        pending -= {name for name in pending if f"{name}: built" in line or f"{name}: loaded from cache" in line}
    assert not pending, f"never built: {pending}\n{''.join(lines)}"
    return lines


@pytest.fixture(scope="module")
def planner(tmp_path_factory):
    processes = Processes()
    process = start_planner(processes, tmp_path_factory.mktemp("cache"))
    wait_all_built(process)
    client = Client()
    client.wait_ready()
    yield process, client
    client.close()
    processes.stop_all()
    print("planner log:\n" + process.stdout.read()[-6000:])


@pytest.fixture(scope="module")
def graphs():
    """The same graphs the node builds, built here with the core library."""
    from dmg_planner.graph import GraphParameters, build_graph
    from dmg_planner.objects import load_object

    result = {}
    for name in ("box", "plug", "bracket"):
        model = load_object(name)
        parameters = GraphParameters(seed_resolution=model.seed_resolution)
        result[name] = build_graph(model.load_shape(parameters.voxel_resolution), parameters)
    return result


def reachable_pairs(graph, count: int, seed: int):
    from dmg_planner.manipulability import manipulability_matrix
    from dmg_planner.search import GripperPose

    matrix = manipulability_matrix(graph)
    rows, cols = np.nonzero(matrix.matrix)
    pick = np.random.default_rng(seed).choice(len(rows), count, replace=False)

    def pose(k):
        return GripperPose(matrix.positions[k], Rotation.from_matrix(matrix.rotations[k]).as_quat())

    return [(pose(i), pose(j)) for i, j in zip(rows[pick], cols[pick])]


def assert_same_plan(response, expected) -> None:
    assert response.success and response.error_code == 0, response.message
    plan = response.plan
    assert len(plan.primitives) == len(expected.primitives)
    for got, want in zip(plan.primitives, expected.primitives):
        assert got.kind == int(want.kind)
        assert got.angle == pytest.approx(want.angle, abs=1e-9)
        assert np.allclose([got.translation.x, got.translation.y, got.translation.z], want.translation, atol=1e-9)
        after = got.gripper_after
        assert np.allclose([after.position.x, after.position.y, after.position.z], want.gripper_after[:3, 3], atol=1e-9)
        turn = Rotation.from_quat([after.orientation.x, after.orientation.y, after.orientation.z, after.orientation.w])
        assert (turn.inv() * Rotation.from_matrix(want.gripper_after[:3, :3])).magnitude() < 1e-6
    assert plan.cost == pytest.approx(expected.cost, rel=1e-9)
    assert len(plan.principal_path) == len(expected.principal_path) == len(plan.secondary_path)
    assert plan.planning_time > 0 and plan.header.frame_id == f"object/{plan.object_id}"


def test_plans_match_the_core_library_on_every_shipped_object(planner, graphs):
    from dmg_planner.search import plan

    _, client = planner
    for index, (name, graph) in enumerate(graphs.items()):
        for start, goal in reachable_pairs(graph, 3, index):
            assert_same_plan(client.plan(name, start, goal), plan(graph, start, goal))


def graph_parameters(**values):
    from dmg_interfaces.msg import GraphParameters

    return GraphParameters(**values)


def test_every_error_code_is_reachable_and_the_node_keeps_serving(planner, graphs, tmp_path):
    from dmg_planner.objects import load_object
    from dmg_planner.search import GripperPose, grasp_pose

    process, client = planner
    box = graphs["box"]
    top = grasp_pose(box, [0.0, 0.0, 0.02], 0.0)
    side = grasp_pose(box, [0.05, 0.0, 0.0], 0.0)
    away = GripperPose(np.array([0.0, 0.5, 0.0]), top.quaternion)
    response = client.PlanRepositioning.Response
    tilt = Rotation.from_euler("y", 20, degrees=True) * Rotation.from_quat(top.quaternion)
    tilted = GripperPose(top.position, tilt.as_quat())
    cases = [
        (("nope", top, top), response.UNKNOWN_OBJECT, "unknown object"),
        (("box", GripperPose(np.array([np.nan, 0, 0]), top.quaternion), top), response.BAD_REQUEST, "non-finite"),
        (("box", GripperPose(top.position, top.quaternion * 2), top), response.BAD_REQUEST, "unit quaternion"),
        (("box", away, top), response.INVALID_START, "misses"),
        (("box", top, away), response.INVALID_GOAL, "misses"),
        (("box", top, side), response.DIFFERENT_COMPONENTS, "regrasp"),
        (("box", top, tilted), response.NO_PATH, "grasp axis"),
    ]
    for (object_id, start, goal), code, words in cases:
        result = client.plan(object_id, start, goal)
        assert not result.success and result.error_code == code and words in result.message, (code, result.message)
        assert result.regrasp_suggested == (code == response.DIFFERENT_COMPONENTS)
    # the regrasp hint: from the suggested grasp the goal is reachable in hand
    hint = client.plan("box", top, side)
    assert f"regrasp into component {hint.goal_component}" in hint.message
    p, q = hint.regrasp_pose.position, hint.regrasp_pose.orientation
    assert client.plan("box", GripperPose(np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w])), side).success
    assert client.plan("box", top, top, principal=5).error_code == response.BAD_REQUEST
    # NOT_READY: a fine graph of a new object is still building when the plan arrives; the
    # LoadObject that waits for that graph holds up no other request meanwhile.
    waiting = client.load_client.call_async(client.LoadObject.Request(
        object_id="fine_box", mesh_path=str(load_object("box").mesh_path), wait=True,
        parameters=graph_parameters(seed_resolution=0.003, voxel_resolution=0.0005)))
    client.spin(1.0)
    early = client.plan("fine_box", top, top)
    assert early.error_code == response.NOT_READY and "being built" in early.message
    assert client.plan("box", top, grasp_pose(box, [0.02, 0.01, 0.02], 0.0)).success
    assert not waiting.done(), "the LoadObject with wait answered before its graph was built"
    assert process.poll() is None


def test_fifty_concurrent_requests_are_all_answered_correctly(planner, graphs):
    from dmg_planner.search import plan

    _, client = planner
    pairs = [("plug", *pair) for pair in reachable_pairs(graphs["plug"], 25, 7)]
    pairs += [("bracket", *pair) for pair in reachable_pairs(graphs["bracket"], 25, 8)]
    requests = []
    for name, start, goal in pairs:
        request = client.PlanRepositioning.Request(object_id=name, start=pose_message(start), goal=pose_message(goal))
        request.options.principal_finger = -1
        requests.append(request)
    responses = client.call_all(client.plan_client, requests, timeout=60)
    assert all(r is not None for r in responses), f"{sum(r is None for r in responses)} of 50 unanswered"
    for (name, start, goal), response in zip(pairs, responses):
        assert_same_plan(response, plan(graphs[name], start, goal))


def test_load_object_errors_then_a_new_object_is_planned_on(planner, tmp_path):
    from dmg_planner.objects import load_object
    from dmg_planner.search import grasp_pose
    from dmg_planner.storage import load_graph

    _, client = planner
    codes = client.LoadObject.Response
    (tmp_path / "broken.stl").write_bytes(b"solid broken\nendsolid\n")
    mesh = str(load_object("plug").mesh_path)
    for fields, code, words in [
        (dict(object_id="broken", mesh_path=str(tmp_path / "broken.stl")), codes.MESH_ERROR, "empty or broken"),
        (dict(object_id="missing", mesh_path=str(tmp_path / "missing.stl")), codes.MESH_ERROR, "no such file"),
        (dict(object_id="", mesh_path=mesh), codes.BAD_REQUEST, "object_id"),
        (dict(object_id="inches", mesh_path=mesh, mesh_units="inch"), codes.BAD_REQUEST, "mesh_units"),
        (dict(object_id="negative", mesh_path=mesh, parameters=graph_parameters(delta=-1.0)), codes.BAD_REQUEST, "delta"),
        (dict(object_id="plug", mesh_path=mesh), codes.ALREADY_LOADED, "already loaded"),
        (dict(object_id="tiny", mesh_path=mesh, mesh_units="mm"), codes.MESH_ERROR, "units"),
        (dict(object_id="ball", mesh_path=str(sphere_mesh(tmp_path / "ball.stl")), wait=True), codes.BUILD_FAILED,
         "no DMG node: every one of the"),
    ]:
        result = client.load(**fields)
        assert not result.success and result.error_code == code and words in result.message, (fields, result.message)
    result = client.load(object_id="plug_copy", mesh_path=mesh, wait=True, parameters=graph_parameters(seed_resolution=0.008))
    assert result.success and result.statistics.dmg_nodes > 100 and not result.statistics.from_cache
    assert result.statistics.dmg_components >= 10 and result.statistics.cache_key
    graph = load_graph(next(p for p in _cache_files(client) if result.statistics.cache_key in p.name))
    start, goal = grasp_pose(graph, [-0.01, 0.0, 0.02], 0.0), grasp_pose(graph, [0.01, 0.01, 0.02], 0.0)
    assert client.plan("plug_copy", start, goal).success


def _cache_files(client):
    """Graph files in the module's planner cache (found through the running node's parameters)."""
    from pathlib import Path

    from rcl_interfaces.srv import GetParameters

    getter = client.node.create_client(GetParameters, "/planner/get_parameters")
    assert getter.wait_for_service(timeout_sec=10)
    response = client.call_all(getter, [GetParameters.Request(names=["cache_dir"])])[0]
    return list(Path(response.values[0].string_value).glob("*.npz"))


def test_latched_topics_and_diagnostics(planner, graphs):
    from dmg_planner.search import grasp_pose

    _, client = planner
    box = graphs["box"]
    assert client.plan("box", grasp_pose(box, [-0.02, 0.0, 0.02], np.pi), grasp_pose(box, [0.03, 0.0, 0.02], np.pi)).success
    # Late subscribers get the last plan and the graphs (transient local); three at once, each
    # a process of its own that mostly waits for discovery.
    echo, markers, diagnostics = side_by_side(*([DMG, "topic", "echo", topic, "--once", "--timeout", "10"]
                                                for topic in ("/dmg/plan", "/dmg/graph_markers", "/diagnostics")))
    assert echo.returncode == 0, echo.stderr
    last = yaml.safe_load(echo.stdout.split("\n---")[0])
    assert last["object_id"] == "box" and last["primitives"][0]["kind"] == 1
    assert markers.returncode == 0, markers.stderr
    for name in ("box", "plug", "bracket"):
        assert f"ns: {name}/vertices" in markers.stdout and f"ns: {name}/edges" in markers.stdout
    assert diagnostics.returncode == 0 and "supervoxels" in diagnostics.stdout and "plans_served" in diagnostics.stdout


def test_restart_loads_graphs_from_the_cache(tmp_path):
    processes = Processes()
    try:
        cold = start_planner(processes, tmp_path / "cache", "-p", "objects:=[box]")
        lines = wait_for_line(cold, "box: built")
        processes.stop_all()
        assert any("box: building" in line for line in lines)
        warm = start_planner(processes, tmp_path / "cache", "-p", "objects:=[box]")
        lines = wait_for_line(warm, "planner up")
        assert any("box: loaded from cache" in line for line in lines), "".join(lines)
        assert "1 of 1 objects ready at start (1 from cache)" in lines[-1]
    finally:
        processes.stop_all()


def test_a_configuration_without_the_gripper_description_stops_the_node_with_the_reason(tmp_path):
    """A copy of config/ from before config/gripper.yaml existed: exit 1 naming the file, no traceback."""
    import os
    import shutil

    from conftest import REPO

    config = tmp_path / "config"
    shutil.copytree(REPO / "config", config)
    (config / "gripper.yaml").unlink()
    result = subprocess.run([DMG, "run", "dmg_planner", "planner_node"], capture_output=True, text=True, timeout=60,
                            env={**os.environ, "DMG_CONFIG_DIR": str(config)})
    assert result.returncode == 1, result.stderr
    assert f"planner_node: cannot start: {config / 'gripper.yaml'}: cannot be read" in result.stderr
    assert "Traceback" not in result.stderr
