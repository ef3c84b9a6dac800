"""The parameters of a DMG build: a light module (no open3d) so command lines can list them cheaply."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

import numpy as np

from dmg_common.gripper import gripper_description


def _gripper(name: str):
    """Default from the gripper's one description (config/gripper.yaml)."""
    return field(default_factory=lambda: getattr(gripper_description(), name))


@dataclass(frozen=True)
class GraphParameters:
    """Everything that changes a built graph (and therefore its cache key)."""

    voxel_resolution: float = 0.001
    seed_resolution: float = 0.013
    spatial_importance: float = 0.9
    normal_importance: float = 1.0
    delta: float = 0.07
    angle_step_deg: float = 5.0
    finger_length: float = _gripper("finger_length")         # palm face to fingertip centre (paper's l: 0.1)
    finger_width: float = _gripper("finger_width")           # across the finger, in the tangent plane
    finger_thickness: float = _gripper("finger_thickness")   # along the contact normal
    finger_tip_overhang: float = _gripper("tip_radius")      # the round tip reaches this far past the contact
    palm_width: float = _gripper("palm_width")               # the palm's face across the finger, at its base; 0 = no palm
    max_opening: float = _gripper("max_opening")             # widest grasp; the palm reaches this far across
    ray_spacing: float = 0.005   # largest gap between the rays that sweep the finger's volume

    def validate(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"graph parameter {f.name} = {value}: must be finite and >= 0")
        for name in ("voxel_resolution", "seed_resolution", "angle_step_deg", "ray_spacing"):
            if getattr(self, name) <= 0:
                raise ValueError(f"graph parameter {name} must be > 0")
        if self.seed_resolution < 2 * self.voxel_resolution:
            raise ValueError(f"seed_resolution {self.seed_resolution} must be at least twice "
                             f"voxel_resolution {self.voxel_resolution}")
        steps = 360.0 / self.angle_step_deg
        if abs(steps - round(steps)) > 1e-6:
            raise ValueError(f"angle_step_deg {self.angle_step_deg} must divide 360")

    @property
    def angle_count(self) -> int:
        return int(round(360.0 / self.angle_step_deg))

    @property
    def angle_step(self) -> float:
        return np.deg2rad(self.angle_step_deg)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)
