"""`dmg bench sim`: real-time factor of the simulated cell, with and without the wrist camera.

Core: the ROS-free Cell steps physics with both arms under velocity control (a slow
circle each, so the damped-least-squares control runs every step), once without rendering
and once rendering the wrist camera at its rate; the time per rendered frame is reported.
Node: sim_bridge_node as its own process, unthrottled (real_time_factor 0), once with
camera_rate 0 and once at 30 Hz; the real-time factor is simulated time (/clock) over wall
time seen by a subscriber, which also counts the images that arrive.
Goals: >= 1.0 without the camera, >= 0.5 with it.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

import numpy as np

from dmg_bringup.bench_common import add_bench, stop_process
from dmg_common.environment import apply_ros_environment, ros_environment

GOALS = {"without_camera": 1.0, "with_camera": 0.5}


def core_run(seconds: float, camera_rate: float) -> dict:
    os.environ.setdefault("MUJOCO_GL", "egl")
    from dmg_sim_bridge.cell import Cell

    cell = Cell()
    cell.reset()
    command_period, frame_period = 0.01, (1.0 / camera_rate if camera_rate > 0 else np.inf)
    frames = []
    next_frame = cell.time if camera_rate > 0 else np.inf
    start_sim, start_wall = cell.time, time.perf_counter()
    while cell.time - start_sim < seconds:
        phase = 2 * np.pi * 0.5 * (cell.time - start_sim)
        for role, sign in (("arm1", 1.0), ("arm2", -1.0)):
            cell.command_twist(role, 0.03 * np.array([np.cos(phase), sign * np.sin(phase), 0.0]), np.zeros(3))
        cell.run(command_period)
        if cell.time >= next_frame:
            began = time.perf_counter()
            cell.render()
            frames.append(time.perf_counter() - began)
            next_frame += frame_period
    wall = time.perf_counter() - start_wall
    cell.close()
    result = {"sim_seconds": cell.time - start_sim, "wall_seconds": wall, "real_time_factor": (cell.time - start_sim) / wall}
    if frames:
        array = np.asarray(frames) * 1000
        result.update(frames=len(frames), frame_ms_mean=float(array.mean()), frame_ms_p95=float(np.percentile(array, 95)))
    return result


def node_run(seconds: float, camera_rate: float) -> dict:
    apply_ros_environment()
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Image

    command = [sys.executable, "-m", "dmg_bringup.cli", "run", "dmg_sim_bridge", "sim_bridge_node", "--ros-args",
               "-p", "real_time_factor:=0.0", "-p", f"camera_rate:={camera_rate}"]
    child = subprocess.Popen(command, env=ros_environment(), start_new_session=True,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rclpy.init()
    node = rclpy.create_node("sim_bench")
    latest = {"clock": None, "images": 0}

    def on_clock(msg):
        latest["clock"] = msg.clock.sec + msg.clock.nanosec * 1e-9

    node.create_subscription(Clock, "/clock", on_clock, 10)
    node.create_subscription(Image, "/arm2/camera/image_raw", lambda _: latest.__setitem__("images", latest["images"] + 1),
                             QoSProfile(depth=2, reliability=ReliabilityPolicy.BEST_EFFORT))
    try:
        deadline = time.monotonic() + 60
        while latest["clock"] is None and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
        if latest["clock"] is None:
            raise RuntimeError("sim_bridge_node published no /clock within 60 s")
        end_warmup = time.monotonic() + 2.0
        while time.monotonic() < end_warmup:
            rclpy.spin_once(node, timeout_sec=0.05)
        sim0, images0, wall0 = latest["clock"], latest["images"], time.monotonic()
        while time.monotonic() - wall0 < seconds:
            rclpy.spin_once(node, timeout_sec=0.05)
        wall = time.monotonic() - wall0
        sim = latest["clock"] - sim0
        result = {"sim_seconds": sim, "wall_seconds": wall, "real_time_factor": sim / wall,
                  "camera_rate": camera_rate, "images_received": latest["images"] - images0}
        if camera_rate > 0:
            result["images_received_per_sim_second"] = result["images_received"] / sim
        return result
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        stop_process(child)


def run(seconds: float, camera_rate: float) -> dict:
    report = {"core": {"without_camera": core_run(seconds, 0.0), "with_camera": core_run(seconds, camera_rate)},
              "node": {"without_camera": node_run(seconds, 0.0), "with_camera": node_run(seconds, camera_rate)},
              "camera_rate": camera_rate, "goals": GOALS}
    report["goals_met"] = {kind: report["node"][kind]["real_time_factor"] >= goal for kind, goal in GOALS.items()}
    return report


def format_report(report: dict) -> str:
    lines = []
    for level in ("core", "node"):
        for kind in ("without_camera", "with_camera"):
            entry = report[level][kind]
            line = f"{level:4s} {kind.replace('_', ' '):15s} real-time factor {entry['real_time_factor']:6.2f}"
            if "frame_ms_mean" in entry:
                line += f"  render {entry['frame_ms_mean']:.1f} ms/frame (p95 {entry['frame_ms_p95']:.1f})"
            if entry.get("images_received_per_sim_second") is not None:
                line += f"  images received {entry['images_received_per_sim_second']:.1f} per sim second"
            lines.append(line)
    met = report["goals_met"]
    lines.append(f"goals (node): >= 1.0 without camera {'met' if met['without_camera'] else 'MISSED'}, "
                 f">= 0.5 with camera at {report['camera_rate']:g} Hz {'met' if met['with_camera'] else 'MISSED'}")
    return "\n".join(lines)


def register(verbs: argparse._SubParsersAction) -> None:
    p = add_bench(verbs, "sim", "real-time factor of the simulated cell with and without the camera", __doc__,
                  lambda args: run(args.seconds, args.camera_rate), format_report)
    p.add_argument("--seconds", type=float, default=10.0, help="length of each run (core: sim s, node: wall s)")
    p.add_argument("--camera-rate", type=float, default=30.0, help="camera frames per simulated second")
