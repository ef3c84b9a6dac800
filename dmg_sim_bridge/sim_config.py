"""config/sim.yaml: the cell's physics, gripper, arms, control and camera, as typed values."""
from __future__ import annotations

from dataclasses import MISSING, dataclass, fields
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from dmg_common.config import config_dir
from dmg_common.gripper import GripperDescription, GripperDescriptionError, load_gripper
from dmg_common.transforms import from_rotation
from dmg_sim_bridge.gripper import GripperSpec

ARM_ROLES = ("arm1", "arm2")


@dataclass(frozen=True)
class ControlSpec:
    dls_damping: float
    singular_threshold: float
    joint_limit_margin: float
    posture_gain: float
    position_weight: float
    max_linear_speed: float
    max_angular_speed: float
    watchdog: float
    joint_kp_per_effort: float
    joint_kv_per_effort: float
    armature: float


@dataclass(frozen=True)
class CameraSpec:
    arm: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    near: float
    far: float

    def intrinsic_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class SimConfig:
    document: dict
    gripper: GripperSpec
    control: ControlSpec
    camera: CameraSpec
    arms: dict[str, str]             # role -> Baxter side
    home: dict[str, np.ndarray]      # role -> 4x4 grasp-frame pose in the base frame
    ik_seed: np.ndarray
    wrist_roll_room: dict[str, float]   # role -> rad
    object: str
    settle_time: float
    settle_position_tolerance: float
    settle_angle_tolerance: float    # rad

    def option_xml(self) -> str:
        physics = self.document["physics"]
        return (f'<option timestep="{physics["timestep"]}" cone="{physics["cone"]}" impratio="{physics["impratio"]}" '
                f'noslip_iterations="{physics["noslip_iterations"]}" integrator="implicitfast"/>')

    @property
    def timestep(self) -> float:
        return float(self.document["physics"]["timestep"])

    @property
    def table(self) -> dict:
        return self.document["table"]


class SimConfigError(ValueError):
    """config/sim.yaml (or a user's copy) cannot describe a cell: the message says which key and why."""


def _pose(entry: dict) -> np.ndarray:
    return from_rotation(Rotation.from_euler("xyz", entry["rpy_deg"], degrees=True).as_matrix(), entry["xyz"])


def _gripper_description() -> GripperDescription:
    try:
        return load_gripper()
    except GripperDescriptionError as error:
        raise SimConfigError(str(error)) from None


def _section(document: dict, name: str, spec: type, path: Path, elsewhere: frozenset[str] = frozenset()) -> dict:
    """Section `name` as keyword arguments of dataclass `spec` (less its fields in `elsewhere`, which come
    from another file): a user's sim.yaml that lacks a key without a default (an older copy) or misspells
    one is told which, not met with a TypeError."""
    entry = document.get(name)
    if not isinstance(entry, dict):
        raise SimConfigError(f"{path}: section '{name}' is missing or not a mapping")
    known = {f.name for f in fields(spec)} - elsewhere
    required = {f.name for f in fields(spec) if f.default is MISSING and f.default_factory is MISSING} - elsewhere
    missing, unknown = sorted(required - entry.keys()), sorted(entry.keys() - known)
    if missing or unknown:
        raise SimConfigError(f"{path}: section '{name}': " + "; ".join(
            f"{label} {', '.join(keys)}" for label, keys in (("missing", missing), ("unknown", unknown)) if keys)
            + " (config/sim.yaml in the repository has them all)")
    return dict(entry)


def load_sim_config(path: Path | None = None) -> SimConfig:
    path = Path(path or config_dir() / "sim.yaml")
    try:
        document = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise SimConfigError(f"{path}: cannot be read: {error}") from None
    if not isinstance(document, dict):
        raise SimConfigError(f"{path}: not a YAML mapping")
    try:
        return _sim_config(document, path)
    except KeyError as missing:
        raise SimConfigError(f"{path}: key {missing} is missing (config/sim.yaml in the repository has them all)") from None


def _sim_config(document: dict, path: Path) -> SimConfig:
    shape = {f.name for f in fields(GripperDescription)} & set(document.get("gripper") or {})
    if shape:
        raise SimConfigError(f"{path}: section 'gripper': {', '.join(sorted(shape))} belong in config/gripper.yaml, "
                             "the gripper's one description (planner, simulation and executor read it)")
    gripper = _section(document, "gripper", GripperSpec, path, elsewhere=frozenset({"geometry"}))
    if "friction" in gripper:
        gripper["friction"] = tuple(gripper["friction"])
    arms = dict(document["arms"])
    if sorted(arms) != list(ARM_ROLES) or sorted(arms.values()) != ["left", "right"]:
        raise SimConfigError(f"{path}: arms must map arm1 and arm2 to left and right, got {arms}")
    camera = CameraSpec(**_section(document, "camera", CameraSpec, path))
    if camera.arm not in ARM_ROLES:
        raise SimConfigError(f"{path}: camera.arm must be one of {ARM_ROLES}, got {camera.arm!r}")
    tolerance = document["settle_tolerance"]
    return SimConfig(
        document=document, gripper=GripperSpec(geometry=_gripper_description(), **gripper), control=ControlSpec(**_section(document, "control", ControlSpec, path)),
        camera=camera, arms=arms, home={role: _pose(document["home"][role]) for role in ARM_ROLES},
        ik_seed=np.asarray(document["ik_seed"], float), wrist_roll_room={role: float(document["wrist_roll_room"][role]) for role in ARM_ROLES},
        object=str(document["object"]),
        settle_time=float(document["settle_time"]), settle_position_tolerance=float(tolerance["position"]),
        settle_angle_tolerance=float(np.deg2rad(tolerance["angle_deg"])))
