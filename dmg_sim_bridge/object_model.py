"""An object of the objects folder as MJCF: its box parts as collision geoms, its AprilTags as textures.

The tag images are generated with cv2.aruco when the scene is built (no binaries in the
repository) and written next to the generated model. Each tag is a thin visual-only box
whose +z face carries the texture; MuJoCo maps a 2-D texture onto that face with the
image's top row along the geom's +y and its left column along -x, which is exactly the
tag-frame convention of dmg_perception.tags (checked by rendering in tests/sim_bridge/test_sim_object.py).
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from dmg_perception.tags import printed_size, tag_image, tag_pose
from dmg_planner.objects import ObjectModel
from dmg_sim_bridge.mjcf import vector

TAG_THICKNESS = 0.0002   # half-thickness of a tag's visual box [m]; lifted this far off the face
TAG_CELL_PIXELS = 16     # texture resolution: pixels per tag cell



def write_tag_textures(model: ObjectModel, directory: Path) -> dict[int, Path]:
    """PNG of every tag of `model` in `directory`; {tag id: path}."""
    directory.mkdir(parents=True, exist_ok=True)
    paths = {}
    for tag in model.apriltags:
        path = directory / f"tag36h11_{tag.id}.png"
        if not cv2.imwrite(str(path), tag_image(tag.id, TAG_CELL_PIXELS)):
            raise OSError(f"could not write {path}")
        paths[tag.id] = path
    return paths


def object_mjcf(model: ObjectModel, texture_dir: Path, body_name: str = "object",
                position=(0.0, 0.0, 0.0), free: bool = True, geom_defaults: str = "") -> tuple[str, str]:
    """(asset XML, body XML) of the object: parts as boxes with the object's mass spread by volume.

    `geom_defaults` is extra attribute text for the collision geoms (friction, condim, solref...).
    """
    volume = sum(float(np.prod(part.size)) for part in model.parts)
    density = model.mass / volume
    textures = write_tag_textures(model, texture_dir)
    assets, geoms = [], []
    for index, part in enumerate(model.parts):
        geoms.append(f'<geom name="{body_name}_part{index}" type="box" size="{vector(part.size / 2)}" '
                     f'pos="{vector(part.center)}" density="{density:.9g}" rgba="0.85 0.65 0.35 1" {geom_defaults}/>')
    for tag in model.apriltags:
        rotation, centre = tag_pose(tag)
        x, y, z, w = Rotation.from_matrix(rotation).as_quat()
        half = printed_size(tag) / 2
        assets.append(f'<texture name="{body_name}_tag{tag.id}" type="2d" file="{textures[tag.id]}"/>'
                      f'<material name="{body_name}_tag{tag.id}" texture="{body_name}_tag{tag.id}" specular="0" '
                      f'shininess="0"/>')
        geoms.append(f'<geom name="{body_name}_tag{tag.id}" type="box" size="{half:.9g} {half:.9g} {TAG_THICKNESS}" '
                     f'pos="{vector(centre + rotation[:, 2] * TAG_THICKNESS)}" quat="{vector([w, x, y, z])}" '
                     f'material="{body_name}_tag{tag.id}" contype="0" conaffinity="0" density="0" group="1"/>')
    joint = f'<freejoint name="{body_name}_free"/>' if free else ""
    body = f'<body name="{body_name}" pos="{vector(position)}">{joint}{"".join(geoms)}</body>'
    return "".join(assets), body
