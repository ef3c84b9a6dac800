"""Real MuJoCo physics: the closed gripper holds a shipped object still against gravity."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmg_planner.objects import load_object
from dmg_sim_bridge.gripper import gripper_mjcf
from dmg_sim_bridge.object_model import object_mjcf
from dmg_sim_bridge.sim_config import load_sim_config

pytestmark = pytest.mark.sim


def held_box_scene(tmp_path, force: float):
    config = load_sim_config()
    spec = config.gripper
    spec = type(spec)(**{**spec.__dict__, "max_force": force})
    gripper = gripper_mjcf("g1", spec)
    model = load_object("box")
    friction = " ".join(map(str, spec.friction))
    assets, body = object_mjcf(model, tmp_path / "textures", position=(0, 0, 0.5 - spec.geometry.finger_length),
                               geom_defaults=f'condim="6" friction="{friction}"')
    # Hand pointing down, grasp axis along world y: the fingers pinch the box's 60 mm faces.
    x, y, z, w = Rotation.from_euler("xz", [180, 90], degrees=True).as_quat()
    xml = (f'<mujoco><compiler angle="radian"/>{config.option_xml()}<asset>{assets}</asset><worldbody>'
           f'<body name="hand" pos="0 0 0.5" quat="{w} {x} {y} {z}">{gripper.bodies}</body>{body}</worldbody>'
           f'<actuator>{gripper.actuators}</actuator><equality>{gripper.equality}</equality></mujoco>')
    mj_model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(mj_model)
    for finger in ("g1_finger0", "g1_finger1"):
        data.joint(finger).qpos = 0.03 + spec.geometry.tip_radius
    data.ctrl[:] = 0.0   # target inside the object: each finger squeezes with its force limit
    mujoco.mj_forward(mj_model, data)
    return mj_model, data


def object_in_grasp(data) -> tuple[np.ndarray, Rotation]:
    site = data.site("g1_grasp")
    rotation = site.xmat.reshape(3, 3)
    position = (data.body("object").xpos - site.xpos) @ rotation
    return position, Rotation.from_matrix(rotation.T @ data.body("object").xmat.reshape(3, 3))


def test_closed_grip_holds_the_box_within_1mm_and_1deg_for_10s(tmp_path):
    model, data = held_box_scene(tmp_path, force=15.0)
    for _ in range(int(1.0 / model.opt.timestep)):       # settle
        mujoco.mj_step(model, data)
    start_position, start_rotation = object_in_grasp(data)
    for _ in range(int(10.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    position, rotation = object_in_grasp(data)
    assert np.linalg.norm(position - start_position) < 0.001
    assert np.rad2deg((start_rotation.inv() * rotation).magnitude()) < 1.0


def test_a_grip_too_weak_for_the_weight_lets_the_box_slide_out(tmp_path):
    # 0.1 kg needs 2 * 0.8 * F >= 0.98 N, i.e. F >= 0.61 N per finger; 0.3 N cannot hold it.
    model, data = held_box_scene(tmp_path, force=0.3)
    start = data.body("object").xpos.copy()
    for _ in range(int(1.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    assert start[2] - data.body("object").xpos[2] > 0.01


def test_the_loosened_grip_the_executor_picks_keeps_the_bracket_from_tilting_where_the_bare_balance_does_not():
    """The bracket hangs off its default grasp: loosened to the force whose friction just balances its
    weight's turn across the grasp axis it tilts; at the executor's margin over that it stays put."""
    import math

    from dmg_common.transforms import invert
    from dmg_executor.grip import tilt_hold_force
    from dmg_executor.push_points import ObjectSurface
    from dmg_executor.settings import ExecutorSettings
    from dmg_sim_bridge.cell import Cell

    settings = ExecutorSettings.defaults()
    surface = ObjectSurface.of(load_object("bracket"))
    cell = Cell()
    try:
        tilts = {}
        for margin in (1.0, settings.grip.tilt_hold_margin):
            cell.reset("bracket")
            cell.run(0.5)
            start = cell.object_in_gripper("arm1")
            balance = tilt_hold_force(start, cell.grasp_pose("arm1")[:3, :3], surface.centre_of_mass, surface.mass,
                                      cell.opening("arm1"), settings.grip.friction)
            assert 0.5 < balance < settings.grip.hold_force     # the bracket's weight does turn it: there is something to hold
            cell.command_gripper("arm1", max(cell.opening("arm1") - settings.grip.slide_squeeze, 0.0), margin * balance)
            cell.run(2.0)
            axes = invert(start)[:3, 0], invert(cell.object_in_gripper("arm1"))[:3, 0]
            tilts[margin] = math.degrees(math.acos(min(1.0, float(axes[0] @ axes[1]))))
    finally:
        cell.close()
    assert tilts[1.0] > 3.0 and tilts[settings.grip.tilt_hold_margin] < 0.5, tilts


def test_the_loosened_grip_the_executor_picks_keeps_a_heavy_block_held_off_centre_from_swinging_round(
        tmp_path, monkeypatch):
    """A 200 g block held 17 mm to the side of its centre of mass: loosened to half the force whose pads'
    torsional friction balances its weight's turn about the grasp axis it swings round; at the executor's
    margin over that it stays put."""
    import math

    from dmg_bringup.object_generator import GeneratorSettings, generate
    from dmg_common.transforms import from_rotation
    from dmg_executor.grip import turn_hold_force
    from dmg_executor.push_points import ObjectSurface
    from dmg_executor.settings import ExecutorSettings
    from dmg_sim_bridge.cell import Cell, default_grasp

    block = GeneratorSettings.load().families["block"]
    generate(1, 5, tmp_path, GeneratorSettings.load({"families": {"block": block}, "mass_range": [0.2, 0.2]}),
             sim_check=False)
    monkeypatch.setenv("DMG_OBJECTS_DIR", str(tmp_path))
    model = load_object("gen_5_0")
    settings = ExecutorSettings.defaults()
    surface = ObjectSurface.of(model)
    cell = Cell()
    try:
        aside = from_rotation(np.eye(3), [0.0, 0.017, 0.0]) @ default_grasp(model, cell.config.gripper.geometry.max_opening)
        turns = {}
        for margin in (0.5, settings.grip.turn_hold_margin):
            cell.reset("gen_5_0", object_in_gripper=aside)
            cell.run(0.5)
            start = cell.object_in_gripper("arm1")
            balance = turn_hold_force(start, cell.grasp_pose("arm1")[:3, :3], surface.centre_of_mass, surface.mass,
                                      settings.grip.torsional_friction)
            assert settings.grip.slide_force / 2 < balance < settings.grip.hold_force   # something to hold
            cell.command_gripper("arm1", max(cell.opening("arm1") - settings.grip.slide_squeeze, 0.0), margin * balance)
            cell.run(2.0)
            turned = cell.object_in_gripper("arm1")[:3, :3] @ start[:3, :3].T      # in the holder frame
            turns[margin] = math.degrees(abs(Rotation.from_matrix(turned).as_rotvec()[0]))   # about the grasp axis
    finally:
        cell.close()
    assert turns[0.5] > 3.0 and turns[settings.grip.turn_hold_margin] < 0.5, turns
