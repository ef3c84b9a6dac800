"""The simulated dual-arm cell, ROS-free: physics, arm velocity control, grippers, camera.

Arm 1 holds the object, arm 2 pushes it and carries the wrist camera. Every pose is in the
base (torso) frame; a gripper's frame is its grasp site (x = grasp axis finger 0 -> finger 1,
z along the fingers, origin between the fingertip centres). A velocity command is a twist of
that frame, resolved to joint velocities with damped least squares on MuJoCo's site Jacobian;
a joint at a limit does not move further into it, and speeds are scaled to the joints' limits.
Commands expire after the watchdog time: the arm then holds its position.

All calls must come from one thread (the EGL renderer is bound to the thread that made it).
"""
from __future__ import annotations

import copy
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import distance, from_rotation, invert
from dmg_planner.objects import ObjectModel, load_object, object_names
from dmg_sim_bridge.robot_model import load_robot
from dmg_sim_bridge.scene import OBJECT_BODY, camera_name, cell_mjcf
from dmg_sim_bridge.sim_config import ARM_ROLES, SimConfig, load_sim_config

IK_ITERATIONS = 300
IK_TOLERANCE = (1e-4, 1e-3)   # m, rad
IK_WRIST_SEEDS = (0.0, np.pi / 2, -np.pi / 2)   # last-joint offsets tried from ik_seed: the IK can end on a limit
IK_STEP = (0.05, 0.2)         # largest task-space step per iteration: m, rad
IK_CENTRING_GAIN = 0.1        # share of the distance to mid-range moved per iteration, in the null space
NULLSPACE_RCOND = 1e-6    # singular values below this share of the largest count as zero (as pinv's rcond)
OPTICAL_FROM_MUJOCO = Rotation.from_euler("x", np.pi).as_matrix()
OPENING_SLACK = 1e-3     # m: a gripper command this far beyond the fingers' travel is taken as its end


class CellError(ValueError):
    """A request the cell cannot carry out; the message says why. The cell is unchanged."""


@dataclass
class Arm:
    role: str
    side: str
    qpos: np.ndarray              # qpos addresses of the 7 joints
    dofs: np.ndarray              # dof addresses
    actuators: np.ndarray         # intvelocity actuator ids
    activations: np.ndarray       # their activation addresses (the integrated joint references)
    lower: np.ndarray
    upper: np.ndarray
    max_velocity: np.ndarray
    site: int                     # grasp site id
    finger_qpos: np.ndarray
    finger_actuators: np.ndarray
    posture: np.ndarray | None = None   # home joint angles, kept in the task's null space
    twist: np.ndarray = field(default_factory=lambda: np.zeros(6))
    command_time: float = -math.inf


@dataclass
class ResetResult:
    object_in_gripper: np.ndarray   # 4x4, where the object settled in gripper 1's frame
    opening: float                  # m between gripper 1's fingertips


@dataclass
class GripperStatus:
    opening: float          # m between the fingertips' inner surfaces
    target_opening: float   # m, last commanded
    max_force: float        # N per finger, in effect
    force: float            # N per finger, applied now


@dataclass
class JointState:
    names: list[str]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


def _finite(values, what: str) -> np.ndarray:
    array = np.asarray(values, float)
    if not np.all(np.isfinite(array)):
        raise CellError(f"{what} has non-finite values: {array.tolist()}")
    return array


def damped_least_squares(jacobian: np.ndarray, twist: np.ndarray, damping: float,
                         threshold: float) -> np.ndarray:
    """Joint velocities for `twist`: exact pseudo-inverse away from singularities, damped near them.

    Damping grows from 0 as the smallest singular value falls below `threshold` (Maciejewski &
    Klein), so tracking is exact in the workspace and joint speeds stay bounded at its edges.
    """
    return _damped_solve(np.linalg.svd(jacobian, full_matrices=False), twist, damping, threshold)


def _damped_solve(svd, twist: np.ndarray, damping: float, threshold: float) -> np.ndarray:
    """damped_least_squares from a Jacobian's thin SVD (u, singular values, vt)."""
    u, singular, vt = svd
    smallest = singular[-1]
    lam2 = damping**2 * (1 - (smallest / threshold) ** 2) if smallest < threshold else 0.0
    return vt.T @ ((singular / (singular**2 + lam2)) * (u.T @ twist))


class Cell:
    def __init__(self, config: SimConfig | None = None, robot: dict | None = None):
        self.config = config or load_sim_config()
        self.robot = robot or load_robot()
        self._renderer: mujoco.Renderer | None = None
        # The wrist camera sees what a real one would: no frame markers. (MuJoCo draws sites by default; a
        # grasp site's 5 mm ball poked through an 8 mm plate beside its tag and pulled the tag's pose 5 deg.)
        self._camera_sees = mujoco.MjvOption()
        self._camera_sees.sitegroup[:] = 0
        self._models: dict[str, mujoco.MjModel] = {}
        self.object: ObjectModel | None = None
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self.arms: dict[str, Arm] = {}
        self._jacobian = None
        # Rows of a twist and its Jacobian: motion weighs position_weight more than turning (see joint_velocities).
        self._task_weights = np.repeat([self.config.control.position_weight, 1.0], 3)
        self._solutions: dict[tuple[str, bytes], np.ndarray] = {}   # IK results; the arms are the same in every model

    # --- building -------------------------------------------------------------------------
    def _model_for(self, name: str) -> tuple[ObjectModel, mujoco.MjModel]:
        try:
            model = load_object(name)
        except KeyError as error:
            raise CellError(str(error.args[0])) from None
        if name not in self._models:
            # The tag textures are files only until the model is compiled: it keeps their pixels.
            with tempfile.TemporaryDirectory(prefix="dmg_sim_") as textures:
                xml = cell_mjcf(self.config, self.robot, model, Path(textures))
                self._models[name] = mujoco.MjModel.from_xml_string(xml)
        return model, self._models[name]

    def _bind(self, object_model: ObjectModel, model: mujoco.MjModel) -> None:
        if self._renderer is not None and self.model is not model:
            self._renderer.close()
            self._renderer = None
        self.object, self.model, self.data = object_model, model, mujoco.MjData(model)
        self.arms = {}
        for role in ARM_ROLES:
            side = self.config.arms[role]
            joints = [model.joint(f"{side}_{j['name']}") for j in self.robot["joints"]]
            actuators = np.array([model.actuator(f"{role}_{j['name']}").id for j in self.robot["joints"]])
            fingers = [model.joint(f"{role}_finger{k}") for k in (0, 1)]
            self.arms[role] = Arm(
                role=role, side=side,
                qpos=np.array([j.qposadr[0] for j in joints]), dofs=np.array([j.dofadr[0] for j in joints]),
                actuators=actuators, activations=model.actuator_actadr[actuators],
                lower=np.array([j.range[0] for j in joints]), upper=np.array([j.range[1] for j in joints]),
                max_velocity=np.array([j["velocity"] for j in self.robot["joints"]], float),
                site=model.site(f"{role}_grasp").id,
                finger_qpos=np.array([f.qposadr[0] for f in fingers]),
                finger_actuators=np.array([model.actuator(f"{role}_finger{k}").id for k in (0, 1)]))
        self._object_geoms = [g for g in range(model.ngeom)
                              if model.geom_bodyid[g] == model.body(OBJECT_BODY).id and model.geom_contype[g]]
        self._object_qpos = model.joint(f"{OBJECT_BODY}_free").qposadr[0]
        self._jacobian = np.zeros((6, model.nv))
        names = [name for arm in self.arms.values() for name in
                 [f"{arm.side}_{j['name']}" for j in self.robot["joints"]] + [f"{arm.role}_finger{k}" for k in (0, 1)]]
        self._joint_layout = (names, np.array([model.joint(n).qposadr[0] for n in names]),
                              np.array([model.joint(n).dofadr[0] for n in names]))

    # --- state queries --------------------------------------------------------------------
    @property
    def time(self) -> float:
        return float(self.data.time)

    def grasp_pose(self, role: str) -> np.ndarray:
        """Gripper `role`'s grasp frame in the base frame (4x4)."""
        site = self.data.site(self.arms[role].site)
        return from_rotation(site.xmat.reshape(3, 3), site.xpos)

    def object_pose(self) -> np.ndarray:
        body = self.data.body(OBJECT_BODY)
        return from_rotation(body.xmat.reshape(3, 3), body.xpos)

    def object_in_gripper(self, role: str) -> np.ndarray:
        """Ground truth: the object frame in gripper `role`'s frame (for evaluation only)."""
        return invert(self.grasp_pose(role)) @ self.object_pose()

    def camera_pose(self) -> np.ndarray:
        """The wrist camera's optical frame (z forward, x right, y down) in the base frame."""
        camera = self.data.camera(camera_name(self.config.camera.arm))
        return from_rotation(camera.xmat.reshape(3, 3) @ OPTICAL_FROM_MUJOCO, camera.xpos)

    def opening(self, role: str) -> float:
        """Distance between the fingertips' inner surfaces [m]."""
        return float(np.sum(self.data.qpos[self.arms[role].finger_qpos]) - 2 * self.config.gripper.geometry.tip_radius)

    def gripper_status(self, role: str) -> GripperStatus:
        arm = self._arm(role)
        spec = self.config.gripper
        target = float(np.mean(self.data.ctrl[arm.finger_actuators]))
        return GripperStatus(self.opening(role), 2 * (target - spec.geometry.tip_radius),
                             float(self.model.actuator_forcerange[arm.finger_actuators[0], 1]),
                             float(np.mean(np.abs(self.data.actuator_force[arm.finger_actuators]))))

    def joint_state(self) -> JointState:
        names, qpos, dofs = self._joint_layout
        return JointState(names, self.data.qpos[qpos].copy(), self.data.qvel[dofs].copy(),
                          self.data.qfrc_actuator[dofs].copy())

    # --- commands -------------------------------------------------------------------------
    def command_twist(self, role: str, linear, angular) -> np.ndarray:
        """Velocity of gripper `role`'s frame in the base frame, until the watchdog expires.

        Faster commands are scaled down to the configured speed limits, direction kept;
        returns the twist that will be applied.
        """
        arm = self._arm(role)
        linear, angular = _finite(linear, "linear velocity"), _finite(angular, "angular velocity")
        control = self.config.control
        scale = min(1.0, control.max_linear_speed / max(np.linalg.norm(linear), 1e-12),
                    control.max_angular_speed / max(np.linalg.norm(angular), 1e-12))
        arm.twist = np.concatenate([linear, angular]) * scale
        arm.command_time = self.time
        return arm.twist.copy()

    def command_gripper(self, role: str, opening: float, max_force: float = 0.0) -> None:
        """Move gripper `role`'s fingers towards `opening` [m], pushing with at most `max_force` N each."""
        arm = self._arm(role)
        spec = self.config.gripper
        opening, max_force = (float(v) for v in _finite([opening, max_force], "gripper command"))
        # A hair beyond the travel is the travel's end: an opening measured past it (fingers pressed apart
        # against their stop) and sent back as the command is no fault (sim: 0.1200x m, the object pushed out).
        if not -OPENING_SLACK <= opening <= spec.geometry.max_opening + OPENING_SLACK:
            raise CellError(f"opening {opening:.4f} m is outside [0, {spec.geometry.max_opening}] m")
        opening = float(np.clip(opening, 0.0, spec.geometry.max_opening))
        if not 0.0 <= max_force <= spec.force_limit:
            raise CellError(f"max_force {max_force:.2f} N is outside [0, {spec.force_limit}] N (0 = default)")
        force = max_force or spec.max_force
        self.model.actuator_forcerange[arm.finger_actuators] = [-force, force]
        self.data.ctrl[arm.finger_actuators] = spec.joint_target(opening)

    def stop(self, role: str) -> None:
        self._arm(role).command_time = -math.inf

    def _arm(self, role: str) -> Arm:
        if role not in self.arms:
            raise CellError(f"unknown arm {role!r}: the cell has {', '.join(ARM_ROLES)}")
        return self.arms[role]

    # --- stepping -------------------------------------------------------------------------
    def joint_velocities(self, arm: Arm, twist: np.ndarray) -> np.ndarray:
        """Joint velocities realising `twist` at the grasp site, within joint position and speed limits
        (where they cannot, the grasp site's motion weighs `position_weight` more than its turning:
        the fingertips stay on their path); the redundant joint moves, unseen by the task, back
        towards the home posture."""
        control = self.config.control
        jacobian = self._jacobian
        mujoco.mj_jacSite(self.model, self.data, jacobian[:3], jacobian[3:], arm.site)
        weights = self._task_weights
        columns, twist = weights[:, None] * jacobian[:, arm.dofs], weights * twist
        reference = self.data.act[arm.activations]
        free = np.ones(len(arm.dofs), bool)
        for _ in range(len(arm.dofs)):
            velocity = np.zeros(len(arm.dofs))
            svd = np.linalg.svd(columns[:, free], full_matrices=False)   # one SVD for the task and its null space
            velocity[free] = _damped_solve(svd, twist, control.dls_damping, control.singular_threshold)
            if arm.posture is not None:
                rows = svd[2][svd[1] > NULLSPACE_RCOND * svd[1][0]]
                nullspace = np.eye(rows.shape[1]) - rows.T @ rows
                velocity[free] += control.posture_gain * nullspace @ (arm.posture - reference)[free]
            blocked = ((reference <= arm.lower + control.joint_limit_margin) & (velocity < 0)) | (
                (reference >= arm.upper - control.joint_limit_margin) & (velocity > 0))
            if not np.any(blocked & free):
                break
            free &= ~blocked
        return velocity / max(1.0, float(np.max(np.abs(velocity) / arm.max_velocity)))

    def step(self, count: int = 1) -> None:
        watchdog = self.config.control.watchdog
        for _ in range(count):
            moving = [arm for arm in self.arms.values()
                      if self.time - arm.command_time <= watchdog and np.any(arm.twist)]
            if moving:   # Jacobians need the kinematics of the current state; a still cell skips them
                mujoco.mj_kinematics(self.model, self.data)
                mujoco.mj_comPos(self.model, self.data)
            for arm in self.arms.values():
                self.data.ctrl[arm.actuators] = self.joint_velocities(arm, arm.twist) if arm in moving else 0.0
            mujoco.mj_step(self.model, self.data)

    def run(self, seconds: float) -> None:
        self.step(int(round(seconds / self.model.opt.timestep)))

    # --- reset ----------------------------------------------------------------------------
    def solve_arm(self, role: str, target: np.ndarray) -> np.ndarray:
        """Joint angles putting gripper `role`'s frame at `target`: of the solutions from a few
        seeds around ik_seed, each also with the wrist flipped (w0 half a turn on, w1 mirrored),
        those leaving the wrist roll `wrist_roll_room` to either side first, then the one
        farthest from any joint limit."""
        arm = self.arms[role]
        key = (role, target.tobytes())
        if key in self._solutions:
            return self._solutions[key]
        solutions, failure = [], None
        for offset in IK_WRIST_SEEDS:
            for flipped in (False, True):
                seed = self.config.ik_seed.copy()
                seed[-1] += offset
                if flipped:
                    seed[4], seed[5] = seed[4] + np.pi, -seed[5]
                try:
                    solutions.append(self._inverse_kinematics(arm, target, seed))
                except CellError as error:
                    failure = error
        if not solutions:
            raise failure

        def preference(q: np.ndarray) -> tuple[bool, float]:
            margins = np.minimum(q - arm.lower, arm.upper - q)
            return bool(margins[-1] >= self.config.wrist_roll_room[role]), float(margins.min())

        self._solutions[key] = max(solutions, key=preference)
        return self._solutions[key]

    def _inverse_kinematics(self, arm: Arm, target: np.ndarray, seed: np.ndarray) -> np.ndarray:
        """Damped least squares iterations; the redundancy moves joints towards mid-range."""
        control = self.config.control
        middle = (arm.lower + arm.upper) / 2
        q = np.clip(seed, arm.lower, arm.upper)
        for iteration in range(2 * IK_ITERATIONS):   # the second half only polishes the pose
            self.data.qpos[arm.qpos] = q
            mujoco.mj_kinematics(self.model, self.data)
            mujoco.mj_comPos(self.model, self.data)
            pose = self.grasp_pose(arm.role)
            error = np.concatenate([target[:3, 3] - pose[:3, 3],
                                    Rotation.from_matrix(target[:3, :3] @ pose[:3, :3].T).as_rotvec()])
            mujoco.mj_jacSite(self.model, self.data, self._jacobian[:3], self._jacobian[3:], arm.site)
            jacobian = self._jacobian[:, arm.dofs]
            nullspace = np.eye(len(q)) - np.linalg.pinv(jacobian) @ jacobian
            centring = IK_CENTRING_GAIN * nullspace @ (middle - q) if iteration < IK_ITERATIONS else 0 * q
            if (np.linalg.norm(error[:3]) < IK_TOLERANCE[0] and np.linalg.norm(error[3:]) < IK_TOLERANCE[1]
                    and np.linalg.norm(centring) < IK_TOLERANCE[1]):
                return q
            # Small steps: the linearisation holds only near the current angles.
            error *= min(1.0, IK_STEP[0] / max(np.linalg.norm(error[:3]), 1e-12),
                         IK_STEP[1] / max(np.linalg.norm(error[3:]), 1e-12))
            step = damped_least_squares(jacobian, error, control.dls_damping, control.singular_threshold)
            q = np.clip(q + step + centring, arm.lower, arm.upper)
        raise CellError(f"{arm.role} cannot reach its home pose {np.round(target[:3, 3], 3).tolist()} "
                        f"(remaining error {np.linalg.norm(error[:3]) * 1000:.1f} mm, "
                        f"{np.rad2deg(np.linalg.norm(error[3:])):.1f} deg)")

    def _surface_along_grasp_axis(self, grasp: np.ndarray) -> tuple[float, float]:
        """Distances from the grasp origin to the object's surface along -x and +x, seen from outside."""
        reach = self.config.gripper.geometry.max_opening
        found = []
        for sign in (-1.0, 1.0):
            axis = sign * grasp[:3, 0]
            start = grasp[:3, 3] + reach * axis
            hits = [mujoco.mju_rayGeom(self.data.geom_xpos[g], self.data.geom_xmat[g], self.model.geom_size[g],
                                       start, -axis, self.model.geom_type[g]) for g in self._object_geoms]
            hits = [h for h in hits if h >= 0]
            if not hits:
                raise CellError("the object has no surface on gripper 1's grasp axis at that pose: "
                                "the fingers would close on nothing")
            found.append(reach - min(hits))
        return found[0], found[1]

    def reset(self, object_name: str = "", object_in_gripper: np.ndarray | None = None,
              grip_force: float = 0.0, restart_clock: bool = False) -> ResetResult:
        """Arms to their home poses, the object held by gripper 1 at `object_in_gripper` (4x4).

        An empty `object_name` = `default_object()`; `object_in_gripper` None = the object's
        default grasp. The gripper is symmetric, so the object is centred
        between the fingers along the grasp axis. On failure the previous scene is kept.
        Simulated time goes on from where it was (a clock behind ROS never runs backwards)
        unless `restart_clock`: then it starts at 0, and what follows does not depend on what
        ran before (the clock's offset alone changes floating-point sums and which control tick
        a camera frame falls on, and a push's outcome with them).
        """
        spec = self.config.gripper
        grip_force = float(_finite(grip_force, "grip force"))
        if not 0.0 <= grip_force <= spec.force_limit:
            raise CellError(f"grip force {grip_force:.2f} N is outside [0, {spec.force_limit}] N (0 = default)")
        if object_in_gripper is not None:
            object_in_gripper = _finite(object_in_gripper, "object pose")
        previous = (self.object, self.model, copy.copy(self.data)) if self.data is not None else None
        try:
            object_model, model = self._model_for(object_name or self.default_object())
            self._bind(object_model, model)
            self.data.time = previous[2].time if previous and not restart_clock else 0.0
            return self._place(object_in_gripper, grip_force or spec.max_force)
        except CellError:
            if previous is not None:
                self._bind(previous[0], previous[1])
                self.data = previous[2]
            raise

    def default_object(self) -> str:
        """The object a reset without a name holds: config/sim.yaml's `object` when the objects
        folder has it, else the folder's first (a folder of one's own objects, DMG_OBJECTS_DIR)."""
        names = object_names()
        return self.config.object if self.config.object in names or not names else names[0]

    def _place(self, object_in_gripper: np.ndarray | None, grip_force: float) -> ResetResult:
        model, data = self.model, self.data
        for role, arm in self.arms.items():
            q = self.solve_arm(role, self.config.home[role])
            data.qpos[arm.qpos] = q
            data.act[arm.activations] = q
            arm.posture = q.copy()
            self.stop(role)
        mujoco.mj_kinematics(model, data)
        if object_in_gripper is None:
            object_in_gripper = default_grasp(self.object, self.config.gripper.geometry.max_opening)
        grasp = self.grasp_pose("arm1")
        self._set_object(grasp @ object_in_gripper)
        mujoco.mj_kinematics(model, data)
        low, high = self._surface_along_grasp_axis(grasp)
        width = low + high
        if width > self.config.gripper.geometry.max_opening:
            raise CellError(f"the object is {width * 1000:.1f} mm wide along the grasp axis at that pose; "
                            f"the gripper opens {self.config.gripper.geometry.max_opening * 1000:.0f} mm")
        centred = object_in_gripper.copy()
        centred[0, 3] += (low - high) / 2
        self._set_object(grasp @ centred)
        data.qpos[self.arms["arm1"].finger_qpos] = self.config.gripper.joint_target(width)
        data.qpos[self.arms["arm2"].finger_qpos] = self.config.gripper.joint_target(0.0)
        self.command_gripper("arm1", 0.0, grip_force)
        self.command_gripper("arm2", 0.0)
        mujoco.mj_forward(model, data)
        self._check_clear()
        self.run(self.config.settle_time)
        settled = self.object_in_gripper("arm1")
        moved, turned = distance(centred, settled)
        if moved > self.config.settle_position_tolerance or turned > self.config.settle_angle_tolerance:
            raise CellError(f"the object did not stay in gripper 1: it moved {moved * 1000:.1f} mm and "
                            f"{np.rad2deg(turned):.1f} deg while settling (grip {grip_force:.1f} N per finger, "
                            f"object {self.object.mass * 1000:.0f} g)")
        return ResetResult(settled, self.opening("arm1"))

    def _set_object(self, pose: np.ndarray) -> None:
        x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
        self.data.qpos[self._object_qpos:self._object_qpos + 7] = [*pose[:3, 3], w, x, y, z]
        self.data.qvel[:] = 0.0

    def _check_clear(self) -> None:
        """The placed object may touch gripper 1's fingertips only."""
        allowed = {self.model.geom(f"arm1_tip{k}").id for k in (0, 1)}
        for contact in self.data.contact[:self.data.ncon]:
            pair = {int(contact.geom1), int(contact.geom2)}
            if pair & set(self._object_geoms) and not pair & allowed and contact.dist < -1e-4:
                other = (pair - set(self._object_geoms)).pop()
                raise CellError(f"the object at that pose intersects {self.model.geom(other).name or 'geom ' + str(other)}")

    # --- camera ---------------------------------------------------------------------------
    def render(self) -> np.ndarray:
        """The wrist camera's RGB image (height, width, 3) uint8."""
        camera = self.config.camera
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, camera.height, camera.width)
        self._renderer.update_scene(self.data, camera=camera_name(camera.arm), scene_option=self._camera_sees)
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def default_grasp(model: ObjectModel, max_opening: float) -> np.ndarray:
    """Object pose in gripper 1's frame when none is given: the fingers pinch the object's
    largest part at its centre (always solid), across that part's thinnest side that fits the
    gripper and is not the tagged axis; the side most tags face looks along the gripper's +y
    (towards the camera arm in the default cell)."""
    largest = max(model.parts, key=lambda part: float(np.prod(part.size)))
    normals = np.array([Rotation.from_euler("xyz", tag.rpy_deg, degrees=True).as_matrix()[:, 2]
                        for tag in model.apriltags]).reshape(-1, 3)
    counts = np.round(np.abs(normals).sum(axis=0), 6)      # rounded: ties go to the first axis
    axis = int(np.argmax(counts)) if len(normals) else int(np.argmax(largest.size))
    y_axis = np.eye(3)[axis] * (np.sign(np.round(normals[:, axis].sum(), 6)) or 1.0)
    others = sorted((k for k in range(3) if k != axis), key=lambda k: largest.size[k])
    fitting = [k for k in others if largest.size[k] < max_opening] or others
    x_axis = np.eye(3)[fitting[0]]
    rotation = np.column_stack([x_axis, y_axis, np.cross(x_axis, y_axis)])   # gripper axes in the object frame
    return from_rotation(rotation.T, -rotation.T @ largest.center)
