"""config/gripper.yaml: the gripper's one description, and the parts of the cell that read it."""
from __future__ import annotations

import pytest
import yaml

from dmg_common.config import config_dir, parameter_defaults
from dmg_common.gripper import GripperDescriptionError, gripper_description, load_gripper
from dmg_executor.settings import ExecutorSettings
from dmg_planner.graph_parameters import GraphParameters
from dmg_planner.search_options import SearchOptions
from dmg_sim_bridge.sim_config import load_sim_config


def _written(tmp_path, edit) -> object:
    document = yaml.safe_load((config_dir() / "gripper.yaml").read_text())
    edit(document)
    path = tmp_path / "gripper.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def test_planner_simulation_and_executor_read_the_same_gripper():
    gripper = load_gripper()
    graph, search = GraphParameters(), SearchOptions()
    assert (graph.finger_length, graph.finger_width, graph.finger_thickness, graph.finger_tip_overhang) == \
        (gripper.finger_length, gripper.finger_width, gripper.finger_thickness, gripper.tip_radius)
    assert search.pusher_tip_radius == gripper.tip_radius
    assert load_sim_config().gripper.geometry == gripper
    executor = ExecutorSettings.defaults().gripper
    assert (executor.tip_radius, executor.finger_length) == (gripper.tip_radius, gripper.finger_length)


def test_a_users_config_directory_brings_its_own_gripper(tmp_path, monkeypatch):
    executor_values = parameter_defaults("executor")       # the shipped executor.yaml (the copy has none)
    _written(tmp_path, lambda d: d.update(finger_length=0.09, max_opening=0.08))
    monkeypatch.setenv("DMG_CONFIG_DIR", str(tmp_path))
    assert gripper_description().finger_length == 0.09
    assert GraphParameters().finger_length == 0.09
    assert ExecutorSettings.from_values(executor_values).gripper.finger_length == 0.09


@pytest.mark.parametrize("edit, named", [
    (lambda d: d.pop("tip_radius"), "missing tip_radius"),
    (lambda d: d.update(palm_depth=0.01), "unknown palm_depth"),
    (lambda d: d.update(max_opening=-0.1), "max_opening = -0.1: must be a finite length > 0 m"),
    (lambda d: d.update(finger_width=".nan"), "finger_width"),
    (lambda d: d.update(tip_radius=0.2), "tip_radius 0.2 m must be shorter than finger_length"),
])
def test_a_broken_description_is_refused_naming_the_file_and_field(tmp_path, edit, named):
    path = _written(tmp_path, edit)
    with pytest.raises(GripperDescriptionError, match=named) as error:
        load_gripper(path)
    assert str(path) in str(error.value)


def test_a_missing_description_names_the_file(tmp_path):
    with pytest.raises(GripperDescriptionError, match="gripper.yaml: cannot be read"):
        load_gripper(tmp_path / "gripper.yaml")
