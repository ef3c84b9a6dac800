"""The environment variables a ROS process of this project needs (ROS-free).

The ROS 2 wheels run without a sourced setup file, so the few variables a sourced
workspace would provide are set here, for this process and for every child the CLI starts.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

from dmg_common.config import config_dir


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
