"""The parameters of a DMG build: a light module (no open3d) so command lines can list them cheaply."""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np


@dataclass(frozen=True)
class GraphParameters:
    """Everything that changes a built graph (and therefore its cache key)."""

    voxel_resolution: float = 0.001
    seed_resolution: float = 0.013
    spatial_importance: float = 0.9
    normal_importance: float = 1.0
    delta: float = 0.07
    angle_step_deg: float = 5.0
    finger_length: float = 0.1
    finger_width: float = 0.02
    finger_thickness: float = 0.01
    finger_tip_overhang: float = 0.008   # how far the fingertip reaches past the contact, away from the palm
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
