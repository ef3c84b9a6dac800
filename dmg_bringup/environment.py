"""Where the project's files are and which environment its ROS processes need.

The ROS 2 wheels run without a sourced setup file, so the few variables a sourced
workspace would provide are set here, for this process and for every child the CLI starts.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import yaml

REPO_ROOT = Path(__file__).resolve().parent.parent


from dmg_planner.objects import config_dir  # noqa: E402 - one definition of where config/ is


def fastdds_profile() -> Path:
    """Fast DDS profile with a 16 MiB shared-memory segment + UDPv4 (camera frames at 30 Hz)."""
    return config_dir() / "fastdds.xml"


def ros_environment(base: dict[str, str] | None = None) -> dict[str, str]:
    """A copy of `base` (default os.environ) completed with what ROS processes here need.

    Values the user set are kept: the venv prefix is appended to AMENT_PREFIX_PATH rather
    than replacing it, and a user's own Fast DDS profile wins over ours.
    """
    env = dict(os.environ if base is None else base)
    prefixes = [p for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    if sys.prefix not in prefixes:
        prefixes.append(sys.prefix)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(prefixes)
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(fastdds_profile()))
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def apply_ros_environment() -> None:
    """Complete os.environ in place; call before rclpy.init() so the DDS profile applies."""
    os.environ.update(ros_environment())


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
