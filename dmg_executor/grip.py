"""How hard the holding gripper must still squeeze while the object is pushed through it.

Two round fingertips touch the object at two points on the grasp axis, `opening` apart.
Loosened, their friction resists a turn of the object about any axis across the grasp axis
with a couple of at most friction x force x opening; the object's weight, hanging off the grasp
axis, turns it that way with the part of its torque about the grasp's middle across that axis.
Below the force that balances the two the object tilts off the grasp axis as soon as the grip
loosens, a tilt no primitive can take back. The part of the torque about the grasp axis turns
the object in the plane the primitives work in; the fingertips' pads resist it with torsional
friction, at most 2 x torsional friction (a length) x force: a heavy object held well off its
centre of mass swings round under its weight as soon as the grip loosens.
"""
from __future__ import annotations

import math

import numpy as np

GRAVITY = np.array([0.0, 0.0, -9.81])   # m/s^2, base frame (z up)
NARROWEST_GRASP = 1e-3                  # m: below this the couple is taken as this wide


def weight_torque(object_in_holder: np.ndarray, holder_rotation: np.ndarray, centre_of_mass: np.ndarray,
                  mass: float) -> np.ndarray:
    """The weight's torque [N m] about the grasp's middle, in the holder frame (x: the grasp axis);
    poses are the object in the holder's frame and the holder's orientation in the base frame,
    `centre_of_mass` in the object frame."""
    weight = mass * (holder_rotation.T @ GRAVITY)
    return np.cross(object_in_holder[:3, :3] @ centre_of_mass + object_in_holder[:3, 3], weight)


def tilt_hold_force(object_in_holder: np.ndarray, holder_rotation: np.ndarray, centre_of_mass: np.ndarray,
                    mass: float, opening: float, friction: float) -> float:
    """Finger force [N] whose friction couple just holds the object's weight from turning it
    across the grasp axis (x of the holder frame)."""
    torque = weight_torque(object_in_holder, holder_rotation, centre_of_mass, mass)
    return float(np.hypot(torque[1], torque[2])) / (friction * max(opening, NARROWEST_GRASP))


def turn_hold_force(object_in_holder: np.ndarray, holder_rotation: np.ndarray, centre_of_mass: np.ndarray,
                    mass: float, torsional_friction: float) -> float:
    """Finger force [N] whose two pads' torsional friction just holds the object's weight from
    turning it about the grasp axis."""
    torque = weight_torque(object_in_holder, holder_rotation, centre_of_mass, mass)
    return abs(float(torque[0])) / (2.0 * torsional_friction)


def tilt_steering(tilt: np.ndarray, direction: np.ndarray, lever: float, grip_reach: float) -> float:
    """Which way [rad, signed] the pusher should slide along the grasp axis x (holder frame) to turn a
    pushed object's tilt `tilt` (rotation vector) back. Sliding drags the face along x by friction
    F_x at the contact `lever` from the grasp axis; the self-centring grip answers with unequal
    finger forces whose sliding friction adds (mu*h - L)*F_x about d x x in all, mu*h = `grip_reach`.
    While the object slides, nothing else resists a turn about that axis."""
    axis = np.cross(direction, [1.0, 0.0, 0.0])
    return -math.copysign(1.0, grip_reach - lever) * float(tilt @ axis)


def balanced_line(turned: float, torque: float, grip_force: float, friction: float, gain: float,
                  below: float, above: float) -> float:
    """Where [m] across the push line from the grasp axis a translation's push runs: a push force F along
    d at an offset e along d x x turns the object about the grasp axis x with e F. While the loosened grip
    slides, its friction resists no turn about x (limit surface: the object turns (torque / F) (mu / mu_t)^2
    rad per metre pushed), so the line runs where e F cancels the weight's `torque` about x [N m], F taken as
    the two fingers' sliding friction, and `gain` [m/rad] further against the turn `turned` [rad] seen since
    the push began; kept within [-below, above] (where the face is)."""
    balance = -torque / max(2.0 * friction * grip_force, 1e-6)
    return float(np.clip(balance - gain * turned, -below, above))
