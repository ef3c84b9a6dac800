"""The gripper both arms carry, from config/gripper.yaml: one description for the planner, the simulation
and the executor, so a grasp the planner calls valid is one the fingers in the cell can make."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import lru_cache
from pathlib import Path

import yaml

from dmg_common.config import config_dir


class GripperDescriptionError(ValueError):
    """config/gripper.yaml missing, unreadable or inconsistent; the message names the file and the field."""


@dataclass(frozen=True)
class GripperDescription:
    """Lengths in metres; the gripper frame is x along the grasp axis, z from the palm along the fingers."""

    finger_length: float      # palm face to fingertip centre
    finger_width: float       # across the grasp axis
    finger_thickness: float   # along the grasp axis
    tip_radius: float         # hemispherical fingertip
    max_opening: float        # between the tips' inner surfaces
    palm_width: float         # palm's face across the grasp axis

    def validate(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise GripperDescriptionError(f"{f.name} = {value!r}: must be a finite length > 0 m")
        if self.tip_radius >= self.finger_length:
            raise GripperDescriptionError(f"tip_radius {self.tip_radius} m must be shorter than finger_length "
                                          f"{self.finger_length} m")


def load_gripper(path: Path | None = None) -> GripperDescription:
    """The description in `path` (default config_dir()/gripper.yaml, so DMG_CONFIG_DIR picks a user's copy)."""
    path = Path(path or config_dir() / "gripper.yaml")
    try:
        document = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise GripperDescriptionError(f"{path}: cannot be read: {error}") from None
    if not isinstance(document, dict):
        raise GripperDescriptionError(f"{path}: not a YAML mapping")
    names = [f.name for f in fields(GripperDescription)]
    missing, unknown = [n for n in names if n not in document], sorted(set(document) - set(names))
    if missing or unknown:
        raise GripperDescriptionError(f"{path}: " + "; ".join(
            part for part in (f"missing {', '.join(missing)}" if missing else "",
                              f"unknown {', '.join(unknown)}" if unknown else "") if part))
    description = GripperDescription(**{n: document[n] for n in names})
    try:
        description.validate()
    except GripperDescriptionError as error:
        raise GripperDescriptionError(f"{path}: {error}") from None
    return description


def gripper_description() -> GripperDescription:
    """config_dir()/gripper.yaml, read again only when the file (or DMG_CONFIG_DIR) changes: the defaults of
    every graph build and search ask for it."""
    path = config_dir() / "gripper.yaml"
    try:
        stamp = path.stat().st_mtime_ns
    except OSError:
        stamp = -1
    return _described(str(path), stamp)


@lru_cache(maxsize=8)
def _described(path: str, stamp: int) -> GripperDescription:
    return load_gripper(Path(path))
