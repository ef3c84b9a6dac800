"""The whole simulated cell as one MJCF document: torso, two Baxter-like arms with grippers,
the wrist camera, a table and the tagged object.

Arm joints are driven by integrated-velocity actuators (the control input is a joint
velocity, the actuator holds the integrated position with a stiff servo), like Baxter's
joint velocity mode; links are gravity compensated, as Baxter's controller does. Only the
fingertips, the table and the object collide: the drawn links are visual.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_planner.objects import ObjectModel
from dmg_sim_bridge.gripper import gripper_mjcf
from dmg_sim_bridge.mjcf import vector
from dmg_sim_bridge.object_model import object_mjcf
from dmg_sim_bridge.robot_model import COMPILER, arm_mjcf, frame
from dmg_sim_bridge.sim_config import ARM_ROLES, SimConfig

OBJECT_BODY = "object"
PIXEL_PITCH = 1e-5   # m; only scales MuJoCo's sensor size, the image depends on pixels alone



def camera_name(role: str) -> str:
    return f"{role}_camera"


def camera_mjcf(config: SimConfig, robot: dict) -> str:
    """The wrist camera at Baxter's hand-camera frame (optical: z forward, x right, y down).

    MuJoCo cameras look along their -z with y up: the optical frame turned half a turn about x.
    """
    camera = config.camera
    optical = frame(robot["hand_camera"])
    x, y, z, w = (Rotation.from_euler("xyz", optical.rpy) * Rotation.from_euler("x", np.pi)).as_quat()
    # MuJoCo's principal-point offset moves the image the opposite way in u (measured).
    offset = ((camera.width - 1) / 2 - camera.cx, camera.cy - (camera.height - 1) / 2)
    return (f'<camera name="{camera_name(camera.arm)}" pos="{vector(optical.xyz)}" quat="{vector([w, x, y, z])}" '
            f'resolution="{camera.width} {camera.height}" focalpixel="{camera.fx} {camera.fy}" '
            f'principalpixel="{vector(offset)}" sensorsize="{camera.width * PIXEL_PITCH} {camera.height * PIXEL_PITCH}"/>')


def cell_mjcf(config: SimConfig, robot: dict, model: ObjectModel, texture_dir: Path) -> str:
    control, spec = config.control, config.gripper
    friction = " ".join(str(f) for f in spec.friction)
    object_assets, object_body = object_mjcf(
        model, texture_dir, body_name=OBJECT_BODY, position=(0.6, 0.0, 0.0),
        geom_defaults=f'condim="6" friction="{friction}" solref="{spec.solref_timeconst} 1"')
    endpoint = frame(robot["gripper_base"]).matrix() @ frame(robot["endpoint"]).matrix()
    arms, actuators, equalities = [], [], []
    for role in ARM_ROLES:
        side = config.arms[role]
        gripper = gripper_mjcf(role, spec, body_attributes='gravcomp="1"')
        children = (f'<body name="{role}_gripper" pos="{vector(endpoint[:3, 3])}" gravcomp="1">'
                    f'{gripper.bodies}</body>')
        if config.camera.arm == role:
            children += camera_mjcf(config, robot)
        arms.append(arm_mjcf(side, robot, body_attributes='gravcomp="1"',
                             joint_attributes=f'armature="{control.armature}"', hand_children=children))
        for joint in robot["joints"]:
            effort = joint["effort"]
            actuators.append(
                f'<intvelocity name="{role}_{joint["name"]}" joint="{side}_{joint["name"]}" '
                f'kp="{control.joint_kp_per_effort * effort}" kv="{control.joint_kv_per_effort * effort}" '
                f'ctrlrange="{-joint["velocity"]} {joint["velocity"]}" actrange="{joint["lower"]} {joint["upper"]}" '
                f'forcerange="{-effort} {effort}"/>')
        actuators.append(gripper.actuators)
        equalities.append(gripper.equality)
    table = config.table
    camera = config.camera
    return (
        f'<mujoco model="dmg_cell">{COMPILER}{config.option_xml()}'
        f'<visual><global offwidth="{camera.width}" offheight="{camera.height}"/>'
        f'<map znear="{camera.near / 10:.9g}" zfar="{camera.far}"/><quality shadowsize="0"/></visual>'
        f'<asset>{object_assets}</asset>'
        '<worldbody>'
        '<light pos="0.6 0 1.5" dir="0 0 -1" directional="true" diffuse="0.6 0.6 0.6"/>'
        '<light pos="1.5 0 0.5" dir="-1 0 -0.3" directional="true" diffuse="0.4 0.4 0.4"/>'
        '<light pos="0 -1.5 0.5" dir="0 1 -0.3" directional="true" diffuse="0.3 0.3 0.3"/>'
        '<light pos="0 1.5 0.5" dir="0 -1 -0.3" directional="true" diffuse="0.3 0.3 0.3"/>'
        f'<geom name="table" type="box" pos="{vector(table["center"])}" size="{vector(np.asarray(table["size"]) / 2)}" '
        'rgba="0.45 0.45 0.5 1"/>'
        '<body name="torso"><geom type="box" pos="-0.05 0 -0.1" size="0.12 0.18 0.3" rgba="0.55 0.1 0.1 1" '
        'contype="0" conaffinity="0" group="2"/>'
        f'{"".join(arms)}</body>{object_body}</worldbody>'
        f'<actuator>{"".join(actuators)}</actuator><equality>{"".join(equalities)}</equality></mujoco>')
