"""perception_node: the held object's pose in the gripper frame, from AprilTags on the wrist camera.

Subscribes: arm2/camera/image_raw (sensor_msgs/Image), arm2/camera/camera_info (sensor QoS),
            arm2/camera/pose, arm1/endpoint_pose (geometry_msgs/PoseStamped, base frame)
            (topic names are parameters)
Publishes:  perception/object_pose (geometry_msgs/PoseWithCovarianceStamped, frame arm1_gripper,
            stamped with the image's time), perception/detections (dmg_interfaces/TagDetections),
            perception/status (dmg_interfaces/PerceptionStatus: TRACKING / SEARCHING / LOST /
            NO_CAMERA), perception/debug_image (when debug_image is true), /diagnostics
Parameters: config/perception.yaml.

Images are processed on a worker thread, newest first: a frame that arrives while one is
being processed replaces the waiting one (counted as dropped), so the node never falls
behind the camera. A bad image (wrong encoding, wrong size) is logged and skipped.
"""
from __future__ import annotations

import math
import threading
import time

import cv2
import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from dmg_interfaces.msg import PerceptionStatus, TagDetection, TagDetections
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from dmg_common.ros.geometry_messages import pose_message, seconds, transform_from_pose
from dmg_common.ros.node_main import run_node
from dmg_common.ros.parameters import declare_from_config
from dmg_perception.estimator import EstimationError, EstimatorSettings, ObjectPoseEstimator
from dmg_perception.images import ImageError, grey_image
from dmg_perception.tracker import FrameResult, Tracker, TrackingState
from dmg_planner.objects import ObjectError, load_object, object_names

# Camera and gripper poses, buffered by stamp: best effort, as a reliable reader holds every later pose
# back until a lost one is resent, and an image then finds no pose of its time.
POSES_QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT)
INPUT_WAIT = 0.1   # s (wall) an image waits for the camera and gripper poses of its time stamp (and camera_info)


def main(argv: list[str] | None = None) -> int:
    return run_node("perception_node", __doc__, "example: perception_node --ros-args -p object:=box -p debug_image:=true",
                    argv, PerceptionNode, startup_errors=(EstimationError, KeyError))


class PerceptionNode(Node):
    def __init__(self) -> None:
        super().__init__("perception")
        values = self.values = declare_from_config(self, "perception")
        every = list(values["objects"]) == ["*"]
        named = ([] if every else list(values["objects"])) + ([values["object"]] if values["object"] else [])
        models = []
        for name in dict.fromkeys((object_names() if every else []) + named):
            try:
                models.append(load_object(name))
            except ObjectError as error:
                if name in named:     # asked for by name: the node cannot do its job without it
                    raise
                self.get_logger().error(f"{error}; perception goes on without it")
        estimator = ObjectPoseEstimator(models, EstimatorSettings.from_values(values))
        self.tracker = Tracker(estimator, values["lost_timeout"], values["pose_tolerance"], values["object"])
        self.lock = threading.Lock()            # guards the tracker's buffers and the pending image
        self.pending: Image | None = None
        self.wake = threading.Event()
        self.stopping = threading.Event()
        self.counts = {"processed": 0, "dropped": 0, "bad_images": 0, "poses": 0}
        self.window = (time.monotonic(), 0)
        self.rate = 0.0
        self.last_status_stamp = 0.0

        self.pose_pub = self.create_publisher(PoseWithCovarianceStamped, "perception/object_pose", 10)
        self.detections_pub = self.create_publisher(TagDetections, "perception/detections", 10)
        self.status_pub = self.create_publisher(PerceptionStatus, "perception/status", 10)
        self.debug_pub = self.create_publisher(Image, "perception/debug_image", 2) if values["debug_image"] else None
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(Image, values["image_topic"], self.on_image, qos_profile_sensor_data)
        self.create_subscription(CameraInfo, values["camera_info_topic"], self.on_camera_info, qos_profile_sensor_data)
        self.create_subscription(PoseStamped, values["camera_pose_topic"],
                                 lambda msg: self.on_pose(self.tracker.camera_poses, msg, "camera pose"), POSES_QOS)
        self.create_subscription(PoseStamped, values["gripper_pose_topic"],
                                 lambda msg: self.on_pose(self.tracker.gripper_poses, msg, "gripper pose"), POSES_QOS)
        self.create_timer(1.0 / values["status_rate"], self.publish_idle_status)
        self.create_timer(1.0, self.publish_diagnostics)
        self.worker = threading.Thread(target=self.work, name="perception", daemon=True)
        self.worker.start()
        self.get_logger().info(f"perception up: tag layouts of {', '.join(model.name for model in models)}; tracking "
                               f"{values['object'] or 'whichever object is in view'} on {values['image_topic']}")

    # --- callbacks: store, never process ------------------------------------------------
    def on_image(self, msg: Image) -> None:
        with self.lock:
            if self.pending is not None:
                self.counts["dropped"] += 1
            self.pending = msg
        self.wake.set()

    def on_camera_info(self, msg: CameraInfo) -> None:
        try:
            with self.lock:
                self.tracker.estimator.set_camera(np.asarray(msg.k, float), list(msg.d))
        except EstimationError as error:
            self.get_logger().error(f"camera_info ignored: {error}", throttle_duration_sec=5.0)

    def on_pose(self, buffer, msg: PoseStamped, what: str) -> None:
        try:
            pose = transform_from_pose(msg.pose, what)
        except ValueError as error:
            self.get_logger().error(f"{what} ignored: {error}", throttle_duration_sec=5.0)
            return
        with self.lock:
            buffer.add(seconds(msg.header.stamp), pose)

    # --- the worker ----------------------------------------------------------------------
    def work(self) -> None:
        while not self.stopping.is_set():
            if not self.wake.wait(timeout=0.1):
                continue
            with self.lock:
                msg, self.pending = self.pending, None
                self.wake.clear()
            if msg is None:
                continue
            try:
                self.process(msg)
            except Exception as error:   # noqa: BLE001 - one bad frame must not end tracking
                if self.stopping.is_set() or not self.context.ok():
                    return                # shutting down: publishers are gone
                self.get_logger().error(f"frame failed: {type(error).__name__}: {error}", throttle_duration_sec=2.0)

    def process(self, msg: Image) -> None:
        try:
            grey = grey_image(msg.encoding, msg.width, msg.height, msg.step, msg.data, bool(msg.is_bigendian))
        except ImageError as error:
            self.counts["bad_images"] += 1
            self.get_logger().error(f"image skipped: {error}", throttle_duration_sec=2.0)
            return
        stamp = seconds(msg.header.stamp)
        self.wait_for_inputs(stamp)
        with self.lock:
            result = self.tracker.process(stamp, grey, self.now())
        self.publish_result(msg, result, grey)

    def wait_for_inputs(self, stamp: float) -> None:
        """Poses sent with an image can arrive after it (a busy machine), and so can the first
        camera_info (it is sent after the image): wait for them a little."""
        deadline = time.monotonic() + INPUT_WAIT
        while time.monotonic() < deadline and not self.stopping.is_set():
            with self.lock:
                newest = [buffer.latest_time for buffer in (self.tracker.camera_poses, self.tracker.gripper_poses)]
                calibrated = self.tracker.estimator.intrinsics is not None
            if calibrated and all(t is not None and t >= stamp for t in newest):
                return
            time.sleep(0.005)

    def now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def publish_result(self, image: Image, result: FrameResult, grey: np.ndarray) -> None:
        self.counts["processed"] += 1
        estimate = result.estimate
        if estimate is not None:
            msg = PoseWithCovarianceStamped()
            msg.header.stamp, msg.header.frame_id = image.header.stamp, self.values["gripper_frame"]
            msg.pose.pose = pose_message(estimate.pose)
            msg.pose.covariance = estimate.covariance.ravel().tolist()
            self.pose_pub.publish(msg)
            self.counts["poses"] += 1
        detections = TagDetections(detections=[self._detection(o, estimate) for o in result.observations])
        detections.header = image.header
        self.detections_pub.publish(detections)
        self.publish_status(image.header.stamp)
        if self.debug_pub is not None:
            self.debug_pub.publish(self._debug_image(image, result, grey))

    def _detection(self, observation, estimate) -> TagDetection:
        detection = TagDetection(id=observation.id, corners=observation.corners.ravel().tolist(),
                                 known=observation.camera_from_tag is not None,
                                 used=bool(estimate and observation.id in estimate.tags_used),
                                 reprojection_error=observation.reprojection_error if estimate else math.nan)
        if observation.camera_from_tag is not None:
            detection.pose = pose_message(observation.camera_from_tag)
        return detection

    def _debug_image(self, image: Image, result: FrameResult, grey: np.ndarray) -> Image:
        canvas = cv2.cvtColor(grey, cv2.COLOR_GRAY2RGB)
        if result.observations:
            cv2.aruco.drawDetectedMarkers(canvas, [o.corners.reshape(1, 4, 2).astype(np.float32)
                                                   for o in result.observations],
                                          np.array([[o.id] for o in result.observations]))
        estimator = self.tracker.estimator
        if result.estimate is not None and result.camera_from_frame is not None:
            camera_from_object = result.camera_from_frame @ result.estimate.pose
            rvec = cv2.Rodrigues(camera_from_object[:3, :3])[0]
            cv2.drawFrameAxes(canvas, estimator.intrinsics, estimator.distortion, rvec, camera_from_object[:3, 3], 0.03)
        text = (f"{result.estimate.object_name}: {len(result.estimate.tags_used)} tags, "
                f"{result.estimate.reprojection_error:.2f} px" if result.estimate else result.problem)
        cv2.putText(canvas, text, (10, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 0), 2)
        out = Image(height=canvas.shape[0], width=canvas.shape[1], encoding="rgb8", step=canvas.shape[1] * 3,
                    data=canvas.tobytes())
        out.header = image.header
        return out

    # --- status and diagnostics ------------------------------------------------------------
    def publish_status(self, stamp=None) -> None:
        with self.lock:
            status = self.tracker.status(self.now())
        msg = PerceptionStatus(state=int(status.state), object_id=status.object_name,
                               seconds_since_seen=float(min(status.seconds_since_seen, 1e9)),
                               tags_used=status.tags_used, reprojection_error=float(status.reprojection_error),
                               message=status.message)
        msg.header.stamp = stamp if stamp is not None else self.get_clock().now().to_msg()
        self.status_pub.publish(msg)
        self.last_status_stamp = time.monotonic()
        if status.state == TrackingState.LOST:
            self.get_logger().warning(status.message, throttle_duration_sec=2.0)

    def publish_idle_status(self) -> None:
        """Keep the status coming when images do not (a dead camera must read LOST)."""
        if time.monotonic() - self.last_status_stamp >= 0.9 / self.values["status_rate"]:
            self.publish_status()

    def publish_diagnostics(self) -> None:
        wall, processed = time.monotonic(), self.counts["processed"]
        self.rate = (processed - self.window[1]) / max(wall - self.window[0], 1e-9)
        self.window = (wall, processed)
        with self.lock:
            status = self.tracker.status(self.now())
        level = {TrackingState.TRACKING: DiagnosticStatus.OK, TrackingState.SEARCHING: DiagnosticStatus.OK,
                 TrackingState.LOST: DiagnosticStatus.WARN, TrackingState.NO_CAMERA: DiagnosticStatus.WARN}[status.state]
        diagnostic = DiagnosticStatus(name=f"{self.get_fully_qualified_name()}: object tracking", hardware_id="wrist camera", level=level,
                                      message=status.message or status.state.name.lower())
        values = {"state": status.state.name, "object": status.object_name, "rate_hz": f"{self.rate:.1f}",
                  "tags_used": str(status.tags_used), "reprojection_error_px": f"{status.reprojection_error:.3f}",
                  **{k: str(v) for k, v in self.counts.items()}}
        diagnostic.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray(status=[diagnostic])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(msg)

    def shutdown(self) -> None:
        self.stopping.set()
        self.worker.join(timeout=2.0)

