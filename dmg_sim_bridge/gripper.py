"""A parallel-jaw gripper with hemispherical fingertips, as MJCF (paper: Baxter's gripper with
round tips). Each finger slides along the grasp axis (gripper x), finger 0 on -x and finger 1
on +x; joint value = that finger's distance from the centre. Force-limited position
actuators close them: commanding a half-opening smaller than the object squeezes it with the
force limit.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class GripperSpec:
    finger_length: float = 0.075      # palm to fingertip centre [m] (Baxter standard finger)
    tip_radius: float = 0.008         # hemispherical fingertip radius [m]
    max_opening: float = 0.12         # largest distance between the two tips' inner surfaces [m]
    kp: float = 2000.0                # position gain [N/m]
    max_force: float = 15.0           # default force limit per finger [N]
    finger_mass: float = 0.05         # [kg]
    friction: tuple[float, float, float] = (0.8, 0.01, 0.0005)   # sliding, torsional, rolling
    solref_timeconst: float = 0.004   # contact stiffness time constant [s] (>= 2 physics steps)


def gripper_mjcf(prefix: str, spec: GripperSpec = GripperSpec()) -> tuple[str, str]:
    """(body XML to put in the hand body, actuator XML). The grasp frame is the site <prefix>_grasp."""
    travel = spec.max_opening / 2 + spec.tip_radius
    friction = " ".join(str(f) for f in spec.friction)
    bodies = [f'<site name="{prefix}_grasp" pos="0 0 {spec.finger_length}"/>']
    for finger, sign in ((0, -1), (1, 1)):
        bodies.append(
            f'<body name="{prefix}_finger{finger}">'
            f'<joint name="{prefix}_finger{finger}" type="slide" axis="{sign} 0 0" range="{spec.tip_radius} {travel}" '
            f'damping="5"/>'
            f'<inertial pos="0 0 {spec.finger_length / 2}" mass="{spec.finger_mass}" diaginertia="1e-5 1e-5 1e-5"/>'
            f'<geom type="box" pos="0 0 {spec.finger_length / 2}" size="0.005 0.007 {spec.finger_length / 2 - spec.tip_radius}" '
            f'rgba="0.2 0.2 0.2 1" contype="0" conaffinity="0" group="2"/>'
            f'<geom name="{prefix}_tip{finger}" type="sphere" pos="0 0 {spec.finger_length}" size="{spec.tip_radius}" '
            f'condim="6" friction="{friction}" solref="{spec.solref_timeconst} 1" rgba="0.1 0.1 0.1 1"/>'
            '</body>')
    actuators = "".join(
        f'<position name="{prefix}_finger{finger}" joint="{prefix}_finger{finger}" kp="{spec.kp}" '
        f'ctrlrange="0 {travel}" forcerange="{-spec.max_force} {spec.max_force}"/>' for finger in (0, 1))
    return "".join(bodies), actuators
