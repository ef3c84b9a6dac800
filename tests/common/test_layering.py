"""The layering holds: ROS-free cores import no ROS and nothing above them, dmg_common imports no
other package of the project, and only the CLI layer imports dmg_bringup."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from conftest import REPO

NODE_PACKAGES = ("dmg_planner", "dmg_perception", "dmg_executor", "dmg_sim_bridge")
PROJECT = (*NODE_PACKAGES, "dmg_common", "dmg_bringup", "dmg_interfaces")
ROS = ("rclpy", "rcl_interfaces", "builtin_interfaces", "dmg_interfaces", "dmg_common.ros")


def _modules(package: str) -> list[Path]:
    return sorted((REPO / package).rglob("*.py"))


def _imports(path: Path) -> set[str]:
    """Every module `path` imports, at the top or inside a function."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)   # a submodule imported by name
    return names


def _is_node_side(path: Path) -> bool:
    """A package's ROS side: its node module and the message conversions only the node uses."""
    return path.stem.endswith("_node") or path.stem.startswith("ros_")


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _ros(name: str) -> bool:
    return _within(name, ROS) or name.split(".")[0].endswith("_msgs")


CORES = [p for package in NODE_PACKAGES for p in _modules(package) if not _is_node_side(p)]
COMMON = _modules("dmg_common")


@pytest.mark.parametrize("path", CORES, ids=lambda p: str(p.relative_to(REPO)))
def test_a_core_imports_no_ros_and_nothing_above_it(path):
    bad = sorted(n for n in _imports(path)
                 if _ros(n) or _within(n, ("dmg_bringup",)) or n.rsplit(".", 1)[-1].endswith("_node")
                 or n.rsplit(".", 1)[-1].startswith("ros_"))
    assert not bad, f"{path.relative_to(REPO)} imports {bad}"


@pytest.mark.parametrize("path", COMMON, ids=lambda p: str(p.relative_to(REPO)))
def test_dmg_common_imports_no_other_package_of_the_project(path):
    bad = sorted(n for n in _imports(path) if _within(n, PROJECT) and not _within(n, ("dmg_common", "dmg_interfaces")))
    assert not bad, f"{path.relative_to(REPO)} imports {bad}"
    if "ros" not in path.relative_to(REPO / "dmg_common").parts:
        assert not [n for n in _imports(path) if _ros(n)], f"{path.relative_to(REPO)} is ROS-free by its place"


@pytest.mark.parametrize("package", (*NODE_PACKAGES, "dmg_common"))
def test_only_the_cli_layer_imports_dmg_bringup(package):
    bad = sorted(f"{p.relative_to(REPO)}: {n}" for p in _modules(package) for n in _imports(p)
                 if _within(n, ("dmg_bringup",)))
    assert not bad, bad


def test_the_rules_see_what_they_are_for():
    assert _ros("rclpy.node") and _ros("geometry_msgs.msg") and _ros("dmg_common.ros.waiting")
    assert not _ros("dmg_common.transforms") and not _ros("numpy")
    assert len(CORES) > 20 and all(p.name != "executor_node.py" for p in CORES)
