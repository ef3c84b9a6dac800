"""Choosing how the pusher holds its wrist camera so the object's tags stay in view.

The camera rides on the pushing gripper, about 85 mm behind and 40 mm beside the fingertips.
Where the fingertips must be is fixed by the push; how the hand is turned about them is
free within the arm's comfortable range. For each place the pusher goes, every orientation
on a grid - tilts of the finger axis up to `tilt_limit`, rolls about it up to `roll_limit`,
from the orientation the pusher started in - is scored by projecting the object's tag
corners into the camera: most tags wholly in the image and facing the camera wins, ties go
to tags nearer the image centre, then to the smaller turn. Rolling matters: it swings the
camera's offset round the fingers, towards the side the tags are on.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_perception.tags import tag_corners, tag_pose
from dmg_planner.objects import ObjectModel

GRID_STEP = np.deg2rad(7.5)
EDGE_MARGIN = 30.0                   # px a tag corner must keep from the image border (the pose is only planned)
FACING_COSINE = np.cos(np.deg2rad(70.0))   # a tag seen more edge-on than this is not counted
LEVEL_SINE = np.sin(np.deg2rad(15.0))   # fingertip axis across a push line: at most this far off
NEAREST = 0.04                       # m; closer to the camera than this is not in view


@dataclass
class CameraModel:
    intrinsics: np.ndarray     # 3x3
    width: int
    height: int
    in_pusher: np.ndarray      # 4x4 optical frame (z forward) in the pusher's grasp frame


@dataclass
class TagLayout:
    corners: np.ndarray        # (tags, 4, 3) object frame
    normals: np.ndarray        # (tags, 3) object frame, out of the face

    @classmethod
    def of(cls, model: ObjectModel) -> "TagLayout":
        corners = np.array([tag_corners(tag) for tag in model.apriltags]).reshape(-1, 4, 3)
        normals = np.array([tag_pose(tag)[0][:, 2] for tag in model.apriltags]).reshape(-1, 3)
        return cls(corners, normals)


def turns(tilt_limit: float, roll_limit: float) -> np.ndarray:
    """(n, 3, 3) rotations in the pusher's own frame: a tilt of the finger axis (z), then a roll about it."""
    tilts = np.arange(-tilt_limit, tilt_limit + 1e-9, GRID_STEP)
    rolls = np.arange(-roll_limit, roll_limit + 1e-9, 2 * GRID_STEP)
    a, b, c = np.meshgrid(tilts, tilts, rolls, indexing="ij")
    keep = np.hypot(a, b) <= tilt_limit + 1e-9
    tilt = Rotation.from_rotvec(np.column_stack([a[keep], b[keep], np.zeros(keep.sum())]))
    roll = Rotation.from_rotvec(np.column_stack([np.zeros(keep.sum()), np.zeros(keep.sum()), c[keep]]))
    return (tilt * roll).as_matrix()


def view_score(camera: CameraModel, tags: TagLayout, object_pose: np.ndarray, tip: np.ndarray,
               orientations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For pusher orientations (n, 3, 3) with the grasp frame at `tip` (base frame): the number of
    tags wholly in view and facing the camera, and their mean distance from the image centre [px]."""
    corners = tags.corners.reshape(-1, 3) @ object_pose[:3, :3].T + object_pose[:3, 3]       # (4t, 3)
    normals = tags.normals @ object_pose[:3, :3].T
    centres = tags.corners.mean(axis=1) @ object_pose[:3, :3].T + object_pose[:3, 3]
    optical = orientations @ camera.in_pusher[:3, :3]                                          # (n, 3, 3)
    position = tip + orientations @ camera.in_pusher[:3, 3]                                   # (n, 3)
    local = np.einsum("nji,nkj->nki", optical, corners[None] - position[:, None])             # (n, 4t, 3)
    depth = local[..., 2]
    safe = np.where(depth > NEAREST, depth, np.inf)
    u = camera.intrinsics[0, 0] * local[..., 0] / safe + camera.intrinsics[0, 2]
    v = camera.intrinsics[1, 1] * local[..., 1] / safe + camera.intrinsics[1, 2]
    inside = ((depth > NEAREST) & (u > EDGE_MARGIN) & (u < camera.width - EDGE_MARGIN)
              & (v > EDGE_MARGIN) & (v < camera.height - EDGE_MARGIN))
    inside = inside.reshape(len(orientations), -1, 4).all(axis=2)                              # (n, t)
    towards = position[:, None] - centres[None]
    facing = np.einsum("ntk,tk->nt", towards, normals) > FACING_COSINE * np.linalg.norm(towards, axis=2)
    seen = inside & facing
    off_centre = np.hypot(u - camera.intrinsics[0, 2], v - camera.intrinsics[1, 2]).reshape(len(orientations), -1, 4)
    off_centre = off_centre.mean(axis=2)
    mean_off = np.where(seen.any(axis=1), (off_centre * seen).sum(axis=1) / np.maximum(seen.sum(axis=1), 1), np.inf)
    return seen.sum(axis=1), mean_off


def best_orientation(camera: CameraModel, tags: TagLayout, object_pose: np.ndarray, tip: np.ndarray,
                     neutral: np.ndarray, candidates: np.ndarray, level: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """The pusher orientation (3x3) among `neutral` @ candidates that sees the object best with its
    grasp frame at `tip`, and how many tags it sees.

    `level`: a direction the pusher's two fingertips must not be spread along (their axis is
    its x). Pushing with the tips spread across the push line, one tip touches first, off the
    line, and turns the object.
    """
    orientations = neutral @ candidates
    turn = np.linalg.norm(Rotation.from_matrix(candidates).as_rotvec(), axis=1)
    if level is not None:
        keep = np.abs(orientations[:, :, 0] @ level) < LEVEL_SINE
        if keep.any():
            orientations, turn = orientations[keep], turn[keep]
    count, off_centre = view_score(camera, tags, object_pose, tip, orientations)
    best = np.lexsort((turn, np.round(off_centre / 20.0), -count))[0]
    return orientations[best], int(count[best])
