"""Shipped objects in MuJoCo: mass from config, and tags a camera really sees where the layout says."""
from __future__ import annotations

import cv2
import mujoco
import numpy as np
import pytest

from dmg_perception.tags import detector, tag_corners, tag_pose
from dmg_planner.objects import load_object, object_names
from dmg_sim_bridge.object_model import object_mjcf

pytestmark = pytest.mark.sim

WIDTH, HEIGHT, FOVY = 640, 480, 45.0
DISTANCE = 0.2


def scene(name: str, tmp_path) -> tuple[mujoco.MjModel, str]:
    model = load_object(name)
    assets, body = object_mjcf(model, tmp_path / "textures", free=False)
    cameras = []
    for tag in model.apriltags:
        rotation, centre = tag_pose(tag)
        eye = centre + DISTANCE * rotation[:, 2]
        # Camera looks along -z with x right and y up: the tag's own x and y, seen from outside.
        cameras.append(f'<camera name="tag{tag.id}" pos="{" ".join(map(str, eye))}" '
                       f'xyaxes="{" ".join(map(str, rotation[:, 0]))} {" ".join(map(str, rotation[:, 1]))}" fovy="{FOVY}"/>')
    xml = (f'<mujoco><asset>{assets}</asset><visual><global offwidth="{WIDTH}" offheight="{HEIGHT}"/></visual>'
           f'<worldbody><light pos="0 0 1" dir="0 0 -1" directional="true"/><light pos="0 0 -1" dir="0 0 1" '
           f'directional="true"/><light pos="1 0 0" dir="-1 0 0" directional="true"/>'
           f'{body}{"".join(cameras)}</worldbody></mujoco>')
    return mujoco.MjModel.from_xml_string(xml), xml


@pytest.mark.parametrize("name", object_names())
def test_object_mass_and_every_tag_seen_where_its_layout_says(name, tmp_path):
    model = load_object(name)
    mj_model, _ = scene(name, tmp_path)
    body = mj_model.body("object")
    assert body.mass[0] == pytest.approx(model.mass, rel=1e-6)
    data = mujoco.MjData(mj_model)
    mujoco.mj_forward(mj_model, data)
    focal = HEIGHT / 2 / np.tan(np.deg2rad(FOVY / 2))
    with mujoco.Renderer(mj_model, HEIGHT, WIDTH) as renderer:
        for tag in model.apriltags:
            renderer.update_scene(data, camera=f"tag{tag.id}")
            gray = cv2.cvtColor(renderer.render(), cv2.COLOR_RGB2GRAY)
            corners, ids, _ = detector().detectMarkers(gray)
            assert ids is not None and tag.id in ids.ravel(), f"{name}: tag {tag.id} not detected"
            found = corners[list(ids.ravel()).index(tag.id)][0]
            # Project the layout's corners with the camera: x right, y up, looking along -z.
            camera = data.camera(f"tag{tag.id}")
            local = (tag_corners(tag) - camera.xpos) @ camera.xmat.reshape(3, 3)
            expected = np.column_stack([WIDTH / 2 + focal * local[:, 0] / -local[:, 2],
                                        HEIGHT / 2 - focal * local[:, 1] / -local[:, 2]])
            assert np.max(np.abs(found - expected)) < 1.5, (name, tag.id, found.tolist(), expected.tolist())
