"""perception_node on the simulated cell: both as separate processes over real DDS."""
from __future__ import annotations

import subprocess
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import DMG, REPO, Processes, RosTestNode
from dmg_common.transforms import distance, homogeneous

pytestmark = pytest.mark.ros


class Watcher(RosTestNode):
    """Records perception's and the sim's topics."""

    def __init__(self) -> None:
        super().__init__("perception_test_watcher")
        from diagnostic_msgs.msg import DiagnosticArray
        from dmg_interfaces.msg import PerceptionStatus, TagDetections
        from dmg_interfaces.srv import ResetScene
        from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import Image

        self.Image, self.ResetScene = Image, ResetScene
        self.latest, self.truth, self.diagnostics = {}, [], {}
        topics = {"/perception/object_pose": PoseWithCovarianceStamped, "/perception/status": PerceptionStatus,
                  "/perception/detections": TagDetections, "/perception/debug_image": Image,
                  "/bad/perception/status": PerceptionStatus}
        for topic, kind in topics.items():
            self.node.create_subscription(kind, topic, lambda msg, topic=topic: self.latest.__setitem__(topic, msg),
                                          QoSProfile(depth=10))
        self.node.create_subscription(PoseStamped, "/ground_truth/object_in_arm1", self.truth.append, 100)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._diagnostics, 50)
        self.bad_images = self.node.create_publisher(Image, "/bad/arm2/camera/image_raw", 10)
        self.reset_client = self.node.create_client(ResetScene, "/sim/reset")

    def _diagnostics(self, msg) -> None:
        for status in msg.status:
            self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}

    def reset(self, **fields):
        return self.call(self.reset_client, self.ResetScene.Request(**fields))


def stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def transform(pose) -> np.ndarray:
    p, q = pose.position, pose.orientation
    return homogeneous([p.x, p.y, p.z], [q.x, q.y, q.z, q.w])


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    processes = Processes(tmp_path_factory.mktemp("perception-cell"))
    sim = processes.start_logged("sim_bridge", [DMG, "run", "dmg_sim_bridge", "sim_bridge_node"])
    perception = processes.start_logged("perception", [DMG, "run", "dmg_perception", "perception_node", "--ros-args",
                                                       "-p", "use_sim_time:=true", "-p", "debug_image:=true"])
    bad = processes.start_logged("perception_bad", [DMG, "run", "dmg_perception", "perception_node",
                                                    "--ros-args", "-r", "__ns:=/bad"])
    watcher = Watcher()
    try:
        watcher.wait_for(lambda: watcher.latest.get("/perception/object_pose"), timeout=60, what="a first object pose")
        yield watcher, {"sim": sim, "perception": perception, "bad": bad}
    finally:
        watcher.close()
        processes.stop_all()


@pytest.mark.sim
def test_object_pose_in_the_gripper_matches_ground_truth(cell):
    watcher, _ = cell
    pose = watcher.wait_for(lambda: watcher.truth and (m := watcher.latest["/perception/object_pose"]) and
                            stamp(watcher.truth[0]) <= stamp(m) <= stamp(watcher.truth[-1]) and m,
                            what="a pose with ground truth around its stamp")
    truth = min(watcher.truth, key=lambda m: abs(stamp(m) - stamp(pose)))
    assert abs(stamp(truth) - stamp(pose)) <= 0.006
    assert pose.header.frame_id == "arm1_gripper"
    moved, turned = distance(transform(pose.pose.pose), transform(truth.pose))
    assert moved < 0.0015 and np.rad2deg(turned) < 1.0
    covariance = np.array(pose.pose.covariance).reshape(6, 6)
    assert np.all(np.linalg.eigvalsh((covariance + covariance.T) / 2) > 0)
    status = watcher.wait_for(lambda: (s := watcher.latest.get("/perception/status")) and s.state == s.TRACKING and s,
                              what="TRACKING status")
    assert status.object_id == "box" and status.tags_used == 2 and status.reprojection_error < 0.5
    # Its own topic: the first detections message may arrive after the status that says TRACKING.
    detections = watcher.wait_for(lambda: watcher.latest.get("/perception/detections"), what="detections").detections
    assert {(d.id, d.used, d.known) for d in detections} == {(0, True, True), (1, True, True)}
    debug = watcher.wait_for(lambda: watcher.latest.get("/perception/debug_image"), what="debug image")
    assert (debug.width, debug.height, debug.encoding) == (640, 480, "rgb8")


@pytest.mark.sim
def test_no_tag_in_view_turns_to_lost_within_the_timeout_and_back(cell):
    watcher, _ = cell
    from geometry_msgs.msg import Pose

    quarter = Pose()   # the box's default grasp turned a quarter about the grasp axis: tags along the fingers
    x, y, z, w = (Rotation.from_euler("x", 90, degrees=True) * Rotation.from_matrix(
        [[0, 1, 0], [0, 0, 1], [1, 0, 0]])).as_quat()
    quarter.orientation.x, quarter.orientation.y, quarter.orientation.z, quarter.orientation.w = x, y, z, w
    assert watcher.reset(object_id="box", use_pose=True, object_in_gripper=quarter).success
    began = time.monotonic()
    status = watcher.wait_for(lambda: (s := watcher.latest["/perception/status"]).state == s.LOST and s,
                              timeout=10, what="LOST")
    assert time.monotonic() - began < 3.0          # lost_timeout 0.5 s of sim time (+ the reset's settle)
    assert "object lost" in status.message and status.seconds_since_seen > 0.5
    assert watcher.reset(object_id="box").success
    watcher.wait_for(lambda: (s := watcher.latest["/perception/status"]).state == s.TRACKING, timeout=10,
                     what=f"TRACKING again ({watcher.latest['/perception/status']})")


@pytest.mark.sim
def test_corrupted_or_unsupported_images_are_logged_and_the_node_carries_on(cell):
    watcher, processes = cell
    name = "/bad/perception: object tracking"
    watcher.wait_for(lambda: watcher.bad_images.get_subscription_count() > 0, timeout=10, what="/bad subscribed")

    def counted() -> bool:
        """Send both bad images (again: the node's sensor-QoS subscription may lose one) and look."""
        for encoding, data in (("yuv422", bytes(640 * 480 * 2)), ("rgb8", bytes(1000))):
            image = watcher.Image(width=640, height=480, encoding=encoding,
                                  step=640 * (2 if encoding == "yuv422" else 3), data=data)
            watcher.bad_images.publish(image)
            watcher.spin(0.3)
        return int(watcher.diagnostics.get(name, {}).get("bad_images", 0)) >= 2

    watcher.wait_for(counted, timeout=20, what="two bad images counted")
    status = watcher.wait_for(lambda: watcher.latest.get("/bad/perception/status"), what="status of /bad")
    assert status.state == status.NO_CAMERA
    assert processes["bad"].poll() is None and processes["perception"].poll() is None


def test_a_broken_object_file_is_left_out_unless_asked_for_by_name(tmp_path, processes):
    """objects: ['*'] takes every object under config/objects: one with a broken object.yaml is logged
    and left out, the node runs on; asked for by name, the node cannot start and says why."""
    import os
    import shutil

    config = tmp_path / "config"
    shutil.copytree(REPO / "config", config)
    (config / "objects" / "zz_broken").mkdir()
    (config / "objects" / "zz_broken" / "object.yaml").write_text("mesh: mesh.stl\nmass: 0.1\n")
    environment = {**os.environ, "DMG_CONFIG_DIR": str(config), "RCUTILS_LOGGING_BUFFERED_STREAM": "0"}
    named = processes.start([DMG, "run", "dmg_perception", "perception_node", "--ros-args", "-r", "__ns:=/named",
                             "-p", "object:=zz_broken"], env=environment)   # beside the other: it stops on its own
    log = tmp_path / "perception_all.log"
    with log.open("w") as sink:
        node = processes.start([DMG, "run", "dmg_perception", "perception_node", "--ros-args", "-r", "__ns:=/all"],
                               stdout=sink, stderr=subprocess.STDOUT, env=environment)
    watcher = RosTestNode("broken_object_watcher")
    try:
        from dmg_interfaces.msg import PerceptionStatus

        statuses = []
        watcher.node.create_subscription(PerceptionStatus, "/all/perception/status", statuses.append, 10)
        watcher.wait_for(lambda: statuses, timeout=30, what="the perception status")
    finally:
        watcher.close()
    assert node.poll() is None
    deadline = time.monotonic() + 15.0          # the node's log reaches the file when its stream flushes
    while "missing field 'seed_resolution'" not in log.read_text() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert "object 'zz_broken'" in log.read_text() and "missing field 'seed_resolution'" in log.read_text()
    _, named_err = named.communicate(timeout=60)
    assert named.returncode == 1
    assert "cannot start: object 'zz_broken'" in named_err and "missing field 'seed_resolution'" in named_err
