"""Choosing how the pusher holds its wrist camera so the object's tags stay in view.

The camera rides on the pushing gripper, about 85 mm behind and 40 mm beside the fingertips.
Where the fingertips must be is fixed by the push; how the hand is turned about them is
free within the arm's comfortable range. For each place the pusher goes, every orientation
on a grid - tilts of the finger axis up to `tilt_limit`, rolls about it up to `roll_limit`,
from the orientation the pusher started in - is scored by projecting the object's tags
into the camera: most tags wholly in the image, facing the camera, large enough there to be
detected and hidden by nothing wins, ties go to tags nearer the image centre, then to the
smaller turn. Rolling matters: it swings the camera's offset round the fingers, towards the
side the tags are on.

What can hide a tag: the object itself (rays cast on its mesh), the holding gripper's
fingers and hand, and the pusher's own fingertips, which sit in front of its camera (a
tag behind them is lost, and a black fingertip touching a tag's black border bends the
detected square). The grippers are modelled as spheres; a tag counts only if the rays
to a grid of points over it and its white margin pass clear of all of them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation

from dmg_executor.settings import ViewSettings
from dmg_perception.tags import tag_corners, tag_pose
from dmg_planner.objects import ObjectModel

MARGIN_SCALE = 1.25                  # the tag's white margin: one cell of the 8 across its black square


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

    def samples(self) -> np.ndarray:
        """(tags, 9, 3): a 3x3 grid over each tag with its white margin, the points that must be unhidden."""
        centres = self.corners.mean(axis=1, keepdims=True)
        corners = centres + MARGIN_SCALE * (self.corners - centres)
        edges = (corners + np.roll(corners, -1, axis=1)) / 2
        return np.concatenate([corners, edges, centres], axis=1)


@dataclass(frozen=True)
class GripperShape:
    """A parallel gripper as spheres in its grasp frame (z along the fingers, origin between the tips)."""

    finger_length: float       # m, palm to fingertip centre
    tip_radius: float          # m
    hand_start: float          # m behind the fingertips where the hand (wrist) begins, on the finger axis
    hand_end: float            # m behind the fingertips where the modelled hand ends
    hand_radius: float         # m

    def fingers(self, opening: float) -> np.ndarray:
        """(k, 4) centres and radii covering both fingers, `opening` apart."""
        finger_radius = 1.25 * self.tip_radius           # the finger's box and a margin for pose error
        along = np.arange(0.0, self.finger_length - self.tip_radius + 1e-9, finger_radius)
        return np.vstack([np.column_stack([np.full_like(along, side * (opening / 2 + self.tip_radius)),
                                           np.zeros_like(along), -along, np.full_like(along, finger_radius)])
                          for side in (-1.0, 1.0)])

    def hand(self) -> np.ndarray:
        """(k, 4) centres and radii covering the hand (wrist) behind the fingers; none if not modelled."""
        if self.hand_radius <= 0 or self.hand_end <= self.hand_start:
            return np.zeros((0, 4))
        along = np.arange(self.hand_start, self.hand_end + 1e-9, 0.75 * self.hand_radius)
        return np.column_stack([np.zeros((len(along), 2)), -along, np.full_like(along, self.hand_radius)])


def placed(spheres: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Spheres (k, 4) given in a frame, moved to where `pose` (4x4) puts that frame."""
    return np.column_stack([spheres[:, :3] @ pose[:3, :3].T + pose[:3, 3], spheres[:, 3]])


def overlap(first: np.ndarray, second: np.ndarray) -> bool:
    """Does any sphere of `first` (k, 4) cut one of `second` (j, 4)?"""
    gaps = np.linalg.norm(first[:, None, :3] - second[None, :, :3], axis=2)
    return bool((gaps < first[:, None, 3] + second[None, :, 3]).any())


@dataclass
class Occluders:
    """Spheres that can hide tags: the holding gripper's `hand` and `fingers` in the base frame,
    `riding` in the pusher's grasp frame (its own fingers, always at the same place in its camera's image)."""

    hand: np.ndarray           # (k, 4) centre, radius
    fingers: np.ndarray        # (i, 4)
    riding: np.ndarray         # (j, 4)

    @classmethod
    def of(cls, shape: GripperShape, holder: np.ndarray, holder_opening: float) -> "Occluders":
        return cls(placed(shape.hand(), holder), placed(shape.fingers(holder_opening), holder), shape.fingers(0.0))

    @property
    def fixed(self) -> np.ndarray:
        """(k + i, 4): the holding gripper's spheres."""
        return np.vstack([self.hand, self.fingers])


def turns(tilt_limit: float, roll_limit: float, step: float) -> np.ndarray:
    """(n, 3, 3) rotations in the pusher's own frame: a tilt of the finger axis (z) on a grid of `step`
    [rad], then a roll about it on a grid of twice that."""
    tilts = np.arange(-tilt_limit, tilt_limit + 1e-9, step)
    rolls = np.arange(-roll_limit, roll_limit + 1e-9, 2 * step)
    a, b, c = np.meshgrid(tilts, tilts, rolls, indexing="ij")
    keep = np.hypot(a, b) <= tilt_limit + 1e-9
    tilt = Rotation.from_rotvec(np.column_stack([a[keep], b[keep], np.zeros(keep.sum())]))
    roll = Rotation.from_rotvec(np.column_stack([np.zeros(keep.sum()), np.zeros(keep.sum()), c[keep]]))
    return (tilt * roll).as_matrix()


def _hidden_by_spheres(cameras: np.ndarray, points: np.ndarray, spheres: np.ndarray) -> np.ndarray:
    """(n, p): does a sphere (n, k, 4) cut the segment from camera n (n, 3) to point p (p, 3)?"""
    ray = points[None] - cameras[:, None]                                        # (n, p, 3)
    to_centre = spheres[..., :3] - cameras[:, None]                               # (n, k, 3)
    dot = ray @ to_centre.transpose(0, 2, 1)                                      # (n, p, k)
    length2 = np.einsum("npd,npd->np", ray, ray)[..., None]
    along = np.clip(dot / length2, 0.0, 1.0)                                      # closest point on the segment
    gap2 = np.einsum("nkd,nkd->nk", to_centre, to_centre)[:, None] - 2 * along * dot + along**2 * length2
    return (gap2 < spheres[:, None, :, 3] ** 2).any(axis=2)


def _hidden_by_object(scene: o3d.t.geometry.RaycastingScene, cameras: np.ndarray, points: np.ndarray,
                      slack: float) -> np.ndarray:
    """(n, p): does the object (its mesh, object frame) stand between camera n and its own point p, by
    more than `slack` [m] (a tag point lies on the surface)?"""
    ray = points[None] - cameras[:, None]
    rays = np.concatenate([np.broadcast_to(cameras[:, None], ray.shape), ray], axis=2).reshape(-1, 6)
    hit = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy().reshape(ray.shape[:2])
    return hit < 1.0 - slack / np.linalg.norm(ray, axis=2)


def view_score(camera: CameraModel, tags: TagLayout, object_pose: np.ndarray, tip: np.ndarray,
               orientations: np.ndarray, rules: ViewSettings, occluders: Occluders | None = None,
               scene: o3d.t.geometry.RaycastingScene | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For pusher orientations (n, 3, 3) with the grasp frame at `tip` (base frame): the number of
    tags wholly in view (corners `rules.edge_margin_px` inside the image, farther than `rules.nearest`)
    and large enough to be detected (`rules.smallest_side_px`), facing the camera (within
    `rules.facing_limit`) and (given the occluders and the object's ray casting scene) hidden by
    nothing, and their mean distance from the image centre [px]."""
    rotation, origin = object_pose[:3, :3], object_pose[:3, 3]
    corners = tags.corners.reshape(-1, 3) @ rotation.T + origin                                # (4t, 3)
    normals = tags.normals @ rotation.T
    centres = tags.corners.mean(axis=1) @ rotation.T + origin
    optical = orientations @ camera.in_pusher[:3, :3]                                          # (n, 3, 3)
    position = tip + orientations @ camera.in_pusher[:3, 3]                                   # (n, 3)
    local = np.einsum("nji,nkj->nki", optical, corners[None] - position[:, None])             # (n, 4t, 3)
    depth = local[..., 2]
    margin = rules.edge_margin_px
    safe = np.where(depth > rules.nearest, depth, np.inf)
    u = camera.intrinsics[0, 0] * local[..., 0] / safe + camera.intrinsics[0, 2]
    v = camera.intrinsics[1, 1] * local[..., 1] / safe + camera.intrinsics[1, 2]
    inside = ((depth > rules.nearest) & (u > margin) & (u < camera.width - margin)
              & (v > margin) & (v < camera.height - margin))
    inside = inside.reshape(len(orientations), -1, 4).all(axis=2)                              # (n, t)
    square = np.stack([u, v], axis=2).reshape(len(orientations), -1, 4, 2)
    sides = np.linalg.norm(square - np.roll(square, -1, axis=2), axis=3).min(axis=2)          # (n, t)
    inside &= sides >= rules.smallest_side_px
    towards = position[:, None] - centres[None]
    facing = np.einsum("ntk,tk->nt", towards, normals) > np.cos(rules.facing_limit) * np.linalg.norm(towards, axis=2)
    seen = inside & facing
    rows = np.flatnonzero(seen.any(axis=1))
    if len(rows) and (occluders is not None or scene is not None):
        samples = tags.samples()
        count = samples.shape[1]
        hidden = np.zeros((len(rows), samples.shape[0] * count), bool)
        if occluders is not None:
            riding = np.concatenate([np.einsum("nij,kj->nki", orientations[rows], occluders.riding[:, :3]) + tip,
                                     np.broadcast_to(occluders.riding[:, 3:], (len(rows), *occluders.riding[:, 3:].shape))],
                                    axis=2)
            spheres = np.concatenate([np.broadcast_to(occluders.fixed, (len(rows), *occluders.fixed.shape)), riding], axis=1)
            hidden |= _hidden_by_spheres(position[rows], samples.reshape(-1, 3) @ rotation.T + origin, spheres)
        if scene is not None:
            cameras = (position[rows] - origin) @ rotation                                   # object frame
            hidden |= _hidden_by_object(scene, cameras, samples.reshape(-1, 3), rules.surface_slack)
        seen[rows] &= ~hidden.reshape(len(rows), -1, count).any(axis=2)
    off_centre = np.hypot(u - camera.intrinsics[0, 2], v - camera.intrinsics[1, 2]).reshape(len(orientations), -1, 4)
    off_centre = off_centre.mean(axis=2)
    mean_off = np.where(seen.any(axis=1), (off_centre * seen).sum(axis=1) / np.maximum(seen.sum(axis=1), 1), np.inf)
    return seen.sum(axis=1), mean_off


def ranked_views(camera: CameraModel, tags: TagLayout, object_pose: np.ndarray, tip: np.ndarray,
                 neutral: np.ndarray, candidates: np.ndarray, rules: ViewSettings, level: np.ndarray | None = None,
                 occluders: Occluders | None = None, scene: o3d.t.geometry.RaycastingScene | None = None,
                 in_line: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pusher orientations (m, 3, 3) among `neutral` @ candidates with the grasp frame at `tip`, best
    view first, and how many tags each sees.

    `level`: a direction the pusher's two fingertips must not be spread along (their axis is
    its x; within `rules.level` of square to it), the grasp axis. Tips spread along it touch the object off the grasp's middle - the
    leading one first, as the hand is never exactly square to the face - and twist the object
    out of the grasp (measured: 5.6 deg about the finger axis over a 3 mm push); tips in a
    plane across it push in line with the grasp.

    `in_line`: a push direction. Among views that see as many tags, those with the tips one
    behind the other along it (within `rules.in_line`) come first: tips side by side across the push touch one before
    the other and turn the object about the grasp axis (measured: 4-29 deg over a 13 mm push).
    """
    orientations = neutral @ candidates
    turn = np.linalg.norm(Rotation.from_matrix(candidates).as_rotvec(), axis=1)
    if level is not None:
        keep = np.abs(orientations[:, :, 0] @ level) < np.sin(rules.level)
        if keep.any():
            orientations, turn = orientations[keep], turn[keep]
    count, off_centre = view_score(camera, tags, object_pose, tip, orientations, rules, occluders, scene)
    crossed = np.zeros(len(orientations), bool) if in_line is None else \
        np.abs(orientations[:, :, 0] @ in_line) < np.cos(rules.in_line)
    order = np.lexsort((turn, np.round(off_centre / 20.0), crossed, -count))
    return orientations[order], count[order]
