"""`dmg bench planner`: service round-trip latency of planner_node beside a trivial echo service.

Both servers run as their own processes (the planner with its default objects, the echo
server answering PlanRepositioning with an empty OK at once); one client calls each in
turn, one call at a time, and reports p50/p95 of the round trip. The difference is what
the planner adds over DDS + rclpy for the same message type. The planner's own
planning_time (measured inside the node) is reported too, and the planner's start-up time
until all shipped objects answer, with an empty graph cache (cold) and from the cache (warm).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time

import numpy as np

from dmg_bringup.bench_common import add_bench, stop_process
from dmg_common.environment import apply_ros_environment, ros_environment

ECHO_SERVICE = "/echo_plan_repositioning"


def echo_server() -> int:
    """Serve PlanRepositioning on ECHO_SERVICE with an empty OK response, until SIGINT/SIGTERM."""
    apply_ros_environment()
    import rclpy
    from dmg_interfaces.srv import PlanRepositioning
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile

    rclpy.init()
    node = rclpy.create_node("echo_plan_repositioning")

    def answer(request, response):
        response.success = True
        return response

    node.create_service(PlanRepositioning, ECHO_SERVICE, answer, qos_profile=QoSProfile(depth=100))
    print("serving", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    rclpy.try_shutdown()
    return 0


def _percentiles(values: list[float]) -> dict[str, float]:
    array = np.asarray(values) * 1000.0
    return {"p50_ms": float(np.percentile(array, 50)), "p95_ms": float(np.percentile(array, 95)),
            "mean_ms": float(array.mean()), "max_ms": float(array.max())}


def run(calls: int, seed_resolution: float) -> dict:
    apply_ros_environment()
    import rclpy
    from dmg_interfaces.srv import PlanRepositioning
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile

    from dmg_planner.graph import GraphParameters, build_graph
    from dmg_planner.objects import load_object
    from dmg_planner.search import grasp_pose

    cache = tempfile.mkdtemp(prefix="dmg_bench_")
    env = ros_environment()
    planner_command = [sys.executable, "-m", "dmg_bringup.cli", "run", "dmg_planner", "planner_node", "--ros-args",
                       "-p", f"cache_dir:={cache}", "-p", f"graph.seed_resolution:={seed_resolution}"]
    children: list[subprocess.Popen] = []
    model = load_object("box")
    graph = build_graph(model.load_shape(0.001), GraphParameters(seed_resolution=seed_resolution))
    rng = np.random.default_rng(0)
    rclpy.init()
    node = rclpy.create_node("planner_bench")
    executor = SingleThreadedExecutor()  # one executor for every call: a new one per call costs ms
    executor.add_node(node)
    try:
        clients = {name: node.create_client(PlanRepositioning, service, qos_profile=QoSProfile(depth=10))
                   for name, service in (("planner", "/plan_repositioning"), ("echo", ECHO_SERVICE))}
        # Start-up until every shipped object answers: empty cache (cold), then again (warm).
        startup = {}
        for kind in ("cold", "warm"):
            began = time.perf_counter()
            children.append(subprocess.Popen(planner_command, env=env, start_new_session=True,
                                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            if not clients["planner"].wait_for_service(timeout_sec=60):
                raise RuntimeError("planner service did not appear")
            for name in ("box", "plug", "bracket"):
                _wait_until_ready(executor, clients["planner"], PlanRepositioning.Request(object_id=name))
            startup[kind] = time.perf_counter() - began
            if kind == "cold":
                stop_process(children.pop())
                while clients["planner"].service_is_ready():
                    executor.spin_once(timeout_sec=0.1)
        children.append(subprocess.Popen([sys.executable, "-c", "from dmg_bringup.planner_bench import echo_server; "
                                          "echo_server()"], env=env, start_new_session=True, stdout=subprocess.DEVNULL))
        if not clients["echo"].wait_for_service(timeout_sec=60):
            raise RuntimeError("echo service did not appear")
        # Requests on the box's top face: random contacts and finger angles (all valid).
        requests = []
        for _ in range(calls):
            start = grasp_pose(graph, [*rng.uniform([-0.04, -0.02], [0.04, 0.02]), 0.02], rng.uniform(0, 2 * np.pi))
            goal = grasp_pose(graph, [*rng.uniform([-0.04, -0.02], [0.04, 0.02]), 0.02], rng.uniform(0, 2 * np.pi))
            request = PlanRepositioning.Request(object_id="box")
            for pose, message in ((start, request.start), (goal, request.goal)):
                message.position.x, message.position.y, message.position.z = map(float, pose.position)
                message.orientation.x, message.orientation.y, message.orientation.z, message.orientation.w = map(
                    float, pose.quaternion)
            requests.append(request)
        _wait_until_ready(executor, clients["planner"], requests[0])
        times: dict[str, list[float]] = {"planner": [], "echo": []}
        planning, failures = [], 0
        for request in requests:
            for name, client in clients.items():
                began = time.perf_counter()
                future = client.call_async(request)
                executor.spin_until_future_complete(future, timeout_sec=10)
                times[name].append(time.perf_counter() - began)
                if name == "planner":
                    response = future.result()
                    failures += response is None or not response.success
                    if response is not None and response.success:
                        planning.append(response.plan.planning_time)
        report = {"calls": calls, "failures": failures, "startup_s": startup, "seed_resolution": seed_resolution,
                  "box_supervoxels": graph.statistics()["supervoxels"], "planner": _percentiles(times["planner"]),
                  "echo": _percentiles(times["echo"]), "planning_inside_node": _percentiles(planning)}
        report["planner_adds"] = {key: report["planner"][key] - report["echo"][key] for key in ("p50_ms", "p95_ms")}
        report["goal_adds_under_5ms_p95"] = report["planner_adds"]["p95_ms"] < 5.0
        return report
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        for child in children:
            stop_process(child)


def _wait_until_ready(executor, client, request, timeout: float = 60.0) -> None:
    """Call until the planner answers something other than NOT_READY (its graph is built)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=10)
        if future.result() is not None and future.result().error_code != future.result().NOT_READY:
            return
        time.sleep(0.2)
    raise RuntimeError("the planner never became ready")


def format_report(report: dict) -> str:
    lines = [f"box graph: {report['box_supervoxels']} supervoxels (seed {report['seed_resolution']} m)"]
    lines += [f"{name:22s} p50 {report[name]['p50_ms']:7.2f} ms  p95 {report[name]['p95_ms']:7.2f} ms  "
             f"max {report[name]['max_ms']:7.2f} ms" for name in ("planner", "echo", "planning_inside_node")]
    adds = report["planner_adds"]
    lines += [f"start-up until box, plug and bracket answer: cold (empty cache) {report['startup_s']['cold']:.2f} s, "
              f"warm (from cache) {report['startup_s']['warm']:.2f} s",
              f"planner adds over echo: p50 {adds['p50_ms']:.2f} ms, p95 {adds['p95_ms']:.2f} ms "
              f"(goal < 5 ms at p95: {'met' if report['goal_adds_under_5ms_p95'] else 'MISSED'}); "
              f"{report['failures']} of {report['calls']} calls failed"]
    return "\n".join(lines)


def register(verbs: argparse._SubParsersAction) -> None:
    p = add_bench(verbs, "planner", "planner_node service latency beside an echo service", __doc__,
                  lambda args: run(args.calls, args.seed_resolution), format_report,
                  lambda report: 0 if report["failures"] == 0 else 1)
    p.add_argument("--calls", type=int, default=500, help="calls per service")
    p.add_argument("--seed-resolution", type=float, default=0.016,
                   help="graph seed resolution of the planner (default 0.016: the box has ~120 supervoxels, "
                        "the size the latency goal names)")
