"""A Baxter-like arm as MJCF, from config/robot/baxter.yaml (the public URDF's kinematics).

Each URDF joint becomes a MuJoCo body at the joint's origin (xyz, then fixed-axis
roll-pitch-yaw, as URDF defines it) with a hinge about its local z, the URDF limits as
range, and the child link's mass. Links are drawn as capsules between consecutive joint
origins. The hand carries sites for the endpoint (the URDF's `<side>_gripper` frame) and the
hand camera.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from dmg_common.config import config_dir
from dmg_sim_bridge.mjcf import vector

LINK_RADIUS = 0.045   # capsule radius of the drawn links [m]
# Joint ranges are written in radians: the model that holds the arm needs this compiler setting.
COMPILER = '<compiler angle="radian"/>'


@dataclass
class Frame:
    xyz: np.ndarray
    rpy: np.ndarray

    @property
    def quaternion_wxyz(self) -> np.ndarray:
        x, y, z, w = Rotation.from_euler("xyz", self.rpy).as_quat()
        return np.array([w, x, y, z])

    def matrix(self) -> np.ndarray:
        transform = np.eye(4)
        transform[:3, :3] = Rotation.from_euler("xyz", self.rpy).as_matrix()
        transform[:3, 3] = self.xyz
        return transform


def load_robot(path: Path | None = None) -> dict:
    return yaml.safe_load((path or config_dir() / "robot" / "baxter.yaml").read_text())


def frame(entry: dict) -> Frame:
    return Frame(np.asarray(entry["xyz"], float), np.asarray(entry["rpy"], float))



def arm_mjcf(side: str, robot: dict, body_attributes: str = "", joint_attributes: str = "",
             hand_children: str = "") -> str:
    """The body tree of one arm (to place inside the torso body), joints named <side>_<joint>.

    `body_attributes` / `joint_attributes` are extra MJCF attribute text for every link body /
    joint (the cell adds gravity compensation and armature); `hand_children` goes inside the
    hand body (the gripper, the camera). The enclosing model must declare COMPILER (radian angles)."""
    mount = frame(robot["arm_mounts"][side])
    closing = []
    xml = [f'<body name="{side}_arm_mount" pos="{vector(mount.xyz)}" quat="{vector(mount.quaternion_wxyz)}">']
    joints = robot["joints"]
    for index, joint in enumerate(joints):
        origin = frame(joint)
        following = frame(joints[index + 1]).xyz if index + 1 < len(joints) else frame(robot["hand"]).xyz
        inertia = 0.4 * joint["mass"] * LINK_RADIUS**2
        xml.append(f'<body name="{side}_{joint["name"]}_link" pos="{vector(origin.xyz)}" '
                   f'quat="{vector(origin.quaternion_wxyz)}" {body_attributes}>'
                   f'<joint name="{side}_{joint["name"]}" axis="0 0 1" range="{joint["lower"]} {joint["upper"]}" '
                   f'actuatorfrcrange="{-joint["effort"]} {joint["effort"]}" damping="{robot["joint_damping"]}" '
                   f'{joint_attributes}/>'
                   f'<inertial pos="0 0 0" mass="{joint["mass"]}" diaginertia="{inertia} {inertia} {inertia}"/>'
                   f'<geom type="capsule" fromto="0 0 0 {vector(following)}" size="{LINK_RADIUS}" '
                   f'rgba="0.6 0.1 0.1 1" contype="0" conaffinity="0" group="2"/>')
        closing.append("</body>")
    hand = frame(robot["hand"])
    endpoint = frame(robot["gripper_base"]).matrix() @ frame(robot["endpoint"]).matrix()   # in the hand frame
    camera = frame(robot["hand_camera"])
    xml.append(f'<body name="{side}_hand" pos="{vector(hand.xyz)}" quat="{vector(hand.quaternion_wxyz)}" '
               f'{body_attributes}>'
               f'<inertial pos="0 0 0" mass="{robot["hand"]["mass"]}" diaginertia="1e-4 1e-4 1e-4"/>'
               f'<site name="{side}_endpoint" pos="{vector(endpoint[:3, 3])}" '
               f'quat="{vector(Frame(np.zeros(3), Rotation.from_matrix(endpoint[:3, :3]).as_euler("xyz")).quaternion_wxyz)}"/>'
               f'<site name="{side}_hand_camera" pos="{vector(camera.xyz)}" quat="{vector(camera.quaternion_wxyz)}"/>'
               f'{hand_children}</body>')
    return "".join(xml) + "".join(closing) + "</body>"
