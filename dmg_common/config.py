"""Where the project's configuration is, and reading it (ROS-free: cores, nodes and the CLI share it)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

REPO_ROOT = Path(__file__).resolve().parent.parent


def config_dir() -> Path:
    """config/ of this checkout, or the directory DMG_CONFIG_DIR names (a user's own copy)."""
    return Path(os.environ.get("DMG_CONFIG_DIR", REPO_ROOT / "config"))


def objects_dir() -> Path:
    """The objects folder (one <name>/object.yaml per object): the directory DMG_OBJECTS_DIR names,
    else config_dir()/objects. Read at every call, so a process that sets it before loading an
    object (or before starting nodes, which inherit it) uses that folder."""
    folder = os.environ.get("DMG_OBJECTS_DIR")
    return Path(folder) if folder else config_dir() / "objects"


def load_parameter_spec(name: str) -> dict[str, dict[str, Any]]:
    """The `parameters` mapping of config/<name>.yaml (defaults, descriptions, ranges)."""
    path = config_dir() / f"{name}.yaml"
    document = yaml.safe_load(Path(path).read_text()) or {}
    spec = document.get("parameters")
    if not isinstance(spec, dict):
        raise ValueError(f"{path} has no 'parameters' mapping")
    return spec


def parameter_defaults(name: str) -> dict[str, Any]:
    """The default value of every parameter in config/<name>.yaml (for ROS-free cores and tests)."""
    return {key: entry["value"] for key, entry in load_parameter_spec(name).items()}


def load_settings(settings_class: type, name: str, overrides: dict[str, Any]):
    """A command's settings dataclass from config/<name>.yaml, with the command line's given
    (non-None) values on top."""
    values = yaml.safe_load((config_dir() / f"{name}.yaml").read_text())
    values.update({k: v for k, v in overrides.items() if v is not None and k in settings_class.__dataclass_fields__})
    return settings_class(**values)
