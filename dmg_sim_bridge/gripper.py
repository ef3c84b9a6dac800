"""A parallel-jaw gripper with hemispherical fingertips, as MJCF (paper: Baxter's gripper with
round tips). Each finger slides along the grasp axis (gripper x), finger 0 on -x and finger 1
on +x; joint value = that finger's distance from the centre. Force-limited position
actuators close them: commanding a half-opening smaller than the object squeezes it with the
force limit. An equality keeps the fingers symmetric, like Baxter's single-motor gripper, so
a held object stays centred on the grasp frame instead of drifting with both fingers.
"""
from __future__ import annotations

from dataclasses import dataclass

from dmg_common.gripper import GripperDescription


@dataclass(frozen=True)
class GripperSpec:
    geometry: GripperDescription      # config/gripper.yaml: fingers, tips, opening (shared with planner and executor)
    kp: float = 20000.0               # position gain [N/m]
    max_force: float = 15.0           # default force limit per finger [N]
    force_limit: float = 40.0         # largest force a command may ask for [N]
    finger_mass: float = 0.05         # [kg]
    friction: tuple[float, float, float] = (0.8, 0.01, 0.0005)   # sliding, torsional, rolling
    solref_timeconst: float = 0.004   # contact stiffness time constant [s] (>= 2 physics steps)

    def joint_target(self, opening: float) -> float:
        """Finger joint value that puts the tips' inner surfaces `opening` apart."""
        return opening / 2 + self.geometry.tip_radius


@dataclass(frozen=True)
class GripperXml:
    bodies: str      # goes inside the body the gripper is mounted on
    actuators: str
    equality: str


def gripper_mjcf(prefix: str, spec: GripperSpec, body_attributes: str = "") -> GripperXml:
    """The gripper's MJCF; its grasp frame is the site <prefix>_grasp (between the tip centres). Only the tips
    collide: the finger boxes (palm to tip) are for the eye."""
    shape = spec.geometry
    travel = spec.joint_target(shape.max_opening)
    friction = " ".join(str(f) for f in spec.friction)
    bodies = [f'<site name="{prefix}_grasp" pos="0 0 {shape.finger_length}"/>']
    for finger, sign in ((0, -1), (1, 1)):
        bodies.append(
            f'<body name="{prefix}_finger{finger}" {body_attributes}>'
            f'<joint name="{prefix}_finger{finger}" type="slide" axis="{sign} 0 0" range="{shape.tip_radius} {travel}" '
            f'damping="5"/>'
            f'<inertial pos="0 0 {shape.finger_length / 2}" mass="{spec.finger_mass}" diaginertia="1e-5 1e-5 1e-5"/>'
            f'<geom type="box" pos="0 0 {shape.finger_length / 2}" size="{shape.finger_thickness / 2} {shape.finger_width / 2} '
            f'{shape.finger_length / 2 - shape.tip_radius}" '
            f'rgba="0.2 0.2 0.2 1" contype="0" conaffinity="0" group="2"/>'
            f'<geom name="{prefix}_tip{finger}" type="sphere" pos="0 0 {shape.finger_length}" size="{shape.tip_radius}" '
            f'condim="6" friction="{friction}" solref="{spec.solref_timeconst} 1" rgba="0.1 0.1 0.1 1"/>'
            '</body>')
    actuators = "".join(
        f'<position name="{prefix}_finger{finger}" joint="{prefix}_finger{finger}" kp="{spec.kp}" '
        f'ctrlrange="0 {travel}" forcerange="{-spec.max_force} {spec.max_force}"/>' for finger in (0, 1))
    equality = (f'<joint joint1="{prefix}_finger1" joint2="{prefix}_finger0" polycoef="0 1 0 0 0" '
                f'solref="{spec.solref_timeconst} 1"/>')
    return GripperXml("".join(bodies), actuators, equality)
