"""`dmg bench perception`: frames per second of the perception pipeline on one core, and latency.

Frames are rendered once by the simulated cell (every shipped object, default grasp turned
by a few angles about the grasp axis). Core: one process pinned to one CPU converts each
rgb8 message payload to grey, detects the tags and fuses the object pose in the gripper
frame, round after round. Node: perception_node as its own process pinned to one CPU; this
process offers it the frames as fast as `--offer-rate` (with camera_info and the camera and
gripper poses stamped like each image, wall clock) and measures what comes back: object
poses per second, and latency from the image stamp to the pose's arrival. Goal:
>= 60 fps (the paper tracks at 28 fps).
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

GOAL_FPS = 60.0


def render_frames(turns_deg=(-20.0, 0.0, 20.0)) -> list[dict]:
    """RGB frames with the poses perception needs, for every shipped object."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from scipy.spatial.transform import Rotation

    from dmg_common.transforms import from_rotation
    from dmg_planner.objects import load_object, object_names
    from dmg_sim_bridge.cell import Cell, default_grasp

    cell = Cell()
    frames = []
    for name in object_names():
        for turn in turns_deg:
            rotation = from_rotation(Rotation.from_euler("x", turn, degrees=True).as_matrix(), np.zeros(3))
            cell.reset(object_name=name, object_in_gripper=rotation @ default_grasp(load_object(name), 0.12))
            frames.append({"rgb": cell.render(), "camera": cell.camera_pose(), "gripper": cell.grasp_pose("arm1")})
    intrinsics = cell.config.camera.intrinsic_matrix()
    cell.close()
    for frame in frames:
        frame["intrinsics"] = intrinsics
    return frames


def core_fps(frames: list[dict], seconds: float) -> dict:
    """Pipeline rate in this process, pinned to one CPU."""
    from dmg_common.transforms import invert
    from dmg_perception.estimator import ObjectPoseEstimator
    from dmg_perception.images import grey_image
    from dmg_planner.objects import load_object, object_names

    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})
    estimator = ObjectPoseEstimator([load_object(name) for name in object_names()])
    estimator.set_camera(frames[0]["intrinsics"])
    payloads = [(f["rgb"].tobytes(), invert(f["gripper"]) @ f["camera"]) for f in frames]
    height, width = frames[0]["rgb"].shape[:2]
    times, found = [], 0
    began = time.perf_counter()
    while time.perf_counter() - began < seconds:
        for data, frame_from_camera in payloads:
            start = time.perf_counter()
            grey = grey_image("rgb8", width, height, width * 3, data)
            estimate = estimator.estimate(estimator.detect(grey), frame_from_camera)
            times.append(time.perf_counter() - start)
            found += estimate is not None
    array = np.asarray(times) * 1000
    return {"frames": len(times), "poses": found, "fps": float(1000 / array.mean()),
            "ms_mean": float(array.mean()), "ms_p95": float(np.percentile(array, 95))}


def node_fps(frames: list[dict], seconds: float, offer_rate: float) -> dict:
    apply_ros_environment()
    import rclpy
    from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image

    from dmg_common.ros.geometry_messages import pose_message, time_message
    from dmg_common.ros.geometry_messages import seconds as stamp_seconds

    cpu = sorted(os.sched_getaffinity(0))[-1]
    command = [sys.executable, "-m", "dmg_bringup.cli", "run", "dmg_perception", "perception_node"]
    child = subprocess.Popen(command, env=ros_environment(), start_new_session=True, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, preexec_fn=lambda: os.sched_setaffinity(0, {cpu}))
    rclpy.init()
    node = rclpy.create_node("perception_bench")
    image_pub = node.create_publisher(Image, "arm2/camera/image_raw", qos_profile_sensor_data)
    info_pub = node.create_publisher(CameraInfo, "arm2/camera/camera_info", qos_profile_sensor_data)
    camera_pub = node.create_publisher(PoseStamped, "arm2/camera/pose", 50)
    gripper_pub = node.create_publisher(PoseStamped, "arm1/endpoint_pose", 50)
    arrivals: list[tuple[float, float]] = []
    node.create_subscription(PoseWithCovarianceStamped, "perception/object_pose",
                             lambda msg: arrivals.append((time.time(), stamp_seconds(msg.header.stamp))), 100)
    height, width = frames[0]["rgb"].shape[:2]
    info = CameraInfo(width=width, height=height, k=frames[0]["intrinsics"].ravel().tolist(), d=[0.0] * 5)
    data = [f["rgb"].tobytes() for f in frames]

    def offer(index: int) -> None:
        frame = frames[index % len(frames)]
        stamp = time_message(time.time())
        for publisher, pose in ((camera_pub, frame["camera"]), (gripper_pub, frame["gripper"])):
            msg = PoseStamped(pose=pose_message(pose))
            msg.header.stamp, msg.header.frame_id = stamp, "base"
            publisher.publish(msg)
        image = Image(width=width, height=height, encoding="rgb8", step=width * 3, data=data[index % len(frames)])
        image.header.stamp, image.header.frame_id = stamp, "arm2_camera_optical"
        info.header = image.header
        info_pub.publish(info)
        image_pub.publish(image)

    try:
        index, deadline = 0, time.monotonic() + 60
        while not arrivals and time.monotonic() < deadline:   # until the node answers
            offer(index)
            index += 1
            rclpy.spin_once(node, timeout_sec=0.05)
        if not arrivals:
            raise RuntimeError("perception_node published no object pose within 60 s")
        arrivals.clear()
        began, offered = time.monotonic(), 0
        while time.monotonic() - began < seconds:
            offer(index)
            index, offered = index + 1, offered + 1
            next_offer = began + offered / offer_rate
            while time.monotonic() < next_offer:
                rclpy.spin_once(node, timeout_sec=max(0.0, next_offer - time.monotonic()))
        elapsed = time.monotonic() - began
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
        latency = np.asarray([arrived - stamped for arrived, stamped in arrivals]) * 1000
        return {"offered_fps": offered / elapsed, "poses_fps": len(arrivals) / elapsed,
                "latency_ms_p50": float(np.percentile(latency, 50)), "latency_ms_p95": float(np.percentile(latency, 95)),
                "cpu": cpu}
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        stop_process(child)


def run(seconds: float, offer_rate: float) -> dict:
    frames = render_frames()
    node = node_fps(frames, seconds, offer_rate)
    core = core_fps(frames, seconds)
    return {"frames_rendered": len(frames), "core_one_cpu": core, "node_one_cpu": node, "goal_fps": GOAL_FPS,
            "goal_met": node["poses_fps"] >= GOAL_FPS}


def format_report(report: dict) -> str:
    core, node = report["core_one_cpu"], report["node_one_cpu"]
    return "\n".join([
        f"core (one CPU): {core['fps']:.1f} fps, {core['ms_mean']:.2f} ms per frame (p95 {core['ms_p95']:.2f}); "
        f"{core['poses']} poses from {core['frames']} frames",
        f"node (one CPU): offered {node['offered_fps']:.1f} fps, object poses {node['poses_fps']:.1f} per second, "
        f"latency image stamp -> pose received p50 {node['latency_ms_p50']:.1f} ms, p95 {node['latency_ms_p95']:.1f} ms",
        f"goal >= {report['goal_fps']:g} fps: {'met' if report['goal_met'] else 'MISSED'}"])


def register(verbs: argparse._SubParsersAction) -> None:
    p = add_bench(verbs, "perception", "perception pipeline fps on one CPU and latency", __doc__,
                  lambda args: run(args.seconds, args.offer_rate), format_report)
    p.add_argument("--seconds", type=float, default=10.0, help="length of each measurement")
    p.add_argument("--offer-rate", type=float, default=90.0, help="frames per second offered to the node")
