"""The Baxter-like arm in MuJoCo has the public URDF's kinematics (checked against a direct FK)."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmg_sim_bridge.robot_model import COMPILER, arm_mjcf, frame, load_robot

pytestmark = pytest.mark.sim


def direct_fk(robot: dict, side: str, angles: np.ndarray) -> np.ndarray:
    """Endpoint pose in the torso frame by chaining the URDF transforms (URDF semantics)."""
    transform = frame(robot["arm_mounts"][side]).matrix()
    for joint, angle in zip(robot["joints"], angles):
        rotate = np.eye(4)
        rotate[:3, :3] = Rotation.from_rotvec([0, 0, angle]).as_matrix()
        transform = transform @ frame(joint).matrix() @ rotate
    for name in ("hand", "gripper_base", "endpoint"):
        transform = transform @ frame(robot[name]).matrix()
    return transform


@pytest.mark.parametrize("side", ["left", "right"])
def test_mujoco_arm_matches_the_urdf_kinematics_and_limits(side):
    robot = load_robot()
    model = mujoco.MjModel.from_xml_string(f"<mujoco>{COMPILER}<worldbody>{arm_mjcf(side, robot)}</worldbody></mujoco>")
    data = mujoco.MjData(model)
    assert model.njnt == 7
    for joint in robot["joints"]:
        assert np.allclose(model.joint(f"{side}_{joint['name']}").range, [joint["lower"], joint["upper"]])
    assert model.body(f"{side}_s0_link").mass[0] == pytest.approx(robot["joints"][0]["mass"])
    rng = np.random.default_rng(0)
    lows = np.array([j["lower"] for j in robot["joints"]])
    highs = np.array([j["upper"] for j in robot["joints"]])
    for angles in [np.zeros(7), *rng.uniform(lows, highs, size=(20, 7))]:
        data.qpos[:] = angles
        mujoco.mj_kinematics(model, data)
        expected = direct_fk(robot, side, angles)
        site = data.site(f"{side}_endpoint")
        assert np.allclose(site.xpos, expected[:3, 3], atol=1e-6)
        assert np.allclose(site.xmat.reshape(3, 3), expected[:3, :3], atol=1e-6)
    # Stretched out (all zero) the endpoint is about a metre from the shoulder, as on a Baxter.
    data.qpos[:] = 0
    mujoco.mj_kinematics(model, data)
    reach = np.linalg.norm(data.site(f"{side}_endpoint").xpos - data.body(f"{side}_s0_link").xpos)
    assert 0.9 < reach < 1.4
